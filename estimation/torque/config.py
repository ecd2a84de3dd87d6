"""Typed configurations of the torque estimators (TQ §III, §V; docs/algorithms.md §5).

Defaults are the paper's simulation values (TQ §VI): ``k = 0.01 s``, ``λ1 = 150 N·m``,
``ℓ = 10 s⁻¹``, ``Γ = diag(0.1, 100)`` for TQ (50), ``κ = 0.1``. TQ gives no Γ for (54) but
a scalar (Theorem 4); see :class:`AdaptiveTvConfig`. The inertia defaults to
:data:`DEFAULT_J_NM_S_PER_RPM` (N·m·s/rpm, since ``N`` is in rpm); set it to the engine's own
value (a scenario passes its estimator-side value, docs/fidelity.md). The paper gives no
``K0`` for TQ (52); its effect decays as ``e^{−ℓt}`` (TQ (53)), so the default only shapes
the first second.

Units matter for TQ (50), not (54): with ``ṁ_ai`` in kg/s (TQ Table I) the constant gain
``Γ2 = 100`` moves θ2 at ``Γ2·λ(P) ≈ 100·ṁ_ai²/ℓ ≈ 3·10⁻³ s⁻¹``, i.e. not at all, so (50)
adapts θ1 alone (``τ̂_e ≈ N·θ̂1``); TQ's ratio Γ2/Γ1 = 1000 would balance the two only with
``ṁ_ai`` of order ``N/30`` (kg/h). (54) normalises by ``K ≈ P⁻¹`` and does not care.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from estimation.torque.channels import AIR_CHANNEL, LOAD_CHANNEL, SPEED_CHANNEL

AIR_UNIT_SCALE: dict[str, float] = {"kg/s": 1.0, "g/s": 1.0e3, "kg/h": 3.6e3}
"""Factor from the measured ṁ_ai [kg/s] to the unit it enters the regressor Φ in."""

DEFAULT_J_NM_S_PER_RPM: float = 0.15 * (2.0 * math.pi / 60.0)
"""Scaled crankshaft inertia ``inertia·2π/60`` [N·m·s/rpm] of a 2 L four-cylinder with a
single-mass flywheel, 0.15 kg·m² (crankshaft, damper and rods ≈ 0.04–0.06 plus flywheel
≈ 0.08–0.12: 0.1–0.2 kg·m²; docs/algorithms.md §5); the SI scenario's plant has this value
(``tests/estimation/test_mismatch.py``)."""


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
    air_unit: Literal["kg/s", "g/s", "kg/h"] = Field(
        "kg/s",
        description="Unit of ṁ_ai inside Φ = [N, ṁ_ai] (TQ Table I: kg/s). It sets the units "
        "of θ2, theta0[1] and K0[1], and what Γ2 of TQ (50) means (module docstring).",
    )
    ell: float = Field(
        10.0, gt=0.0, description="Forgetting rate ℓ of P, Q (TQ (45)) and K (TQ (52)) [1/s]."
    )
    gamma: tuple[float, float] = Field(
        (0.1, 100.0),
        description="Diagonal of the constant learning gain Γ of TQ (50), for θ1 and θ2 "
        "[1/(rpm²·s²), 1/((air unit)²·s²)] (paper: diag(0.1, 100)).",
    )
    kappa: float = Field(
        0.1,
        ge=0.0,
        description="Weight κ of the instantaneous error W2 (TQ (47)) [-]; the paper "
        "compares 0 and 0.1.",
    )
    theta0: tuple[float, float] = Field(
        (0.0, 0.0),
        description="Initial estimate Θ̂(0) = [θ1 N·m/rpm, θ2 N·m/(air unit)] (paper: zero).",
    )


class AdaptiveConstConfig(AdaptiveConfig):
    """Constant learning gain, TQ (50): ``Θ̂' = −Γ(W1 + κW2)``."""


class AdaptiveTvConfig(AdaptiveConfig):
    """Time-varying learning gain, TQ (52)/(54): ``K̇ = ℓK − KΦ_fᵀΦ_fK``, ``K(0) = K0⁻¹``,
    ``Θ̂' = −ΓK(W1 + κW2)``."""

    K0: tuple[float, float] = Field(
        (1.0, 1.0e-6),
        description="Diagonal of K0 = K(0)⁻¹ of TQ (52), positive [rpm²·s, (air unit)²·s]; "
        "not given in TQ, forgotten as e^{−ℓt} (TQ (53)), so it shapes only the first second.",
    )
    gamma: tuple[float, float] = Field(
        (10.0, 10.0),
        description="Diagonal of Γ in TQ (54) [1/s]; K ≈ P⁻¹ makes it a rate, independent of the "
        "units of Φ. TQ's Theorem 4 needs Γ scalar and gives no value (diag(0.1, 100) is stated "
        "for (50)); with that diagonal ΓK(P + κΦ_fᵀΦ_f) has an unstable eigenvalue on about "
        "half the samples of both scenarios when κ = 0.1, and (54) diverges. Default: Γ = 10·I, "
        "chosen by the declared rule of app/reproduce/sensitivity.py (grid 1, 3, 10, 30, 100; "
        "lowest seed-mean ISE on torque-si tuning seeds 0–4, nominal mismatch; "
        "docs/estimators.md#dev-tq-gamma-54).",
    )
