"""Settings of the LPV adaptive observer of a MAF-sensor error map (LPV §4).

A pydantic model whose JSON schema the dashboard renders as a form: the map's grid, the
adaptation law and gain, the LMI's ε, where ρ comes from and the measured channels. The
observer that reads it, and why its defaults differ from a literal reading of the paper, is
:mod:`estimation.observers.lpv`.
"""

from __future__ import annotations

from typing import Literal, Self

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from estimation.filters.config import AxisConfig
from estimation.observers.airpath_model import AirpathModelConfig

__all__ = ["FUEL_AXIS_MG", "SPEED_AXIS_RPM", "LpvConfig"]

FUEL_AXIS_MG = [float(v) for v in np.arange(0.0, 56.0 + 1e-9, 4.0)]
SPEED_AXIS_RPM = [float(v) for v in np.arange(0.0, 3000.0 + 1e-9, 250.0)]


def _default_axes() -> list[AxisConfig]:
    return [
        AxisConfig(name="fuel_mg_per_cycle", breakpoints=FUEL_AXIS_MG, unit="mg/cycle"),
        AxisConfig(name="speed_rpm", breakpoints=SPEED_AXIS_RPM, unit="rpm"),
    ]


class LpvConfig(BaseModel):
    """Settings of the LPV observer (LPV §4: grid, ε = 0.25 / 0.11; see
    :mod:`estimation.observers.lpv` for the adaptation gain, the gain structure and ρ1)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    axes: list[AxisConfig] = Field(default_factory=_default_axes, min_length=1)
    adaptation: Literal["normalised", "constant"] = Field(
        "normalised",
        description="Γ = diag((1/γ + ∫ψ_j² dt)⁻¹) ('normalised') or Γ = γI ('constant', the "
        "paper's law with γ = 200).",
    )
    gamma: float = Field(
        10.0,
        gt=0,
        description="Initial adaptation gain γ [1/s per unit ψ²]: Γ = γI when constant. The "
        "default 10 is the declared rule's choice for the normalised gain (grid 1–1000, tuning "
        "seeds 0–4, nominal, lowest MRE over the papers' segments: docs/tuning.md"
        "#declared-rules).",
    )
    gain_structure: Literal["decoupled", "full"] = Field(
        "decoupled", description="LMI gain structure (estimation.observers.lmi)."
    )
    rho1: str = Field(
        "rho1",
        description="Channel of ρ1 [kg/rad]: 'rho1' (intake-manifold balance) or "
        "'rho1_compressor' (the compressor map, LPV (3) literally).",
    )
    eps1: float = Field(0.25, gt=0, description="ε1 of the LMI (LPV (28)).")
    eps2: float = Field(0.11, gt=0, description="ε2 of the LMI (LPV (28)).")
    a1: float | None = Field(None, gt=0, description="R_a T_im / V_im; default: from model.")
    a2: float | None = Field(
        None, gt=0, description="R_e T_em / V_em; default: from model at the mean T_em."
    )
    model: AirpathModelConfig = Field(
        default_factory=AirpathModelConfig,
        description="The observer's air-path model (a1, a2 and, with rho_source='model', ρ).",
    )
    rho_source: Literal["channels", "model"] = Field(
        "channels",
        description="ρ from the log's channels rho1…rho5 ('channels') or computed with the "
        "observer's model from the measured signals ('model').",
    )
    rho_min: list[float] | None = Field(None, description="ρ box lower bounds; default: data.")
    rho_max: list[float] | None = Field(None, description="ρ box upper bounds; default: data.")
    rho4_floor: float = Field(
        0.1,
        ge=0,
        lt=1,
        description="Lower ρ4 bound of a data box is at least this fraction of its maximum "
        "(ρ2 = ρ4 = 0 leaves p_em unobservable and marginal, the LMI infeasible).",
    )
    turbine_power: Literal["derivative", "zero"] = "derivative"
    adapt_only_with_flow: bool = Field(
        True,
        description="Freeze θ where ρ1 = 0: the compressor model then predicts no flow, so "
        "the whole MAF reading would be taken for sensor error.",
    )
    fill: Literal["none", "quadratic", "smooth"] = Field(
        "none",
        description="Fill of the finished map's unvisited cells (ψ weight < 1): 'quadratic' "
        "is LPV (37)'s surface (2-D maps, >= 6 visited cells), 'smooth' the smoothest "
        "continuation of the visited part (estimation/observers/lpv_fill.py); 'none' keeps "
        "their initial value. The state is not filled.",
    )
    p_im: str = Field("p_im_pa", description="Intake manifold pressure [Pa].")
    p_em: str | None = Field(
        "p_em_pa", description="Exhaust manifold pressure [Pa]; only used to initialise x̂2."
    )
    omega_t: str = Field("omega_t_rad_s", description="Turbocharger speed [rad/s].")
    maf: str = Field("maf_kg_s", description="MAF sensor reading W_c + ΔW_c [kg/s].")
    fuel_flow: str = Field("w_f_kg_s", description="Fuel mass flow W_f [kg/s].")
    t_em: str | None = Field(
        "t_em_k", description="Exhaust temperature [K] for the default a2 (rho_source='channels')."
    )
    u_egr: str = Field("u_egr_pos_pct", description="EGR valve position [%] (rho_source='model').")
    u_vgt: str = Field("u_vgt_pos_pct", description="VGT position [%] (rho_source='model').")
    fuel: str = Field("fuel_mg_per_cycle", description="Fuel [mg/cycle] (rho_source='model').")
    speed: str = Field("speed_rpm", description="Engine speed [rpm] (rho_source='model').")

    @model_validator(mode="after")
    def _check(self) -> Self:
        if self.eps1 + self.eps2 >= 2.0:
            raise ValueError(f"eps1 + eps2 must be < 2, got {self.eps1} + {self.eps2}")
        for name in ("rho_min", "rho_max"):
            v = getattr(self, name)
            if v is not None and len(v) != 5:
                raise ValueError(f"{name} needs 5 values, got {len(v)}")
        if (self.rho_min is None) != (self.rho_max is None):
            raise ValueError("give both rho_min and rho_max, or neither")
        return self
