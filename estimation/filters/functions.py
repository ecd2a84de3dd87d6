"""Pure run functions of the five map-updating filters (procedure form).

``<kind>_run(state, idx, w, y, accept, settings) → (state', ŷ, status)`` advances a copy of
``state`` over a chunk of samples in one compiled kernel call and never mutates its input.
``idx, w`` are the sparse regressor rows (:meth:`estimation.table.Grid.regressor`) already
aligned with ``y`` (a sensor delay is applied by the caller); ``status`` is 0 for an accepted
sample, 1 for one rejected by the ``accept`` mask, 2 for one rejected by the innovation gate.
Given ``s_out`` (length of the chunk), a run function also writes each sample's innovation
variance there, in the output's unit squared (docs/tuning.md): ``hᵀPh + σv²`` for KF and
SKF, ``σv²·(hᵀPh + 1)`` for RLS, ``σv²`` for SSKF and NLMS (what their gates test against).

Tables of 1, 2 and 3 dimensions (2, 4, 8 corners) run kernels compiled for that corner count
(:mod:`estimation.kernels.specialise`); other dimensions, or ``specialised=False``, run the
generic kernels. Both give bit-identical results.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from estimation import kernels
from estimation.errors import ShapeError, StateError
from estimation.filters.settings import FilterSettings
from estimation.filters.state import FilterState, KfState, LocalState, ThetaState

RunResult = tuple[FilterState, np.ndarray, np.ndarray]


def initial_state(
    kind: str, theta0: np.ndarray, settings: FilterSettings, *, y_m0: float | None = None
) -> FilterState:
    """The state before the first sample: ``θ = θ0``, ``P = diag(P0)``.

    With sensor dynamics the sensor state starts at ``y_m0`` (callers pass the first usable
    measurement) with variance ``σv²``.
    """
    theta = np.array(theta0, dtype=np.float64).ravel()
    p = theta.size
    if settings.p0.size != p:
        raise ShapeError(f"p0 has {settings.p0.size} cells, the table {p}")
    common = {"kind": kind, "step": 0, "rejected_mask": 0, "rejected_gate": 0, "theta": theta}
    sensor = settings.has_sensor
    if sensor and kind not in ("kf", "skf"):
        raise StateError(f"{kind!r} does not model sensor dynamics")
    ym = float(y_m0 if y_m0 is not None else 0.0) if sensor else None
    if kind == "kf":
        P = np.diag(np.append(settings.p0, settings.sigma_v2) if sensor else settings.p0)
        return KfState(**common, P=P, y_m=ym)
    if kind in ("skf", "rls"):
        n_corners = settings.n_corners
        na = n_corners + 1 if sensor else n_corners
        P_active = np.zeros((na, na))
        if sensor:
            P_active[-1, -1] = settings.sigma_v2
        return LocalState(
            **common,
            var=settings.p0.copy(),
            last=np.full(p, -1, dtype=np.int64),
            active=np.full(n_corners, -1, dtype=np.int64),
            P_active=P_active,
            y_m=ym,
        )
    if kind in ("sskf", "nlms"):
        return ThetaState(**common)
    raise StateError(f"unknown filter kind {kind!r}; expected one of {FILTER_KINDS}")


def kf_run(
    state: KfState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    settings: FilterSettings,
    s_out: np.ndarray | None = None,
    *,
    specialised: bool = True,
) -> RunResult:
    """Full KF over a chunk (SKF §4.4, docs/algorithms.md §2.1; kernel :func:`kf_kernel`)."""
    x = np.append(state.theta, state.y_m) if state.y_m is not None else state.theta.copy()
    P = state.P.copy()
    yhat, status = _outputs(y)
    kernels.kalman.kf_kernel(
        x,
        P,
        idx,
        w,
        y,
        accept,
        settings.sigma_w2,
        settings.sigma_v2,
        settings.p0,
        settings.limit,
        settings.locked,
        settings.gate2,
        settings.has_sensor,
        settings.lag,
        settings.sigma_f2,
        yhat,
        status,
        _variances(y, s_out),
        kernels.specialise.corner_token(idx.shape[1], specialised=specialised),
    )
    p = state.theta.size
    y_m = float(x[p]) if state.y_m is not None else None
    return _advance(state, status, theta=x[:p].copy(), P=P, y_m=y_m), yhat, status


def _local_run(
    state: LocalState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    settings: FilterSettings,
    s_out: np.ndarray | None = None,
    *,
    rls: bool,
    specialised: bool = True,
) -> RunResult:
    theta, var, last = state.theta.copy(), state.var.copy(), state.last.copy()
    active, Pa = state.active.copy(), state.P_active.copy()
    ym = np.array([state.y_m if state.y_m is not None else 0.0])
    yhat, status = _outputs(y)
    kernels.local.local_kernel(
        theta,
        var,
        last,
        active,
        Pa,
        ym,
        state.step,
        idx,
        w,
        y,
        accept,
        np.zeros_like(settings.sigma_w2) if rls else settings.sigma_w2,
        1.0 if rls else settings.sigma_v2,
        settings.forgetting if rls else 1.0,
        settings.sigma_v2 if rls else 1.0,
        settings.p0,
        settings.limit,
        settings.locked,
        settings.gate2,
        settings.lag,
        settings.sigma_f2,
        yhat,
        status,
        _variances(y, s_out),
        kernels.specialise.corner_token(idx.shape[1], specialised=specialised),
        kernels.specialise.sensor_token(settings.has_sensor and not rls),
    )
    y_m = float(ym[0]) if state.y_m is not None else None
    new = _advance(
        state, status, theta=theta, var=var, last=last, active=active, P_active=Pa, y_m=y_m
    )
    return new, yhat, status


def skf_run(
    state: LocalState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    settings: FilterSettings,
    s_out: np.ndarray | None = None,
    *,
    specialised: bool = True,
) -> RunResult:
    """Simplified KF over a chunk (SKF §4.7 Algorithm 1, docs/algorithms.md §2.2)."""
    return _local_run(state, idx, w, y, accept, settings, s_out, rls=False, specialised=specialised)


def rls_run(
    state: LocalState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    settings: FilterSettings,
    s_out: np.ndarray | None = None,
    *,
    specialised: bool = True,
) -> RunResult:
    """Local RLS with forgetting λ on the active cells over a chunk (docs/algorithms.md §2.4)."""
    return _local_run(state, idx, w, y, accept, settings, s_out, rls=True, specialised=specialised)


def sskf_run(
    state: ThetaState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    settings: FilterSettings,
    s_out: np.ndarray | None = None,
    *,
    specialised: bool = True,
) -> RunResult:
    """Steady-state KF over a chunk (SKF §4.5 (15)–(16), docs/algorithms.md §2.3)."""
    theta = state.theta.copy()
    yhat, status = _outputs(y)
    kernels.gain_only.sskf_kernel(
        theta,
        idx,
        w,
        y,
        accept,
        settings.sigma_w2,
        settings.sigma_v2,
        settings.locked,
        settings.gate2,
        yhat,
        status,
        kernels.specialise.corner_token(idx.shape[1], specialised=specialised),
    )
    if s_out is not None:
        s_out[:] = settings.sigma_v2
    return _advance(state, status, theta=theta), yhat, status


def nlms_run(
    state: ThetaState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    settings: FilterSettings,
    s_out: np.ndarray | None = None,
    *,
    specialised: bool = True,
) -> RunResult:
    """Normalised LMS over a chunk (docs/algorithms.md §2.4)."""
    theta = state.theta.copy()
    yhat, status = _outputs(y)
    kernels.gain_only.nlms_kernel(
        theta,
        idx,
        w,
        y,
        accept,
        settings.mu,
        settings.eps,
        settings.sigma_v2,
        settings.locked,
        settings.gate2,
        yhat,
        status,
        kernels.specialise.corner_token(idx.shape[1], specialised=specialised),
    )
    if s_out is not None:
        s_out[:] = settings.sigma_v2
    return _advance(state, status, theta=theta), yhat, status


RUN_FUNCTIONS: dict[str, Callable[..., RunResult]] = {
    "kf": kf_run,
    "skf": skf_run,
    "sskf": sskf_run,
    "rls": rls_run,
    "nlms": nlms_run,
}
FILTER_KINDS = tuple(RUN_FUNCTIONS)  # the registry's map filters (checked by the tests)


def run_chunk(
    state: FilterState,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray | None,
    settings: FilterSettings,
    *,
    s_out: np.ndarray | None = None,
    specialised: bool = True,
) -> RunResult:
    """Dispatch to the run function of ``state.kind`` after checking the chunk's arrays
    (``s_out``: where to write the innovation variances; ``specialised=False``: the generic
    kernels whatever the dimension, for comparisons; module docstring)."""
    n = y.shape[0]
    if idx.shape != w.shape or idx.shape[0] != n:
        raise ShapeError(f"regressor shapes {idx.shape}, {w.shape} do not fit {n} samples")
    if state.theta.size != settings.p0.size:
        raise StateError(f"state has {state.theta.size} cells, the table {settings.p0.size}")
    if accept is None:
        accept = np.ones(n, dtype=np.bool_)
    elif accept.shape != (n,):
        raise ShapeError(f"accept mask has shape {accept.shape}, expected ({n},)")
    if s_out is not None and (s_out.shape != (n,) or s_out.dtype != np.float64):
        raise ShapeError(f"s_out must be float64 of shape ({n},), got {s_out.shape}")
    return RUN_FUNCTIONS[state.kind](
        state,
        np.ascontiguousarray(idx, dtype=np.int64),
        np.ascontiguousarray(w, dtype=np.float64),
        np.ascontiguousarray(y, dtype=np.float64),
        np.ascontiguousarray(accept, dtype=np.bool_),
        settings,
        s_out,
        specialised=specialised,
    )


def variance(state: FilterState, settings: FilterSettings) -> np.ndarray | None:
    """Current variance of every cell (diag P), or ``None`` for covariance-free filters.

    For the local filters the lazily aged variances are brought up to date here (capped at
    P0 with limiting); the state is not modified.
    """
    if isinstance(state, KfState):
        return np.diag(state.P)[: state.theta.size].copy()
    if isinstance(state, LocalState):
        aging = np.zeros_like(settings.sigma_w2) if state.kind == "rls" else settings.sigma_w2
        var = state.var + aging * (state.step - 1 - state.last)
        if settings.limit:
            var = np.minimum(var, settings.p0)
        for c, j in enumerate(state.active):
            if j >= 0:
                var[j] = state.P_active[c, c]
        return var
    return None


def _variances(y: np.ndarray, s_out: np.ndarray | None) -> np.ndarray:
    """Where a kernel writes its innovation variances: ``s_out``, or scratch if not wanted."""
    return np.empty(y.shape[0]) if s_out is None else s_out


def _outputs(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.empty(y.shape[0]), np.empty(y.shape[0], dtype=np.int8)


def _advance(state: FilterState, status: np.ndarray, **arrays: object) -> FilterState:
    return dataclasses.replace(
        state,
        step=state.step + int(status.size),
        rejected_mask=state.rejected_mask
        + int(np.count_nonzero(status == kernels.kalman.REJECTED_MASK)),
        rejected_gate=state.rejected_gate
        + int(np.count_nonzero(status == kernels.kalman.REJECTED_GATE)),
        **arrays,
    )
