"""The air-path model an observer runs: its own calibration of the W&E mean value model.

The LPV observer (:mod:`estimation.observers.lpv`) and the EKFs (:mod:`estimation.observers.ekf`)
evaluate the Wahlström & Eriksson (2011) air-path model (LPV (1)–(3); docs/algorithms.md §4, §6)
with the parameter vector of :mod:`estimation.kernels.airpath_plant`. The values they use are
*theirs*, stated here, not read from the simulator: :data:`MODEL_DEFAULTS` is the calibration
of the ~2 L four-cylinder engine the scenarios simulate (the nominal values of the plant when
this table was written; ``tests/estimation/test_mismatch.py`` checks they still agree, so
``mismatch="none"`` reproduces the perfect-model runs). :class:`AirpathModelConfig` lets a
config override the constants a real calibration is least sure of — manifold volumes,
volumetric, compressor and turbine efficiencies, flow areas, turbo inertia — which is how a
scenario under ``mismatch="nominal"`` hands an observer its drawn and then identified model
(:mod:`estimation.mismatch`, :mod:`estimation.observers.airpath_identify`, docs/fidelity.md).

:func:`model_rho` is the scheduling vector ρ of LPV (3) computed with this model from measured
signals (ρ1 by the intake-manifold balance, as :mod:`estimation.observers.lpv` documents).
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from estimation import kernels
from estimation.errors import ConfigError, ShapeError

__all__ = ["MODEL_DEFAULTS", "TUNABLE", "AirpathModelConfig", "model_rho"]

MODEL_DEFAULTS: dict[str, float] = {
    "R_a": 287.0,
    "R_e": 286.0,
    "c_pa": 1011.0,
    "c_pe": 1332.0,
    "c_va": 724.0,
    "gamma_a": 1.3964088398,
    "gamma_e": 1.2734225621,
    "T_amb": 298.4636219512,
    "p_amb": 101111.3414634146,
    "T_im": 300.6185731707,
    "V_im": 0.003453689167974882,
    "V_em": 0.0031397174254317113,
    "r_c": 17.0,
    "V_d": 0.002,
    "n_cyl": 4.0,
    "q_HV": 42900000.0,
    "AFs": 14.57,
    "X_Oc": 0.2314,
    "hA_pipe": 18.298725779974568,
    "c_vol1": -0.00020816619843,
    "c_vol2": -0.0027083549353699365,
    "c_vol3": 1.1497021021,
    "eta_sc": 1.1015294625,
    "x_cv": 2.3370584442e-14,
    "R_c": 0.022000000000000002,
    "c_wpsi1": 3.2918204435325007e-09,
    "c_wpsi2": -9.525868198000001e-05,
    "c_wpsi3": 1.0286164756,
    "c_wphi1": -4.325079262212501e-09,
    "c_wphi2": -0.0008524347780300001,
    "c_wphi3": 29.646172151,
    "c_psi2": 0.0,
    "c_phi2": 0.0,
    "Q_c11": 33.788924455979775,
    "Q_c12": -8.206016986115701,
    "Q_c22": 2.147855962,
    "eta_cmax": 0.736360788,
    "W_copt": 0.08328961631650002,
    "pi_copt": 1.0455177468,
    "c_pi": 0.2707594739,
    "A_egrmax": 0.00012100000000000003,
    "PI_egropt": 0.6500040483,
    "c_egr1": -0.0001110424,
    "c_egr2": 0.0177806123,
    "c_egr3": 0.0,
    "tau_egr1": 0.05,
    "tau_egr2": 0.13,
    "K_egr": 1.8,
    "tau_degr": 0.065,
    "A_vgtmax": 0.000332523037275,
    "R_t": 0.022000000000000002,
    "BSR_opt": 0.9755203162,
    "c_m1": 1.3482594520651208,
    "c_m2": 5034.925821090909,
    "c_m3": 0.010000098745,
    "w_tlin": 5085.2750792590905,
    "c_mlin": 1.4021470818,
    "K_t": 2.8901926611,
    "c_f1": 1.9479627004,
    "c_f2": -0.7763118933,
    "c_vgt1": 126.8719357229,
    "c_vgt2": 117.1447468823,
    "eta_tmmax": 0.8180027269,
    "tau_vgt": 0.025,
    "tau_dvgt": 0.04,
    "J_t": 2.5e-05,
    "eta_min": 0.2,
    "z_lin": 0.01,
    "omega_t_min": 200.0,
    "omega_t_max": 30000.0,
    "A_cr": 0.001,
    "dp_lin": 500.0,
}
"""The observer's W&E parameter set (SI units, symbols and order of
:data:`estimation.kernels.airpath_plant.PARAM_NAMES`): the Scania set of W&E (2011) scaled to
a 2.0 L four-cylinder engine (docs/algorithms.md §6)."""

TUNABLE = (
    "V_im",
    "V_em",
    "c_vol1",
    "c_vol2",
    "c_vol3",
    "eta_cmax",
    "eta_tmmax",
    "A_egrmax",
    "A_vgtmax",
    "J_t",
)
"""The constants :class:`AirpathModelConfig` exposes (and a mismatch draw perturbs)."""


class AirpathModelConfig(BaseModel):
    """The observer's air-path model: :data:`MODEL_DEFAULTS` with these constants overridden.

    Defaults are the values of :data:`MODEL_DEFAULTS`.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    V_im: float = Field(MODEL_DEFAULTS["V_im"], gt=0, description="Intake manifold volume [m³].")
    V_em: float = Field(MODEL_DEFAULTS["V_em"], gt=0, description="Exhaust manifold volume [m³].")
    c_vol1: float = Field(
        MODEL_DEFAULTS["c_vol1"], description="η_vol = c_vol1 √p_im + … [Pa^-1/2] (W&E (14))."
    )
    c_vol2: float = Field(
        MODEL_DEFAULTS["c_vol2"], description="η_vol = … + c_vol2 √n_e + … [rpm^-1/2]."
    )
    c_vol3: float = Field(
        MODEL_DEFAULTS["c_vol3"],
        gt=0,
        description="Constant term of the volumetric efficiency η_vol [-] (W&E (14)).",
    )
    eta_cmax: float = Field(
        MODEL_DEFAULTS["eta_cmax"], gt=0, le=1, description="Peak compressor efficiency [-]."
    )
    eta_tmmax: float = Field(
        MODEL_DEFAULTS["eta_tmmax"],
        gt=0,
        le=1,
        description="Peak turbine-mechanical efficiency [-].",
    )
    A_egrmax: float = Field(
        MODEL_DEFAULTS["A_egrmax"], gt=0, description="Largest EGR valve flow area [m²]."
    )
    A_vgtmax: float = Field(
        MODEL_DEFAULTS["A_vgtmax"], gt=0, description="Largest VGT flow area [m²]."
    )
    J_t: float = Field(MODEL_DEFAULTS["J_t"], gt=0, description="Turbocharger inertia [kg m²].")

    def vector(self) -> np.ndarray:
        """The kernel parameter vector (order ``PARAM_NAMES``) of this model."""
        values = MODEL_DEFAULTS | {name: float(getattr(self, name)) for name in TUNABLE}
        return np.array([values[n] for n in kernels.airpath_plant.PARAM_NAMES], dtype=np.float64)

    def a1(self) -> float:
        """LPV (5) ``a1 = R_a T_im / V_im`` [J/(kg m³)]."""
        return MODEL_DEFAULTS["R_a"] * MODEL_DEFAULTS["T_im"] / self.V_im

    def a2(self, t_em_k: float) -> float:
        """LPV (5) ``a2 = R_e T_em / V_em`` at the exhaust temperature ``t_em_k`` [K]."""
        return MODEL_DEFAULTS["R_e"] * t_em_k / self.V_em


def model_rho(
    columns: tuple[np.ndarray, ...],
    time_s: np.ndarray,
    model: AirpathModelConfig,
    *,
    n_iter: int = 12,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ρ of LPV (3) from measured ``columns = (p_im Pa, p_em Pa, ω_t rad/s, ũ_egr %, ũ_vgt %,
    u_δ mg/cycle, n_e rpm)`` with ``model``; returns ``(rho (n, 5), rho1_compressor (n,),
    t_em (n,) K)``.

    ``ρ2…ρ5`` and ``T_em`` (the Seiliger fixed point, ``n_iter`` iterations) are LPV (3) as
    printed; ``ρ1 = (ρ3 p_im − ρ2 p_em + ṗ_im/a1)/ω_t`` is the intake-manifold balance with the
    backward-difference ``ṗ_im`` (:mod:`estimation.observers.lpv`), ``rho1_compressor`` the
    compressor-map value of LPV (3).
    """
    cols = [np.ascontiguousarray(c, dtype=np.float64) for c in columns]
    n = cols[0].size
    if len(cols) != 7 or any(c.shape != (n,) for c in cols):
        raise ShapeError(f"model_rho needs 7 columns of length {n}")
    t = np.asarray(time_s, dtype=np.float64)
    if t.shape != (n,) or (n > 1 and np.any(np.diff(t) <= 0)):
        raise ShapeError(f"time_s must be strictly increasing with {n} samples, got {t.shape}")
    if n < 2:
        raise ConfigError("ρ from measurements needs at least two samples")
    if n_iter < 1:
        raise ConfigError(f"n_iter must be at least 1, got {n_iter}")
    rho = np.empty((n, 5))
    t_em = np.empty(n)
    w_egr = np.empty(n)
    kernels.airpath_plant.airpath_rho_kernel(*cols, int(n_iter), model.vector(), rho, t_em, w_egr)
    rho1_compressor = rho[:, 0].copy()
    p_im, p_em, omega = cols[0], cols[1], cols[2]
    dp_dt = np.empty(n)
    dp_dt[1:] = np.diff(p_im) / np.diff(t)
    dp_dt[0] = dp_dt[1]
    rho[:, 0] = (rho[:, 2] * p_im - rho[:, 1] * p_em + dp_dt / model.a1()) / omega
    return rho, rho1_compressor, t_em
