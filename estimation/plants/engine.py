"""The diesel engine of the drive-cycle plants: full-load curve, friction and fuel.

:class:`DieselEngine` turns a brake torque at a speed into injected fuel (Willans line) and
gives the full-load and drag torques the gearbox and driver of
:mod:`estimation.plants.vehicle` and the WHTC denormalisation work against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimation.errors import ConfigError

__all__ = ["DieselEngine"]


@dataclass(frozen=True, slots=True)
class DieselEngine:
    """A ~2.0 L four-cylinder common-rail diesel (light duty), after the SKF paper's test engine.

    Full-load curve ``T_max(n)``: linear interpolation of ``full_load_torque_nm`` over
    ``full_load_speed_rpm`` (N·m, rpm; flat outside). Defaults: 380 N·m at 1750–2500 rpm,
    ≈121 kW at 4000 rpm (rated), governor cut to 0 N·m at 4500 rpm.

    Friction (drag) torque from a quadratic friction mean effective pressure::

        FMEP(n) = c0 + c1·(n/1000) + c2·(n/1000)²   [bar],   T_fr = FMEP·V_d/(4π)   [N·m]

    Fuel per cylinder and cycle (Willans line, 4-stroke: indicated work per cycle
    ``4π·(T_e + T_fr)`` shared by ``z`` cylinders)::

        u_δ = 4π·(T_e + T_fr) / (z·η_i(n)·Q_LHV)·10⁶   [mg/cycle],
        η_i(n) = η_i,max·(1 − k_η·((n − n_opt)/1000)²)

    so ≈64 mg/cycle at full load (the SKF NOx table spans 0–80 mg/cycle).
    """

    displacement_l: float = 2.0
    n_cylinders: int = 4
    idle_speed_rpm: float = 800.0
    rated_speed_rpm: float = 4000.0
    full_load_speed_rpm: tuple[float, ...] = (
        800.0, 1000.0, 1250.0, 1500.0, 1750.0, 2500.0, 3000.0, 3500.0, 4000.0, 4250.0, 4500.0,
    )  # fmt: skip
    full_load_torque_nm: tuple[float, ...] = (
        150.0, 200.0, 280.0, 340.0, 380.0, 380.0, 360.0, 330.0, 290.0, 200.0, 0.0,
    )  # fmt: skip
    friction_mep_bar: tuple[float, float, float] = (0.75, 0.25, 0.05)
    indicated_efficiency_max: float = 0.46
    efficiency_speed_rpm: float = 2000.0  # n_opt
    efficiency_curvature: float = 0.03  # k_η per (1000 rpm)²
    fuel_lhv_mj_per_kg: float = 42.8
    fuel_cut_min_rpm: float = 1000.0  # overrun fuel cut only above this speed

    def __post_init__(self) -> None:
        n = np.asarray(self.full_load_speed_rpm, dtype=np.float64)
        t = np.asarray(self.full_load_torque_nm, dtype=np.float64)
        if n.ndim != 1 or n.size < 2 or n.shape != t.shape or np.any(np.diff(n) <= 0):
            raise ConfigError(
                f"full-load curve needs >= 2 strictly increasing speeds with one torque each, "
                f"got speeds {self.full_load_speed_rpm} and torques {self.full_load_torque_nm}"
            )
        if np.any(t < 0):
            raise ConfigError(f"full-load torque must be >= 0, got {self.full_load_torque_nm}")
        if not 0 < self.idle_speed_rpm < self.rated_speed_rpm <= n[-1]:
            raise ConfigError(
                f"need 0 < idle ({self.idle_speed_rpm}) < rated ({self.rated_speed_rpm}) <= last "
                f"full-load speed ({n[-1]}) rpm"
            )
        if self.full_load_torque(self.rated_speed_rpm) <= 0:
            raise ConfigError("full-load torque at rated speed must be > 0")
        for name in ("displacement_l", "fuel_lhv_mj_per_kg", "indicated_efficiency_max"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.indicated_efficiency_max >= 1 or self.n_cylinders < 1:
            raise ConfigError("need 0 < indicated_efficiency_max < 1 and n_cylinders >= 1")
        eta_lo = self.indicated_efficiency(np.array([0.0, n[-1]])).min()
        if eta_lo <= 0:
            raise ConfigError(f"efficiency_curvature makes η_i <= 0 ({eta_lo:g}) in range")

    def full_load_torque(self, speed_rpm: np.ndarray | float) -> np.ndarray:
        """``T_max(n)`` in N·m."""
        return np.interp(speed_rpm, self.full_load_speed_rpm, self.full_load_torque_nm)

    def friction_torque(self, speed_rpm: np.ndarray | float) -> np.ndarray:
        """``T_fr(n) = FMEP(n)·V_d/(4π)`` in N·m (≥ 0; the motoring torque is ``−T_fr``)."""
        x = np.asarray(speed_rpm, dtype=np.float64) / 1000.0
        c0, c1, c2 = self.friction_mep_bar
        return (c0 + c1 * x + c2 * x * x) * 1e5 * self.displacement_l * 1e-3 / (4.0 * np.pi)

    def indicated_efficiency(self, speed_rpm: np.ndarray | float) -> np.ndarray:
        """``η_i(n) = η_i,max·(1 − k_η·((n − n_opt)/1000)²)``."""
        x = (np.asarray(speed_rpm, dtype=np.float64) - self.efficiency_speed_rpm) / 1000.0
        return self.indicated_efficiency_max * (1.0 - self.efficiency_curvature * x * x)

    def fuel_mg_per_cycle(
        self, torque_nm: np.ndarray | float, speed_rpm: np.ndarray | float
    ) -> np.ndarray:
        """Injected fuel ``u_δ`` in mg per cylinder and cycle for brake torque ``T_e`` (Willans).

        Clipped at 0: a torque at or below ``−T_fr`` needs no fuel.
        """
        work_j = 4.0 * np.pi * (np.asarray(torque_nm) + self.friction_torque(speed_rpm))
        per_cyl = work_j / (self.n_cylinders * self.indicated_efficiency(speed_rpm))
        return np.maximum(per_cyl / (self.fuel_lhv_mj_per_kg * 1e6) * 1e6, 0.0)
