"""Typed configurations of the torque estimators (TQ §III, §V; ALGORITHMS.md §5).

Defaults are the paper's simulation values (TQ §VI): ``k = 0.01 s``, ``λ1 = 150 N·m``,
``ℓ = 10 s⁻¹``, ``Γ = diag(0.1, 100)``, ``κ = 0.1``. The inertia defaults to the SI plant's
scaled ``J`` (N·m·s/rpm, since ``N`` is in rpm); set it to the engine's own value (the rig's
is in its scenario truth, ``J_nm_s_per_rpm``). The paper gives no ``K0`` for TQ (52); its
effect decays as ``e^{−ℓt}`` (TQ (53)), so the default only shapes the first second.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from estimation.plants.torque import AIR_CHANNEL, LOAD_CHANNEL, SPEED_CHANNEL, SiEngineParams

DEFAULT_J_NM_S_PER_RPM: float = SiEngineParams().J_nm_s_per_rpm
"""Scaled crankshaft inertia of the SI plant, ``inertia·2π/60`` [N·m·s/rpm]."""


class TorqueEstimatorConfig(BaseModel):
    """What every torque estimator needs: the channels, the inertia and the filter constant."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    speed_channel: str = Field(
        SPEED_CHANNEL, min_length=1, description="Measured engine speed N channel [rpm]."
    )
    load_channel: str = Field(
        LOAD_CHANNEL, min_length=1, description="Measured load torque τ_l channel [N·m]."
    )
    J_nm_s_per_rpm: float = Field(
        DEFAULT_J_NM_S_PER_RPM,
        gt=0.0,
        description="Crankshaft inertia J of TQ (8) scaled for N in rpm [N·m·s/rpm] "
        "(= inertia [kg·m²]·2π/60).",
    )
    k: float = Field(
        0.01,
        gt=0.0,
        description="Filter time constant k of TQ (9)/(21)/(23)/(42) [s]; keep it ≫ the "
        "sample period (paper: 0.01 s).",
    )


class UioConfig(TorqueEstimatorConfig):
    """Unknown input observer, TQ (9), (14)."""


class DirtyConfig(TorqueEstimatorConfig):
    """Dirty-differentiation estimator, TQ (23)–(24)."""


class SmoConfig(TorqueEstimatorConfig):
    """Sliding-mode estimator, TQ (19)–(21)."""

    lambda1: float = Field(
        150.0,
        gt=0.0,
        description="Switching gain λ1 of TQ (19) [N·m]; must exceed |τ_e| (paper: 150 in "
        "simulation, 350 on the rig).",
    )


class AdaptiveConfig(TorqueEstimatorConfig):
    """Adaptive parameter laws of TQ (41)–(54): ``τ_e = ΦΘ``, ``Φ = [N, ṁ_ai]``."""

    air_channel: str = Field(
        AIR_CHANNEL, min_length=1, description="Measured intake air mass flow ṁ_ai [kg/s]."
    )
    ell: float = Field(
        10.0, gt=0.0, description="Forgetting rate ℓ of P, Q (TQ (45)) and K (TQ (52)) [1/s]."
    )
    gamma: tuple[float, float] = Field(
        (0.1, 100.0),
        description="Diagonal of the learning gain Γ of TQ (50)/(54), for θ1 [N·m/rpm] and "
        "θ2 [N·m/(kg/s)] (paper: diag(0.1, 100)).",
    )
    kappa: float = Field(
        0.1,
        ge=0.0,
        description="Weight κ of the instantaneous error W2 (TQ (47)) [-]; the paper "
        "compares 0 and 0.1.",
    )
    theta0: tuple[float, float] = Field(
        (0.0, 0.0),
        description="Initial estimate Θ̂(0) = [θ1 N·m/rpm, θ2 N·m/(kg/s)] (paper: zero).",
    )


class AdaptiveConstConfig(AdaptiveConfig):
    """Constant learning gain, TQ (50): ``Θ̂' = −Γ(W1 + κW2)``."""


class AdaptiveTvConfig(AdaptiveConfig):
    """Time-varying learning gain, TQ (52)/(54): ``K̇ = ℓK − KΦ_fᵀΦ_fK``, ``K(0) = K0⁻¹``,
    ``Θ̂' = −ΓK(W1 + κW2)``."""

    K0: tuple[float, float] = Field(
        (1.0, 1.0e-6),
        description="Diagonal of K0 = K(0)⁻¹ of TQ (52), positive [rpm²·s, (kg/s)²·s]; "
        "not given in TQ, forgotten as e^{−ℓt}.",
    )
    gamma: tuple[float, float] = Field(
        (10.0, 10.0),
        description="Diagonal of Γ in TQ (54) [1/s]. TQ's stability proof (Theorem 4) takes Γ "
        "scalar and gives no value; the (50) gain diag(0.1, 100) makes ΓK lose definiteness "
        "and (54) diverge on our plants, so the default is scalar (10 chosen on torque-si "
        "seed 0 from 1, 10, 30, 100, 300, 1000).",
    )
