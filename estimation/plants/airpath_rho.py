"""The air path in the LPV form of the LPV paper: ρ from measurements and ``ẋ = A(ρ)x + E``.

:func:`rho_from_measurements` evaluates the scheduling vector ρ of LPV (3) (with ``T_em`` and
``W_egr``) from measured signals through the plant's own sub-models
(:mod:`estimation.kernels.airpath_plant`); ``ρ1`` from the intake-manifold balance
(:func:`manifold_rho1`) or, literally, from the compressor map. :func:`lpv_rhs` is the
right-hand side of LPV (4)–(5). Units of ρ: :data:`estimation.plants.airpath.UNITS`.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from estimation.errors import ConfigError, ShapeError
from estimation.kernels import airpath_plant as apk
from estimation.plants.airpath_params import AirpathParams

__all__ = ["lpv_rhs", "manifold_rho1", "rho_from_measurements"]


def lpv_rhs(
    x: np.ndarray,
    rho: np.ndarray,
    w_f_kg_s: np.ndarray,
    p_t_eta_m_w: np.ndarray,
    *,
    a1: float,
    a2: float | np.ndarray,
    J_t: float,
) -> np.ndarray:
    """``ẋ = A(ρ) x + E`` of LPV (4)–(5) for rows ``x = (p_im, p_em, ω_t)``.

    ``A(ρ) = [[−a1ρ3, a1ρ2, a1ρ1], [a2ρ3, −a2(ρ2+ρ4), 0], [0, 0, −ρ5]]``,
    ``E = (0, a2 W_f, P_t η_m / (J_t ω_t))``. Shapes ``(n, 3)``, ``(n, 5)``, ``(n,)``.
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    rho = np.atleast_2d(np.asarray(rho, dtype=np.float64))
    p_im, p_em, w = x[:, 0], x[:, 1], x[:, 2]
    r1, r2, r3, r4, r5 = rho.T
    a2 = np.asarray(a2, dtype=np.float64)
    return np.column_stack(
        [
            a1 * (-r3 * p_im + r2 * p_em + r1 * w),
            a2 * (r3 * p_im - (r2 + r4) * p_em + w_f_kg_s),
            -r5 * w + np.asarray(p_t_eta_m_w) / (J_t * w),
        ]
    )


def rho_from_measurements(
    p_im_pa: np.ndarray,
    p_em_pa: np.ndarray,
    omega_t_rad_s: np.ndarray,
    u_egr_pos_pct: np.ndarray,
    u_vgt_pos_pct: np.ndarray,
    fuel_mg_per_cycle: np.ndarray,
    speed_rpm: np.ndarray,
    *,
    time_s: np.ndarray | None = None,
    rho1_model: Literal["manifold", "compressor"] = "manifold",
    params: AirpathParams | None = None,
    n_iter: int = 12,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ρ of LPV (3), ``T_em`` [K] and ``W_egr`` [kg/s] from measured signals.

    Evaluates the plant's own sub-models (so ρ is what an observer with a perfect model
    would compute); the exhaust temperature comes from the Seiliger model's fixed point
    (``n_iter`` iterations). ``ρ2 … ρ5`` are LPV (3) as printed. Returns
    ``(rho (n, 5) in the units of UNITS, t_em (n,), w_egr (n,))``.

    ``ρ1 = W_c/ω_t`` [kg/rad] has two evaluations that agree on the true trajectory:

    - ``"compressor"`` — LPV (3) literally, ``ρ1 = p_amb π R_c³ Φ_c(p_im, ω_t)/(R_a T_amb)``.
      It is ill-conditioned in the measured pressure: at low turbo speed the whole speed
      line spans about 1 kPa of boost (``Ψ_c ∝ (Π_c^(1−1/γa) − 1)/ω_t²``), and below ambient
      the inlet restriction passes ~0.05–0.1 kg/s per kPa, so ``|∂W_c/∂p_im|`` reaches
      ~1e−4 kg/(s Pa). On the WHTC (``maf-whtc``), 1 kPa of white pressure noise makes
      ``ρ1`` exactly 0 in 3 % of the samples and biases ``ρ1 ω_t`` by +3.9 g/s on average,
      five times the MAF error the observer is to find (0.8 g/s); at 0.32 kPa the bias is
      still +0.75 g/s.
    - ``"manifold"`` (default) — the intake-manifold mass balance, LPV (1) first row solved
      for ``W_c``: ``ρ1 = (ρ3 p_im − ρ2 p_em + ṗ_im/a1)/ω_t``, i.e. ``(W_ei − W_egr +
      ṗ_im/a1)/ω_t``, with ``a1 = R_a T_im/V_im`` (LPV (5)) and ``ṗ_im`` the backward
      difference of the measured ``p_im`` over ``time_s`` (causal, and the derivative the
      observer's implicit-Euler step holds over each sample; the first sample takes the
      first difference). The engine-side sub-models are well conditioned (``W_ei ∝ p_im``;
      the EGR valve's ``Ψ_egr`` has a bounded slope) and the differenced noise telescopes
      under the observer's averaging, so noise enters ``ρ1`` nearly unbiased: −0.05 g/s at
      1 kPa, +0.001 g/s at 0.32 kPa on the WHTC. Its per-sample scatter (1.8 g/s RMS at
      1 kPa, mostly the EGR flow near ``Π_egr ≈ 1``) is what the observer has to average.

    ``time_s`` (n,) [s], strictly increasing, is required for ``"manifold"``.
    """
    prm = (params or AirpathParams.scaled()).to_vector()
    cols = [
        np.ascontiguousarray(a, dtype=np.float64)
        for a in (
            p_im_pa,
            p_em_pa,
            omega_t_rad_s,
            u_egr_pos_pct,
            u_vgt_pos_pct,
            fuel_mg_per_cycle,
            speed_rpm,
        )
    ]
    n = cols[0].size
    if any(c.shape != (n,) for c in cols):
        raise ShapeError(f"all inputs must be 1-D of length {n}, got {[c.shape for c in cols]}")
    if rho1_model not in ("manifold", "compressor"):
        raise ConfigError(f"rho1_model must be 'manifold' or 'compressor', got {rho1_model!r}")
    rho = np.empty((n, 5))
    t_em = np.empty(n)
    w_egr = np.empty(n)
    if rho1_model == "manifold" and time_s is None:
        raise ConfigError("time_s is needed for the manifold ρ1 (or pass rho1_model='compressor')")
    if n_iter < 1:
        raise ConfigError(f"n_iter must be at least 1, got {n_iter}")
    apk.airpath_rho_kernel(*cols, int(n_iter), prm, rho, t_em, w_egr)
    if rho1_model == "manifold":
        a1 = prm[apk.R_A] * prm[apk.T_IM] / prm[apk.V_IM]
        rho[:, 0] = manifold_rho1(rho, cols[0], cols[1], cols[2], time_s, a1)
    return rho, t_em, w_egr


def manifold_rho1(
    rho: np.ndarray,
    p_im: np.ndarray,
    p_em: np.ndarray,
    omega_t: np.ndarray,
    time_s: np.ndarray | Any,
    a1: float,
) -> np.ndarray:
    """``ρ1 = (ρ3 p_im − ρ2 p_em + ṗ_im/a1)/ω_t`` with the backward-difference ``ṗ_im``
    (see :func:`rho_from_measurements`)."""
    n = p_im.size
    t = np.asarray(time_s, dtype=np.float64)
    if t.shape != (n,) or (n > 1 and np.any(np.diff(t) <= 0)):
        raise ShapeError(f"time_s must be strictly increasing with {n} samples, got {t.shape}")
    dp_dt = np.zeros(n)
    if n > 1:
        dp_dt[1:] = np.diff(p_im) / np.diff(t)
        dp_dt[0] = dp_dt[1]
    return (rho[:, 2] * p_im - rho[:, 1] * p_em + dp_dt / a1) / omega_t
