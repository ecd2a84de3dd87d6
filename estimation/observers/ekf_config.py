"""Settings of the three air-path EKF variants (docs/algorithms.md §4; EKF §5.1).

Pydantic models whose JSON schema the dashboard renders as a form: the measured channels
(:class:`EkfChannels`), the noise and start-up settings shared by every variant
(:class:`EkfConfig`) and what each variant adds — the MAF bias of ``ekf-aug``
(:class:`EkfAugConfig`) and the correction map of ``ekf-map`` (:class:`EkfMapConfig`). The
observer that reads them is :mod:`estimation.observers.ekf`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from estimation.observers.airpath_model import AirpathModelConfig

__all__ = [
    "DEFAULT_MAF_AXIS",
    "OUTPUT_NAMES",
    "EkfAugConfig",
    "EkfChannels",
    "EkfConfig",
    "EkfDefConfig",
    "EkfMapConfig",
    "Output",
]

OUTPUT_NAMES = ("maf", "p_im", "p_em", "omega_t")  # in kernel column order (Y_*)
Output = Literal["maf", "p_im", "p_em", "omega_t"]

DEFAULT_MAF_AXIS = [round(0.02 * i, 2) for i in range(11)]  # the EKF-style grid, kg/s


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


Triple = tuple[float, float, float]


class EkfChannels(_Strict):
    """Names of the measured channels the observer reads."""

    u_egr: str = Field("u_egr_pos_pct", description="EGR valve position ũ_egr [%].")
    u_vgt: str = Field("u_vgt_pos_pct", description="VGT position ũ_vgt [%].")
    fuel: str = Field("fuel_mg_per_cycle", description="Injected fuel u_δ [mg/cycle].")
    speed: str = Field("speed_rpm", description="Engine speed n_e [rpm].")
    maf: str = Field("maf_kg_s", description="MAF sensor reading W_c,meas [kg/s].")
    p_im: str = Field("p_im_pa", description="Intake manifold pressure sensor [Pa].")
    p_em: str = Field("p_em_pa", description="Exhaust manifold pressure sensor [Pa].")
    omega_t: str = Field("omega_t_rad_s", description="Turbo speed sensor [rad/s].")

    def inputs(self) -> list[str]:
        """Input channels in the kernel's ``U_*`` column order."""
        return [self.u_egr, self.u_vgt, self.fuel, self.speed]

    def output(self, name: str) -> str:
        return str(getattr(self, name))


class EkfConfig(_Strict):
    """Settings shared by the three EKF variants (standard deviations, SI units).

    Measurement noise of the MAF: ``R = sigma_maf_abs² + (sigma_maf_rel · y)²``; of the other
    sensors ``sigma_p_im²``, ``sigma_p_em²``, ``(sigma_omega_t_rel · y)²`` — the defaults are
    single sensor readings of 1 % (MAF), 1 kPa and 0.5 % (ω_t). Process noise is
    white with intensity ``σ²`` per second: a parameter receives ``σ² Δt`` over a sample
    period ``Δt``; for the states it is integrated along the model's dynamics
    (``∫ Φ(s) diag(σ²) Φ(s)ᵀ ds``), so the stiff ``p_im`` holds about ``σ²/(2|λ|)``.
    """

    channels: EkfChannels = Field(default_factory=EkfChannels)
    model: AirpathModelConfig = Field(
        default_factory=AirpathModelConfig,
        description="The observer's air-path model (estimation.observers.airpath_model).",
    )
    outputs: list[Output] = Field(
        default_factory=lambda: ["maf"],
        min_length=1,
        description="Measured outputs fed back (EKF §5.2 simulation study: the MAF only).",
    )
    sigma_maf_rel: float = Field(0.01, ge=0.0, description="Relative σ of the MAF reading.")
    sigma_maf_abs: float = Field(2e-4, gt=0.0, description="Absolute σ of the MAF [kg/s].")
    sigma_p_im: float = Field(1000.0, gt=0.0, description="σ of the p_im sensor [Pa].")
    sigma_p_em: float = Field(1000.0, gt=0.0, description="σ of the p_em sensor [Pa].")
    sigma_omega_t_rel: float = Field(0.005, gt=0.0, description="Relative σ of the ω_t sensor.")
    sigma_state: Triple = Field(
        (500.0, 1000.0, 20.0),
        description="Process noise intensity σ of (p_im Pa, p_em Pa, ω_t rad/s) per √s.",
    )
    sigma0_state: Triple = Field(
        (2e4, 3e4, 2000.0), description="Initial σ of (p_im Pa, p_em Pa, ω_t rad/s)."
    )
    x0: Triple | None = Field(
        None,
        description="Initial (p_im Pa, p_em Pa, ω_t rad/s); default: the model settled for "
        "settle_s at the first sample's inputs.",
    )
    settle_s: float = Field(30.0, gt=0.0, le=600.0, description="Settling time of x0 [s].")
    max_step_s: float = Field(
        0.005,
        gt=0.0,
        le=1.0,
        description="Longest exponential-Euler step of the prediction [s].",
    )
    gate_sigma: float | None = Field(
        5.0,
        gt=0.0,
        description="Innovation gate: an output with e²/s > gate_sigma² is not used (χ², "
        "1 dof; null: no gate).",
    )
    limit: Literal["none", "p0", "diag"] = Field(
        "p0",
        description="Cap parameter variances at P0 (EKF §3.1): p0 = PSD-preserving, "
        "P ← D·P·D with D_ii = √(P0_ii/P_ii) (mapwise); diag = the paper's literal "
        "P_ii ← min(P_ii, P0_ii), off-diagonals untouched (P can become indefinite); "
        "none = no cap.",
    )

    @field_validator("sigma_state", "sigma0_state")
    @classmethod
    def _non_negative(cls, v: Triple) -> Triple:
        if any(not np.isfinite(a) or a < 0 for a in v):
            raise ValueError(f"must be finite and ≥ 0, got {list(v)}")
        return v

    @field_validator("x0")
    @classmethod
    def _positive(cls, v: Triple | None) -> Triple | None:
        if v is not None and any(not np.isfinite(a) or a <= 0 for a in v):
            raise ValueError(f"must be finite and > 0, got {list(v)}")
        return v

    @field_validator("outputs")
    @classmethod
    def _unique(cls, v: list[str]) -> list[str]:
        if len(set(v)) != len(v):
            raise ValueError(f"names an output twice: {v}")
        return v


class EkfDefConfig(EkfConfig):
    """Def: the default model, no MAF correction (EKF §5.1)."""


class EkfAugConfig(EkfConfig):
    """Aug: one random-walk bias ``b`` [kg/s] added to the MAF output (EKF §5.1)."""

    sigma_bias: float = Field(
        2e-3, ge=0.0, description="Random-walk σ of b per √s [kg/s] (as fast as the system)."
    )
    sigma0_bias: float = Field(0.01, gt=0.0, description="Initial σ of b (also its cap) [kg/s].")


class EkfMapConfig(EkfConfig):
    """Map: 1-D relative correction map ``q(W, θ)`` on the MAF (EKF §5.1, (6))."""

    breakpoints: list[float] = Field(
        default_factory=lambda: list(DEFAULT_MAF_AXIS),
        min_length=2,
        description="Strictly increasing breakpoints of q over W [kg/s].",
    )
    theta0: float = Field(0.0, gt=-1.0, description="Initial map value q [-].")
    sigma_theta: float = Field(
        2e-3, ge=0.0, description="Random-walk σ of each grid value per √s [-] (slow: aging)."
    )
    sigma0_theta: float = Field(
        0.1, gt=0.0, description="Initial σ of each grid value (also its cap) [-]."
    )

    @field_validator("breakpoints")
    @classmethod
    def _increasing(cls, g: list[float]) -> list[float]:
        for i in range(len(g) - 1):
            if not g[i] < g[i + 1]:
                raise ValueError(f"must be strictly increasing; {g[i]:g} then {g[i + 1]:g}")
        return g
