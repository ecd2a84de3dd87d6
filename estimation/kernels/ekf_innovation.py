"""The EKF's innovations and their variances, sample by sample (docs/tuning.md#innovations).

:func:`estimation.kernels.ekf.ekf_kernel` updates with each used output ``j`` in turn
(sequential scalar updates) and keeps neither ``e`` nor ``S``. This driver runs it one
sample at a time and, before each sample, recovers what its update of output ``j`` saw:

    x⁻, P⁻ of output j  = ekf_kernel over sample k alone, from the posterior of k − 1, with
                          only the used outputs before j updating (the prior for the first)
    e_j = y_j − h_j(x⁻),   S_j = H_j P⁻ H_jᵀ + r_abs2_j + r_rel2_j · y_j²

(the kernel's own ``measurement``, ``v = P H``, ``d = H v``, ``s = d + R``, so ``e_j²/S_j``
is exactly what its χ² gate tests). Then the real sample is run from the same posterior.
Both runs start from the same state and take the same path, so the filter itself is
unchanged (the run's outputs and final state equal :func:`ekf_kernel`'s over the chunk);
the price is one extra propagation per used output and sample.
"""

import math

import numba as nb
import numpy as np

from estimation.kernels import airpath_plant as apk
from estimation.kernels.ekf import N_X, N_Y, ekf_kernel, measurement


@nb.njit(cache=True)
def ekf_innovation_kernel(
    x: np.ndarray,
    P: np.ndarray,
    mem: np.ndarray,
    counts: np.ndarray,
    mode: int,
    g: np.ndarray,
    time: np.ndarray,
    U: np.ndarray,
    Y: np.ndarray,
    use: np.ndarray,
    r_abs2: np.ndarray,
    r_rel2: np.ndarray,
    accept: np.ndarray,
    q_rate: np.ndarray,
    p0_diag: np.ndarray,
    limit: int,
    gate2: float,
    max_step_s: float,
    prm: np.ndarray,
    start: int,
    stop: int,
    x_out: np.ndarray,
    w_c_out: np.ndarray,
    yhat_out: np.ndarray,
    corr_out: np.ndarray,
    status_out: np.ndarray,
    e_out: np.ndarray,
    s_out: np.ndarray,
) -> None:
    """:func:`ekf_kernel` over samples ``start … stop−1`` (same arguments and outputs), plus
    ``e_out``, ``s_out`` (stop − start, N_Y): the innovation and its variance of every used
    output at every accepted sample (module docstring); NaN where the output is not used or
    the sample is masked."""
    m = x.shape[0]
    xs = np.empty(m)
    Ps = np.empty((m, m))
    mems = np.empty(2)
    cs = np.empty_like(counts)
    before = np.zeros(N_Y, dtype=np.bool_)
    one_x = np.empty((1, N_X))
    one_w = np.empty(1)
    one_y = np.empty((1, N_Y))
    one_c = np.empty(1)
    one_s = np.empty(1, dtype=np.int8)
    H = np.empty(m)
    v = np.empty(m)
    alg = np.empty(apk.N_ALG)
    xb = np.empty(N_X)
    grad = np.empty(N_X)
    for k in range(start, stop):
        o = k - start
        for j in range(N_Y):
            e_out[o, j] = math.nan
            s_out[o, j] = math.nan
        if accept[k]:
            for j in range(N_Y):
                before[j] = False
            for j in range(N_Y):
                if not use[j]:
                    continue
                xs[:] = x
                Ps[:, :] = P
                mems[:] = mem
                cs[:] = counts
                ekf_kernel(
                    xs, Ps, mems, cs, mode, g, time, U, Y, before, r_abs2, r_rel2, accept,
                    q_rate, p0_diag, limit, gate2, max_step_s, prm, k, k + 1,
                    one_x, one_w, one_y, one_c, one_s,
                )  # fmt: skip
                yhat = measurement(j, xs, mode, g, U[k], mems, prm, alg, xb, grad, H)
                for i in range(m):
                    acc = 0.0
                    for c in range(m):
                        if H[c] != 0.0:
                            acc += Ps[i, c] * H[c]
                    v[i] = acc
                d = 0.0
                for c in range(m):
                    if H[c] != 0.0:
                        d += H[c] * v[c]
                e_out[o, j] = Y[k, j] - yhat
                s_out[o, j] = d + r_abs2[j] + r_rel2[j] * Y[k, j] * Y[k, j]
                before[j] = True
        ekf_kernel(
            x, P, mem, counts, mode, g, time, U, Y, use, r_abs2, r_rel2, accept, q_rate,
            p0_diag, limit, gate2, max_step_s, prm, k, k + 1,
            x_out[o : o + 1], w_c_out[o : o + 1], yhat_out[o : o + 1], corr_out[o : o + 1],
            status_out[o : o + 1],
        )  # fmt: skip
