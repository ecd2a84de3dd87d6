"""Compile-time sizes for the map-filter kernels.

A kernel takes a *size token*, a tuple whose length is the size it should be compiled for;
numba types a tuple by its length, so each length gets its own machine code, in which
``len(token)`` is a constant and LLVM unrolls the short corner loops. The empty tuple selects
the generic code, which reads the size from the arrays at run time. Either way the
arithmetic is the same, in the same order, so both give bit-identical results.
"""

import numba as nb

#: Corner counts (2^d for a d-dimensional table) that get their own compiled kernels.
SPECIALISED_CORNERS = (2, 4, 8)
GENERIC: tuple[()] = ()


@nb.njit(cache=True, inline="always")
def fixed_or(token: tuple, runtime: int) -> int:
    """``len(token)`` (a compile-time constant) if the token is not empty, else ``runtime``."""
    return len(token) if len(token) > 0 else runtime


def corner_token(n_corners: int, *, specialised: bool = True) -> tuple[int, ...]:
    """The size token of a kernel for ``n_corners`` active elements per sample: a tuple of
    that length if the count is in :data:`SPECIALISED_CORNERS`, else :data:`GENERIC`."""
    if specialised and n_corners in SPECIALISED_CORNERS:
        return (0,) * n_corners
    return GENERIC


def sensor_token(has_sensor: bool) -> tuple[int, ...]:
    """One extra element (the sensor state ``y_M``) in the local system, or none."""
    return (0,) if has_sensor else GENERIC
