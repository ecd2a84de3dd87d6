"""Identify an observer's flow model on a separate segment with a reference air flow.

An observer that estimates the MAF sensor's error measures it against its own model's flow:
with the intake-manifold balance (LPV (1), first row) the model flow is
``W_c = W_ei − W_egr + ṗ_im/a1``. A 5 % error in the volumetric efficiency is a 5 % error in
``W_ei``, several g/s on a 2 L engine, where the MAF error map is about 1 g/s
(docs/fidelity.md). Before the observer runs, the two terms are therefore calibrated on an
identification segment — another drive of the same engine on which a reference flow
``W_c,ref`` (a test-bench meter, not the MAF under test) was logged — by linear least squares:

``W_c,ref − ṗ_im/a1 = g·(c_vol1 √p_im + c_vol2 √n_e + c_vol3) − A_egrmax·h``

where ``g = W_ei/η_vol`` and ``h = W_egr/A_egrmax`` are evaluated with the current model
(:func:`estimation.observers.airpath_model.model_rho`; ``W_ei = ρ3 p_im``, ``W_egr =
ρ2 p_em``, W&E (14), (21)); ``h`` depends on the exhaust temperature and hence on ``η_vol``,
so the fit is repeated ``n_iter`` times. By default only the offset ``c_vol3`` of the
volumetric efficiency and the EGR flow area are fitted (:data:`DEFAULT_FIT`); every other
constant of the model stays as configured.

The regressors are nonlinear in the measured pressures (the EGR valve's ``Ψ_egr`` is steep
near ``Π_egr ≈ 1``), so white pressure noise biases the fit (errors in variables): with the
logged σ of 0.32 kPa the EGR area came out 3 % low on an FTP-75 segment. Every signal is
therefore first smoothed by a centred moving mean of ``smooth_samples`` (default 11, 1.1 s at
10 Hz; the segment is offline, so a non-causal filter is allowed), which brings it within
0.6 % (and within 3 % from single 1 kPa readings).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimation.errors import ConfigError, ShapeError
from estimation.observers.airpath_model import AirpathModelConfig, model_rho
from estimation.signals import Signals

__all__ = ["DEFAULT_FIT", "IDENTIFIED", "identify_flow_model"]

IDENTIFIED = ("c_vol1", "c_vol2", "c_vol3", "A_egrmax")
"""The constants :func:`identify_flow_model` can fit."""

DEFAULT_FIT = ("c_vol3", "A_egrmax")
"""What it fits by default: the offset of ``η_vol`` and the EGR area. With all four, ``c_vol1``
and ``c_vol3`` trade off (``√p_im`` spans only 1.7:1) and the noise moves them far apart."""

_COLUMNS = (
    "p_im_pa",
    "p_em_pa",
    "omega_t_rad_s",
    "u_egr_pos_pct",
    "u_vgt_pos_pct",
    "fuel_mg_per_cycle",
    "speed_rpm",
)


def identify_flow_model(
    signals: Signals,
    w_c_ref_kg_s: np.ndarray,
    model: AirpathModelConfig,
    *,
    fit: tuple[str, ...] = DEFAULT_FIT,
    smooth_samples: int = 11,
    n_iter: int = 3,
) -> tuple[AirpathModelConfig, dict[str, Any]]:
    """``model`` with :data:`IDENTIFIED` fitted on ``signals`` (channels of
    :mod:`estimation.plants.airpath`) against the reference flow ``w_c_ref_kg_s`` (n,) [kg/s].

    ``fit``: a subset of :data:`IDENTIFIED`. Returns the identified model and a report:
    ``rms_residual_kg_s`` of the fit, ``samples`` used (those with the engine fuelled) and
    the fitted values.
    """
    if not fit or any(name not in IDENTIFIED for name in fit):
        raise ConfigError(f"fit must name some of {', '.join(IDENTIFIED)}; got {list(fit)}")
    signals.require(list(_COLUMNS))
    ref = np.asarray(w_c_ref_kg_s, dtype=np.float64)
    n = len(signals)
    if ref.shape != (n,):
        raise ShapeError(f"reference flow has shape {ref.shape}, the segment has {n} samples")
    cols = tuple(_centred_mean(signals[c], smooth_samples) for c in _COLUMNS)
    ref = _centred_mean(ref, smooth_samples)
    p_im, p_em, speed = cols[0], cols[1], cols[6]
    t = signals.time
    dp_dt = np.empty(n)
    dp_dt[1:] = np.diff(p_im) / np.diff(t)
    dp_dt[0] = dp_dt[1]
    use = np.isfinite(ref) & (cols[5] > 0.0)
    if np.count_nonzero(use) < 10 * len(IDENTIFIED):
        raise ConfigError(f"identification needs ≥ {10 * len(IDENTIFIED)} fuelled samples")
    fitted = model
    residual = np.full(n, np.nan)
    for _ in range(n_iter):
        rho, _, _ = model_rho(cols, t, fitted)
        eta_vol = fitted.c_vol1 * np.sqrt(p_im) + fitted.c_vol2 * np.sqrt(speed) + fitted.c_vol3
        g = rho[:, 2] * p_im / eta_vol
        h = rho[:, 1] * p_em / fitted.A_egrmax
        features = {
            "c_vol1": g * np.sqrt(p_im),
            "c_vol2": g * np.sqrt(speed),
            "c_vol3": g,
            "A_egrmax": -h,
        }
        y = ref - dp_dt / fitted.a1()
        for name in IDENTIFIED:
            if name not in fit:
                y = y - features[name] * getattr(fitted, name)
        X = np.column_stack([features[name] for name in fit])
        coef, *_ = np.linalg.lstsq(X[use], y[use], rcond=None)
        if not np.all(np.isfinite(coef)):
            raise ConfigError(f"identification failed: coefficients {coef.tolist()}")
        fitted = fitted.model_copy(update=dict(zip(fit, map(float, coef), strict=True)))
        residual = y - X @ coef
    report = {
        "rms_residual_kg_s": float(np.sqrt(np.mean(residual[use] ** 2))),
        "samples": int(np.count_nonzero(use)),
        "values": {name: float(getattr(fitted, name)) for name in fit},
    }
    return fitted, report


def _centred_mean(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving mean over ``width`` samples (odd; shrinking at the ends)."""
    x = np.asarray(x, dtype=np.float64)
    if width <= 1:
        return x
    half = width // 2
    c = np.concatenate([[0.0], np.cumsum(x)])
    k = np.arange(x.size)
    lo = np.maximum(k - half, 0)
    hi = np.minimum(k + half + 1, x.size)
    return (c[hi] - c[lo]) / (hi - lo)
