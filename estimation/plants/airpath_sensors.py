"""What the air-path simulator puts into its measurements: the MAF error and sensor noise.

:class:`MafErrorSpec` is the injected MAF error with its true table — additive over
``(u_δ, n_e)`` (LPV (7), default :func:`default_maf_error_2d` on the LPV §4 grid) or relative
over ``W_c`` (EKF (6), default :func:`default_maf_relative_error`); :class:`NoiseSpec` the
white Gaussian noise of every sensor. :func:`estimation.plants.airpath.simulate_airpath`
applies both.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from estimation.errors import ConfigError
from estimation.table import Axis, Table

__all__ = [
    "FUEL_AXIS_MG",
    "MAF_AXIS_KG_S",
    "SPEED_AXIS_RPM",
    "MafErrorSpec",
    "NoiseSpec",
    "default_maf_error_2d",
    "default_maf_relative_error",
]

FUEL_AXIS_MG = np.arange(0.0, 56.0 + 1e-9, 4.0)  # LPV §4 grid, mg/cycle
SPEED_AXIS_RPM = np.arange(0.0, 3000.0 + 1e-9, 250.0)  # LPV §4 grid, rpm
MAF_AXIS_KG_S = np.linspace(0.0, 0.2, 11)  # EKF-style 1-D grid over W_c, kg/s


def default_maf_error_2d(fuel_mg_per_cycle: np.ndarray, speed_rpm: np.ndarray) -> np.ndarray:
    """Default additive MAF error ``ΔW_c(u_δ, n_e)`` [kg/s] (a smooth stand-in for LPV Fig. 3).

    With ``u = u_δ/56`` and ``n = n_e/3000``:
    ``ΔW_c = 10⁻³ (−0.4 + 1.6 n + 1.0 u n − 0.8 u² + 0.6 sin(π n) sin(π u))`` kg/s,
    i.e. −0.4 … +1.9 g/s: a few % of the flows of the ~2 L engine (15 g/s at idle,
    60–150 g/s at load), crossing zero at low speed so the map has both signs.
    """
    u = np.asarray(fuel_mg_per_cycle, dtype=np.float64) / 56.0
    n = np.asarray(speed_rpm, dtype=np.float64) / 3000.0
    return 1e-3 * (
        -0.4 + 1.6 * n + 1.0 * u * n - 0.8 * u * u + 0.6 * np.sin(np.pi * n) * np.sin(np.pi * u)
    )


def default_maf_relative_error(maf_kg_s: np.ndarray) -> np.ndarray:
    """Default relative MAF error ``q(W)`` [-] for EKF (6), ``w = W / 0.2 kg/s``:
    ``q = 0.04 − 0.07 w + 0.03 sin(2π w)`` (+5 % at low flow, −4 % near 0.15 kg/s)."""
    w = np.asarray(maf_kg_s, dtype=np.float64) / 0.2
    return 0.04 - 0.07 * w + 0.03 * np.sin(2.0 * np.pi * w)


@dataclass(frozen=True, slots=True)
class MafErrorSpec:
    """Which MAF error the simulator injects, with its true table.

    ``kind``: ``"additive_2d"`` (table over ``(fuel_mg_per_cycle, speed_rpm)``, values in
    kg/s, LPV (7)), ``"relative_1d"`` (table over ``maf_kg_s``, values ``q`` dimensionless,
    EKF (6)) or ``"none"``. With ``function`` (points ``(n, d)`` in the table's axis order →
    values) the plant evaluates it off-grid instead of interpolating ``table``, which then
    only describes the truth at the nodes (:mod:`estimation.truth_maps`, docs/fidelity.md).
    """

    kind: Literal["additive_2d", "relative_1d", "none"]
    table: Table | None = None
    function: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        if self.kind == "none":
            if self.table is not None:
                raise ConfigError("MafErrorSpec(kind='none') takes no table")
            return
        if self.kind not in ("additive_2d", "relative_1d"):
            raise ConfigError(
                f"MafErrorSpec.kind must be 'additive_2d', 'relative_1d' or 'none', "
                f"got {self.kind!r}"
            )
        if not isinstance(self.table, Table):
            raise ConfigError(f"MafErrorSpec({self.kind!r}) needs a Table, got {self.table!r}")
        want = 2 if self.kind == "additive_2d" else 1
        if self.table.ndim != want:
            raise ConfigError(
                f"MafErrorSpec({self.kind!r}) needs a {want}-D table, got {self.table.ndim}-D"
            )
        if self.kind == "relative_1d" and np.any(self.table.values <= -1.0):
            raise ConfigError(
                f"relative MAF error q must be > -1 everywhere, got min {self.table.values.min()}"
            )

    @classmethod
    def none(cls) -> MafErrorSpec:
        return cls("none")

    @classmethod
    def additive_2d(cls, table: Table | None = None) -> MafErrorSpec:
        """LPV (7) additive map; default :func:`default_maf_error_2d` on the LPV grid."""
        if table is None:
            uu, nn = np.meshgrid(FUEL_AXIS_MG, SPEED_AXIS_RPM, indexing="ij")
            table = Table(
                [
                    Axis("fuel_mg_per_cycle", "mg/cycle", FUEL_AXIS_MG),
                    Axis("speed_rpm", "rpm", SPEED_AXIS_RPM),
                ],
                default_maf_error_2d(uu, nn),
            )
        return cls("additive_2d", table)

    @classmethod
    def relative_1d(cls, table: Table | None = None) -> MafErrorSpec:
        """EKF (6) relative map; default :func:`default_maf_relative_error` on 0:0.02:0.2."""
        if table is None:
            table = Table(
                [Axis("maf_kg_s", "kg/s", MAF_AXIS_KG_S)],
                default_maf_relative_error(MAF_AXIS_KG_S),
            )
        return cls("relative_1d", table)

    def error_kg_s(
        self, w_c_kg_s: np.ndarray, fuel_mg_per_cycle: np.ndarray, speed_rpm: np.ndarray
    ) -> np.ndarray:
        """The injected error ``W_c,meas − W_c`` [kg/s] (before noise) at each sample."""
        w = np.asarray(w_c_kg_s, dtype=np.float64)
        if self.kind == "none":
            return np.zeros_like(w)
        assert self.table is not None
        evaluate = self.table.evaluate if self.function is None else self.function
        if self.kind == "additive_2d":
            return evaluate(np.column_stack([fuel_mg_per_cycle, speed_rpm]))
        return evaluate(w[:, None]) * w

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "table": None if self.table is None else self.table.to_dict(),
            "off_grid": self.function is not None,
        }


@dataclass(frozen=True, slots=True)
class NoiseSpec:
    """White Gaussian sensor noise: standard deviation of one sensor reading (0: channel off).

    ``maf_rel`` and ``omega_t_rel`` are relative to the reading (1 % and 0.5 %);
    ``p_im_pa``, ``p_em_pa`` absolute (1 kPa); ``speed_rpm``, ``fuel_mg`` absolute (0: the
    crank-angle speed and the ECU fuel command are taken as exact).

    ``averaged_readings`` (N ≥ 1) is the ECU's sampling model: each logged sample is the mean
    of N independent readings taken over the sample period (a boxcar anti-aliasing filter,
    e.g. an ECU reading its sensors in a 10 ms task and logging at 10 Hz: N = 10). The
    logged noise of every channel is then ``σ/√N`` (:meth:`logged_scale`). The signal itself
    is point-sampled: the boxcar's delay of half a sample period is not modelled. With the
    default N = 1 the levels above are those of the logged samples.
    """

    maf_rel: float = 0.01
    p_im_pa: float = 1000.0
    p_em_pa: float = 1000.0
    omega_t_rel: float = 0.005
    speed_rpm: float = 0.0
    fuel_mg: float = 0.0
    averaged_readings: int = 1

    def __post_init__(self) -> None:
        for name in ("maf_rel", "p_im_pa", "p_em_pa", "omega_t_rel", "speed_rpm", "fuel_mg"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ConfigError(f"NoiseSpec.{name} must be finite and ≥ 0, got {v}")
        n = self.averaged_readings
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= 100_000:
            raise ConfigError(f"NoiseSpec.averaged_readings must be an integer ≥ 1, got {n!r}")

    @classmethod
    def off(cls) -> NoiseSpec:
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def scaled(self, factor: float) -> NoiseSpec:
        """Every σ multiplied by ``factor`` (≥ 0; the averaging unchanged): the logging's
        noise at an unexpected level (``Scenario.build(noise_scale=…)``)."""
        if not np.isfinite(factor) or factor < 0:
            raise ConfigError(f"noise scale must be finite and ≥ 0, got {factor!r}")
        return NoiseSpec(
            maf_rel=self.maf_rel * factor,
            p_im_pa=self.p_im_pa * factor,
            p_em_pa=self.p_em_pa * factor,
            omega_t_rel=self.omega_t_rel * factor,
            speed_rpm=self.speed_rpm * factor,
            fuel_mg=self.fuel_mg * factor,
            averaged_readings=self.averaged_readings,
        )

    def logged_scale(self) -> float:
        """Factor ``1/√N`` from a reading's σ to the logged sample's σ."""
        return 1.0 / float(np.sqrt(self.averaged_readings))

    def to_dict(self) -> dict[str, float]:
        return {
            "maf_rel": self.maf_rel,
            "p_im_pa": self.p_im_pa,
            "p_em_pa": self.p_em_pa,
            "omega_t_rel": self.omega_t_rel,
            "speed_rpm": self.speed_rpm,
            "fuel_mg": self.fuel_mg,
            "averaged_readings": int(self.averaged_readings),
        }
