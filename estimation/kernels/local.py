"""Local (active-cell) covariance filters: the simplified Kalman filter and local RLS.

SKF (docs/algorithms.md §2.2, SKF §4.7 Algorithm 1): a variance per cell ``var`` (length p) plus a
dense covariance ``Pa`` of the active elements (``2^d``, plus ``y_M`` with sensor dynamics).
Inactive cells age lazily: ``last[j]`` is the step through which ``var[j]`` has been aged, and
``σw²_j·(steps missed)`` is added when ``j`` becomes active again, so a step costs O(4^d),
independent of the table size ``p``.

A step's rank-1 covariance update is applied at the start of the next step, not at the end
of its own: when the next step keeps none of the active elements (a new cell on nearly every
sample of a log that jumps about, the SKF paper's simulation 1), only the diagonal of the
update is needed, for the variances written back, and the new local system starts diagonal.
The arithmetic of every element that is kept is the same, in the same order, so the results
are bit-identical to updating at once.

Local RLS (docs/algorithms.md §2.4) is the same bookkeeping with no process noise, unit
measurement variance and exponential forgetting ``Pa ← Pa/λ`` on the active block only, so
cells that are not excited do not wind up.
"""

import numba as nb
import numpy as np

from estimation.kernels.kalman import ACCEPTED, REJECTED_GATE, REJECTED_MASK, _cap_row_col
from estimation.kernels.specialise import fixed_or


@nb.njit(cache=True, inline="always")
def _switch_active(
    k_step: int,
    idx: np.ndarray,
    k: int,
    active: np.ndarray,
    var: np.ndarray,
    last: np.ndarray,
    Pa: np.ndarray,
    sigma_w2: np.ndarray,
    p0: np.ndarray,
    limit: bool,
    has_sensor: bool,
    pos_old: np.ndarray,
    scratch: np.ndarray,
    nc: int,
    na: int,
) -> None:
    """Move the local system from the elements ``active`` to ``idx[k]`` at step ``k_step``.

    Leaving elements write their variance back to ``var`` (aged through ``k_step − 1``);
    entering ones are aged lazily for the steps they missed (capped at ``P0`` with ``limit``;
    capping each step and capping once give the same value because aging is monotone);
    the covariance of a pair is kept only if both elements are in the old and the new set
    (SKF §5.2). ``y_M`` (last row/column) is always active.
    """
    for c in range(nc):
        pos_old[c] = -1
    for c2 in range(nc):
        j = active[c2]
        if j < 0:
            continue
        leaving = True
        for c in range(nc):
            if idx[k, c] == j:
                pos_old[c] = c2
                leaving = False
                break
        if leaving:
            var[j] = Pa[c2, c2]
            last[j] = k_step - 1
    for c in range(nc):
        oc = pos_old[c]
        if oc >= 0:
            for c2 in range(nc):
                oc2 = pos_old[c2]
                scratch[c, c2] = Pa[oc, oc2] if oc2 >= 0 else 0.0
            if has_sensor:
                scratch[c, na - 1] = Pa[oc, na - 1]
        else:
            for c2 in range(na):
                scratch[c, c2] = 0.0
            j = idx[k, c]
            aged = var[j] + sigma_w2[j] * (k_step - 1 - last[j])
            if limit and aged > p0[j]:
                aged = p0[j]
            scratch[c, c] = aged
    if has_sensor:
        for c in range(nc):
            scratch[na - 1, c] = scratch[c, na - 1]
        scratch[na - 1, na - 1] = Pa[na - 1, na - 1]
    for c in range(na):
        for c2 in range(na):
            Pa[c, c2] = scratch[c, c2]
    for c in range(nc):
        active[c] = idx[k, c]


@nb.njit(cache=True, inline="always")
def _overlaps(idx: np.ndarray, k: int, active: np.ndarray, nc: int) -> bool:
    """Whether sample ``k`` keeps any of the ``active`` elements."""
    kept = False
    for c in range(nc):
        for c2 in range(nc):
            kept |= idx[k, c] == active[c2]
    return kept


@nb.njit(cache=True, inline="always")
def _rank_one_update(Pa: np.ndarray, v: np.ndarray, inv_s: float, na: int) -> None:
    """``Pa ← Pa − v vᵀ / s``."""
    for c in range(na):
        for c2 in range(na):
            Pa[c, c2] -= (v[c] * v[c2]) * inv_s


@nb.njit(cache=True)
def local_kernel(
    theta: np.ndarray,
    var: np.ndarray,
    last: np.ndarray,
    active: np.ndarray,
    Pa: np.ndarray,
    ym: np.ndarray,
    step0: int,
    idx: np.ndarray,
    w: np.ndarray,
    y: np.ndarray,
    accept: np.ndarray,
    sigma_w2: np.ndarray,
    r_update: float,
    forget: float,
    gate_scale: float,
    p0: np.ndarray,
    limit: bool,
    locked: np.ndarray,
    gate2: float,
    lag: float,
    sigma_f2: float,
    yhat_out: np.ndarray,
    status_out: np.ndarray,
    s_out: np.ndarray,
    corners: tuple,
    sensor: tuple,
) -> None:
    """Run the local filter over ``n`` samples, updating the state arrays in place.

    Per sample ``k`` (global step ``step0 + k``), with ``q`` the active weights and ``q_u``
    the same with locked cells zeroed:

    * switch the local system if the active elements changed (:func:`_switch_active`);
    * sensor dynamics (SKF (29)–(33)): ``y_M ← a y_M + (1−a) qᵀθ_A``, ``Pa ← F Pa Fᵀ``,
      ``Pa_yy += σf²``;
    * predict: ``Pa_AA ← Pa_AA / λ`` (RLS forgetting; λ = 1 for SKF) and
      ``Pa_cc += σw²`` for the active cells (SKF); cap at ``P0`` with ``limit`` (PSD form);
    * innovation ``e = y − ŷ``, ``s = hᵀ Pa h + r`` (r = σv² for SKF, 1 for RLS);
      reject if masked or ``e² > gate2 · gate_scale · s``;
    * update ``g = Pa h / s``, ``θ_A += g e``, ``Pa ← Pa − (Pa h)(Pa h)ᵀ / s`` (applied at
      the start of the next sample or at the end of the call, module docstring).

    ``s_out[k]`` is the innovation variance in the output's unit squared, ``gate_scale · s``
    (SKF: ``s``; RLS: ``σv² s``), for the innovation statistics of docs/tuning.md.

    ``corners`` and ``sensor`` are size tokens (:mod:`estimation.kernels.specialise`): the
    corner count ``2^d`` (or generic) and one element for ``y_M`` if the sensor is modelled.
    """
    n = y.shape[0]
    nc = fixed_or(corners, idx.shape[1])
    has_sensor = len(sensor) > 0
    na = nc + len(sensor)
    s_ = na - 1
    b = 1.0 - lag
    inv_forget = 1.0 / forget
    pos_old = np.empty(nc, dtype=np.int64)
    scratch = np.empty((na, na))
    q = np.empty(nc)
    v = np.empty(na)
    pending = False  # the last accepted sample's rank-1 update, Pa -= v vᵀ · inv_pending
    inv_pending = 0.0
    for k in range(n):
        changed = False
        for c in range(nc):
            if idx[k, c] != active[c]:
                changed = True
                break
        diagonal = False  # Pa's corner block is diagonal: Pa q skips the zero products
        if pending and changed and not _overlaps(idx, k, active, nc):
            # _switch_active to a set sharing no element, with the pending update applied to
            # the leaving variances alone; Pa restarts as the entering ones' diagonal, aged
            # (written out here: as an inlined function it cost 2 ns a sample more)
            for c2 in range(nc):
                j = active[c2]
                if j >= 0:
                    var[j] = Pa[c2, c2] - (v[c2] * v[c2]) * inv_pending
                    last[j] = step0 + k - 1
            p_yy = Pa[s_, s_] - (v[s_] * v[s_]) * inv_pending if has_sensor else 0.0
            for c in range(na):
                for c2 in range(na):
                    Pa[c, c2] = 0.0
            for c in range(nc):
                j = idx[k, c]
                aged = var[j] + sigma_w2[j] * (step0 + k - 1 - last[j])
                if limit and aged > p0[j]:
                    aged = p0[j]
                Pa[c, c] = aged
                active[c] = j
            if has_sensor:
                Pa[s_, s_] = p_yy
            changed = False
            diagonal = True
        elif pending:
            _rank_one_update(Pa, v, inv_pending, na)
        pending = False
        if changed:
            _switch_active(
                step0 + k,
                idx,
                k,
                active,
                var,
                last,
                Pa,
                sigma_w2,
                p0,
                limit,
                has_sensor,
                pos_old,
                scratch,
                nc,
                na,
            )
        for c in range(nc):
            q[c] = 0.0 if locked[active[c]] else w[k, c]
        if has_sensor:
            pred = 0.0
            for c in range(nc):
                pred += w[k, c] * theta[active[c]]
            hPh = 0.0
            hc = 0.0
            for c in range(nc):
                if diagonal:
                    acc = Pa[c, c] * q[c]
                else:
                    acc = 0.0
                    for c2 in range(nc):
                        acc += Pa[c, c2] * q[c2]
                v[c] = acc
                hPh += q[c] * acc
                hc += q[c] * Pa[c, s_]
            pyy = b * b * hPh + 2.0 * lag * b * hc + lag * lag * Pa[s_, s_]
            for c in range(nc):
                cross = b * v[c] + lag * Pa[c, s_]
                Pa[c, s_] = cross
                Pa[s_, c] = cross
            Pa[s_, s_] = pyy + sigma_f2
            ym[0] = lag * ym[0] + b * pred
        if forget != 1.0:
            for c in range(nc):
                if not locked[active[c]]:
                    for c2 in range(nc):
                        if not locked[active[c2]]:
                            Pa[c, c2] *= inv_forget
        for c in range(nc):
            Pa[c, c] += sigma_w2[active[c]]
        if limit:
            for c in range(nc):
                j = active[c]
                if Pa[c, c] > p0[j]:
                    _cap_row_col(Pa, c, p0[j])
        if has_sensor:
            yhat = ym[0]
            for c in range(na):
                v[c] = Pa[c, s_]
            s = Pa[s_, s_] + r_update
        else:
            yhat = 0.0
            s = r_update
            for c in range(nc):
                yhat += w[k, c] * theta[active[c]]
                if diagonal:
                    v[c] = Pa[c, c] * q[c]
                else:
                    acc = 0.0
                    for c2 in range(nc):
                        acc += Pa[c, c2] * q[c2]
                    v[c] = acc
            for c in range(nc):
                s += q[c] * v[c]
        yhat_out[k] = yhat
        s_out[k] = gate_scale * s
        if not accept[k]:
            status_out[k] = REJECTED_MASK
            continue
        e = y[k] - yhat
        if e * e > gate2 * gate_scale * s:
            status_out[k] = REJECTED_GATE
            continue
        inv_s = 1.0 / s
        ge = e * inv_s
        for c in range(nc):
            theta[active[c]] += v[c] * ge
        if has_sensor:
            ym[0] += v[s_] * ge
        pending = True
        inv_pending = inv_s
        status_out[k] = ACCEPTED
    if pending:
        _rank_one_update(Pa, v, inv_pending, na)
