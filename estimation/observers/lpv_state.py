"""The LPV observer's state, its prepared log and what a streamed run takes from the whole log.

The observer is :mod:`estimation.observers.lpv`; the state is explicit and serialisable, so a
resumed run continues bit-identically (``run(..., state=snapshot.state)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from estimation.state import EstimatorState

__all__ = ["LpvBox", "LpvPrepared", "LpvState"]


@dataclass(frozen=True, slots=True, eq=False)
class LpvState(EstimatorState):
    """Observer state: step, x̂ (3,) [Pa, Pa, rad/s], θ̂ (p,) [kg/s], the accumulated ψ
    weights (visits) and excitation ``S_j = ∫ψ_j² dt`` [s] (the normalised gain) of every
    element, and the design it runs.

    The gain and the ρ box are part of the state so a resumed run uses exactly the design
    of the interrupted one.
    """

    a1: float
    a2: float
    x_hat: np.ndarray
    theta: np.ndarray
    weight_sum: np.ndarray
    excitation: np.ndarray
    L_scaled: np.ndarray
    state_scale: np.ndarray
    output_scale: np.ndarray
    rho_lo: np.ndarray
    rho_hi: np.ndarray

    ARRAYS: ClassVar[tuple[str, ...]] = (
        "x_hat",
        "theta",
        "weight_sum",
        "excitation",
        "L_scaled",
        "state_scale",
        "output_scale",
        "rho_lo",
        "rho_hi",
    )
    WHAT: ClassVar[str] = "LPV observer state"


@dataclass(frozen=True, slots=True, eq=False)
class LpvPrepared:
    """A log turned into kernel inputs."""

    idx: np.ndarray
    w: np.ndarray
    y: np.ndarray  # (n, 3) p_im, ω_t, W_c,meas
    rho: np.ndarray  # (n, 5)
    e: np.ndarray  # (n, 3) E of LPV (3)
    h: np.ndarray  # (n,) step to each sample, h[0] = 0
    accept: np.ndarray
    time_s: np.ndarray
    x0: np.ndarray
    offset: int = 0  # a window's first log sample (run_windows)
    total: int = 0  # samples in the whole log (0: these rows are the log)
    rejected_before: int = 0  # samples masked before the window
    box: LpvBox | None = None  # the whole log's, for a window's first state


@dataclass(frozen=True, slots=True, eq=False)
class LpvBox:
    """What a run's gain design and ``E`` take from the whole log: the ρ box of its samples
    (before the configured box or the ρ4 floor apply), the mean exhaust temperature [K], and
    the observer's ``(n,)`` accept mask (the run's, and ρ1 > 0 with ``adapt_only_with_flow``)."""

    rho_min: np.ndarray
    rho_max: np.ndarray
    t_em_k: float
    accept: np.ndarray
