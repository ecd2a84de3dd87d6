"""Multilinear interpolation regressor ψ(u) in sparse form (docs/algorithms.md §1)."""

import numba as nb
import numpy as np

from estimation.kernels.specialise import fixed_or


@nb.njit(cache=True)
def _locate(g: np.ndarray, u: float) -> tuple[int, float]:
    """Cell ``i`` with ``g[i] <= u < g[i+1]`` and ``η = (u-g[i])/(g[i+1]-g[i])``, clamped."""
    return _locate_near(g, u, 0)


@nb.njit(cache=True, inline="always")
def _locate_near(g: np.ndarray, u: float, hint: int) -> tuple[int, float]:
    """:func:`_locate`, trying cell ``hint`` (in ``[0, len(g)-2]``) before the bisection.

    A drive moves its operating point a little per sample, so the previous sample's cell
    usually holds the next one; the cell and ``η`` are the bisection's either way.
    """
    n = g.shape[0]
    if u <= g[0]:
        return 0, 0.0
    if u >= g[n - 1]:
        return n - 2, 1.0
    if g[hint] <= u < g[hint + 1]:
        return hint, (u - g[hint]) / (g[hint + 1] - g[hint])
    lo = 0
    hi = n - 1
    while hi - lo > 1:  # invariant: g[lo] <= u < g[hi]
        mid = (lo + hi) >> 1
        if g[mid] <= u:
            lo = mid
        else:
            hi = mid
    return lo, (u - g[lo]) / (g[lo + 1] - g[lo])


@nb.njit(cache=True, inline="always")
def _dims(corners: tuple, runtime: int) -> int:
    """The table dimension ``d`` for ``2^d`` corners, a constant when the size token fixes it."""
    if len(corners) == 2:
        return 1
    if len(corners) == 4:
        return 2
    if len(corners) == 8:
        return 3
    return runtime


@nb.njit(cache=True)
def regressor_kernel(
    U: np.ndarray,
    breakpoints: np.ndarray,
    sizes: np.ndarray,
    strides: np.ndarray,
    idx_out: np.ndarray,
    w_out: np.ndarray,
    corners: tuple,
) -> None:
    """Fill ``idx_out[n, 2^d]`` and ``w_out[n, 2^d]`` for inputs ``U[n, d]``.

    ``breakpoints`` is the concatenation of all axes (axis ``a`` occupies
    ``sizes[a]`` entries); ``strides`` are the C-order strides of the flat value
    vector. Corner ``c`` takes the upper breakpoint on axis ``a`` when bit
    ``d-1-a`` of ``c`` is set, so corners come out in C order (last axis fastest),
    and its weight is the product of ``η_a`` or ``1-η_a`` (LPV (35), SKF (10), (12b)).
    ``corners`` is the size token of :mod:`estimation.kernels.specialise` (``2^d`` or
    generic); each sample's search starts from the previous sample's cell. Results are
    bit-identical whatever the token.
    """
    n = U.shape[0]
    d = _dims(corners, U.shape[1])
    n_corners = fixed_or(corners, idx_out.shape[1])
    cell = np.zeros(d, dtype=np.int64)
    eta = np.empty(d)
    for k in range(n):
        offset = 0
        for a in range(d):
            g = breakpoints[offset : offset + sizes[a]]
            cell[a], eta[a] = _locate_near(g, U[k, a], cell[a])
            offset += sizes[a]
        for c in range(n_corners):
            flat = 0
            weight = 1.0
            for a in range(d):
                upper = (c >> (d - 1 - a)) & 1
                flat += (cell[a] + upper) * strides[a]
                weight *= eta[a] if upper else 1.0 - eta[a]
            idx_out[k, c] = flat
            w_out[k, c] = weight
