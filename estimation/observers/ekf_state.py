"""The EKFs' state, their prepared log and their resolved settings (the kernel's arguments).

The observers are :mod:`estimation.observers.ekf`; the state is explicit and serialisable, so
a resumed run continues bit-identically (``run(..., state=snapshot.state)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from estimation.state import EstimatorState

__all__ = ["EkfModel", "EkfSettings", "EkfState"]


@dataclass(frozen=True, slots=True, eq=False)
class EkfState(EstimatorState):
    """Frozen, serialisable EKF state after ``step`` log samples.

    ``x`` (m,) = ``[p_im, p_em, ω_t]`` + ``[b]`` (Aug) or + ``θ`` (Map) and ``P`` (m, m) are
    the posterior of sample ``step − 1`` (the prior of sample 0 when ``step = 0``); ``mem``
    the model's Seiliger memory ``(T_1 K, x_r)``; ``counts`` (kernel ``C_*`` layout) the
    gated outputs per output and the state clamps; ``rejected_mask``/``rejected_gate`` the
    samples masked / with a gated output.
    """

    rejected_mask: int
    rejected_gate: int
    counts: np.ndarray
    x: np.ndarray
    P: np.ndarray
    mem: np.ndarray

    ARRAYS: ClassVar[tuple[str, ...]] = ("counts", "x", "P", "mem")


@dataclass(frozen=True, slots=True, eq=False)
class EkfModel:
    """A log, or rows ``offset …`` of one, turned into kernel inputs (chunks index into it).

    ``U`` (n, 4) inputs in ``U_*`` order (:mod:`estimation.kernels.ekf`); ``Y`` (n, 4)
    measurements in ``Y_*`` order (NaN for outputs not used); ``accept`` (n,); ``time_s``
    (n,). A window of a log of ``total`` samples
    (:meth:`~estimation.observers.ekf.EkfObserver.prepare_window`) starts at log sample
    ``offset``, the row before its first step (the kernel propagates from sample ``k − 1``).
    """

    U: np.ndarray
    Y: np.ndarray
    accept: np.ndarray
    time_s: np.ndarray
    offset: int = 0
    total: int = 0

    @property
    def end(self) -> int:
        """The log sample after the model's last row."""
        return self.offset + int(self.U.shape[0])


@dataclass(frozen=True, slots=True)
class EkfSettings:
    """Resolved numeric settings of one variant (kernel arguments)."""

    mode: int
    g: np.ndarray
    use: np.ndarray
    r_abs2: np.ndarray
    r_rel2: np.ndarray
    q_rate: np.ndarray
    p0_diag: np.ndarray
    limit: int  # estimation.kernels.ekf.LIMIT_NONE / LIMIT_PSD / LIMIT_DIAG
    gate2: float
    max_step_s: float
    theta0: float
    prm: np.ndarray
