"""The synthetic checks of the SKF paper, §5 (docs/algorithms.md §2.7), as data generators.

Source: Guardiola et al., *SKF look-up table NOx* paper (``papers/skf-lookup-table-nox.txt``),
(20)–(22) and §5.1–5.3. A static 4×4 table, no sensor dynamics::

    u1 = [500 1500 2500 3500]   rpm        (SKF (20a), rows r)
    u2 = [0 20 40 60]           mg/stroke  (SKF (20b), columns c)
    T_r = ones(4, 4)                         (SKF (21))
    y_k = ψ(u_k)ᵀ vec(T_r) + v_k = 1 + v_k   (SKF (11b))

* **Simulation 1** (§5.1): ``{u_k}_{k=1}^{1400}`` i.i.d. uniform over the grid
  (``u1 ~ U[500, 3500]``, ``u2 ~ U[0, 60]``), ``y_k = 1``.
* **Simulation 2** (§5.2): ``u1 = 2000`` for all ``k``; ``u2`` a triangle with step 0.6,
  ``u2(k) = 0.6·k`` for ``k = 1…100`` (reaches 60 at ``k = 100``) and ``60 − 0.6·(k − 100)`` for
  ``k = 101…200`` (back to 0 at ``k = 200``): 200 samples, ``y_k = 1``. The paper says "u1
  varies monotonically from 0 to 60 … while u1 = 2000": the first ``u1`` is a typo for ``u2``.
  The paper's "from k = 0" is the initial condition before the first sample (``u2(0) = 0``).
* **Simulation 3** (§5.3): simulation 2 plus ``v_k ~ U(−0.2, 0.2)`` ("uniform distributed noise
  with zero mean and maximum amplitude of 0.2").

Sample ``k`` (1-based, as in the paper) is at time ``t = k`` seconds: a 1 Hz time base
starting at 1 s, so a plot against time reads like the paper's figures against ``k``.

In sims 2/3 ``u1 = 2000`` sits halfway between rows 1500 and 2500, so the 8 excited cells are
those two rows — the paper's elements 5–12, numbered row by row (1-based), which are the
0-based C-order flat indices 4–11 used by :class:`~estimation.table.Table`. The paper's areas
(22): 1 = {5, 6, 9, 10}, 2 = {6, 7, 10, 11}, 3 = {7, 8, 11, 12}.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np

from estimation.errors import ConfigError
from estimation.signals import Signals
from estimation.table import Axis, Table

U1_BREAKPOINTS_RPM: tuple[float, ...] = (500.0, 1500.0, 2500.0, 3500.0)
"""SKF (20a): ``r = [500 1500 2500 3500]`` (speed, rpm)."""

U2_BREAKPOINTS_MG_PER_STROKE: tuple[float, ...] = (0.0, 20.0, 40.0, 60.0)
"""SKF (20b): ``c = [0 20 40 60]`` (injected fuel, mg/stroke)."""

SIM1_SAMPLES = 1400
SIM2_SAMPLES = 200
SIM2_U1_RPM = 2000.0
SIM2_U2_STEP = 0.6  # 60 / 100 per sample
SIM3_NOISE_AMPLITUDE = 0.2
SAMPLE_PERIOD_S = 1.0

SIM2_EXCITED_ELEMENTS_PAPER: tuple[int, ...] = (5, 6, 7, 8, 9, 10, 11, 12)
"""The 8 cells the paper says sims 2/3 excite, 1-based row-by-row numbering (SKF §5.2, (22))."""

SIM2_AREAS_PAPER: tuple[tuple[int, int, int, int], ...] = (
    (5, 6, 9, 10),
    (6, 7, 10, 11),
    (7, 8, 11, 12),
)
"""The three active areas of sims 2/3, 1-based row-by-row numbering (SKF §5.2, (22))."""


@dataclass(frozen=True, slots=True)
class SkfSimFilterSettings:
    """Filter settings of SKF §5 (docs/algorithms.md §2.7), for callers running the checks.

    theta0 : initial table value of every cell (``x0 = 0``).
    P0 : initial variance of every cell (``P0 = [0]``).
    sigma_v2 : measurement noise variance ``σv²``.
    sigma_w2 : per-sample random-walk variance of each cell ``σw²`` (``Q = σw² I``).
    """

    theta0: float = 0.0
    P0: float = 0.0
    sigma_v2: float = 1.0
    sigma_w2: float = 1.0

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


SKF_SIM_FILTER_SETTINGS = SkfSimFilterSettings()
"""SKF §5: ``θ0 = 0``, ``P0 = 0``, ``σv² = σw² = 1`` for all three simulations."""


@dataclass(frozen=True, slots=True)
class SkfSimTruth:
    """Truth of one synthetic check (arrays read-only).

    number : 1, 2 or 3.
    table : the true table ``T_r`` (all ones, SKF (21)).
    y_true : (n,) noise-free output ``ψ(u_k)ᵀ vec(T_r) = 1`` (stored as exact ones).
    noise : (n,) the noise ``v_k`` added to ``y`` (zeros for sims 1 and 2).
    excited_cells : 0-based C-order flat indices of the cells with a positive weight.
    seed : the seed used (sim 2 draws nothing).
    """

    number: int
    table: Table
    y_true: np.ndarray
    noise: np.ndarray
    excited_cells: tuple[int, ...]
    seed: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary (lists, ints and floats only)."""
        return {
            "number": self.number,
            "table": self.table.to_dict(),
            "y_true": self.y_true.tolist(),
            "noise": self.noise.tolist(),
            "excited_cells": list(self.excited_cells),
            "seed": self.seed,
            "filter_settings": SKF_SIM_FILTER_SETTINGS.to_dict(),
        }


def skf_sim_table(values: float | np.ndarray = 1.0) -> Table:
    """A table on the grid of SKF (20): axes ``u1`` [rpm] × ``u2`` [mg/stroke]; default T_r."""
    return Table(
        (
            Axis("u1", "rpm", U1_BREAKPOINTS_RPM),
            Axis("u2", "mg/stroke", U2_BREAKPOINTS_MG_PER_STROKE),
        ),
        values,
    )


def sim2_u2_profile() -> np.ndarray:
    """``u2(k)`` of SKF §5.2 for ``k = 1…200``: ``60 − |0.6·k − 60|`` (0.6 … 60 … 0)."""
    k = np.arange(1, SIM2_SAMPLES + 1, dtype=np.float64)
    return 60.0 - np.abs(SIM2_U2_STEP * k - 60.0)


def skf_sim(
    number: Literal[1, 2, 3], *, seed: int = 0, noise_scale: float = 1.0
) -> tuple[Signals, SkfSimTruth]:
    """Data of simulation ``number`` of SKF §5 (see the module docstring).

    Parameters
    ----------
    number : 1 (random inputs, 1400 samples), 2 (u2 sweep, 200 samples) or 3 (2 + noise).
    seed : seed of ``np.random.default_rng`` (inputs of sim 1, noise of sim 3).
    noise_scale : factor on the noise of sim 3 (``U(−0.2s, 0.2s)``), applied after the draw so
        the same seed gives the same noise shape at every scale (0: noise-free).

    Returns
    -------
    signals : channels ``u1`` [rpm], ``u2`` [mg/stroke], ``y`` [-] at 1 Hz, ``t = 1, 2, … s``.
    truth : :class:`SkfSimTruth`.

    >>> signals, truth = skf_sim(2)
    >>> len(signals), float(signals["u2"].max()), truth.excited_cells
    (200, 60.0, (4, 5, 6, 7, 8, 9, 10, 11))
    """
    if isinstance(number, bool) or number not in (1, 2, 3):
        raise ConfigError(f"SKF simulation number must be 1, 2 or 3, got {number!r}")
    if not isinstance(seed, int | np.integer) or isinstance(seed, bool):
        raise ConfigError(f"seed must be an int, got {seed!r}")
    rng = np.random.default_rng(seed)
    table = skf_sim_table()
    if number == 1:
        u1 = rng.uniform(U1_BREAKPOINTS_RPM[0], U1_BREAKPOINTS_RPM[-1], SIM1_SAMPLES)
        u2 = rng.uniform(
            U2_BREAKPOINTS_MG_PER_STROKE[0], U2_BREAKPOINTS_MG_PER_STROKE[-1], SIM1_SAMPLES
        )
    else:
        u2 = sim2_u2_profile()
        u1 = np.full(u2.shape, SIM2_U1_RPM)
    U = np.column_stack([u1, u2])
    y_true = np.ones(u1.size)  # = ψ(u_k)ᵀ vec(T_r), written exactly as the paper's y_k = 1
    if number == 3:
        noise = rng.uniform(-SIM3_NOISE_AMPLITUDE, SIM3_NOISE_AMPLITUDE, y_true.size)
        noise *= float(noise_scale)
    else:
        noise = np.zeros_like(y_true)
    y = y_true + noise
    idx, w = table.regressor(U)
    excited = tuple(int(i) for i in np.unique(idx[w > 0.0]))
    time_s = SAMPLE_PERIOD_S * np.arange(1, y.size + 1, dtype=np.float64)
    signals = Signals(
        time_s, {"u1": u1, "u2": u2, "y": y}, {"u1": "rpm", "u2": "mg/stroke", "y": ""}
    )
    for arr in (y_true, noise):
        arr.setflags(write=False)
    truth = SkfSimTruth(
        number=int(number),
        table=table,
        y_true=y_true,
        noise=noise,
        excited_cells=excited,
        seed=int(seed),
    )
    return signals, truth
