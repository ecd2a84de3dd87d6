"""First-order lag with pure delay: the NOx sensor of SKF (25).

Parameters, units and validation are in :mod:`estimation.plants.nox`; this module only loops.
"""

import numba as nb
import numpy as np


@nb.njit(cache=True)
def sensor_kernel(x: np.ndarray, delay: int, a: float, y_init: float, out: np.ndarray) -> None:
    """``out[k] = a·out[k−1] + (1−a)·x[k−delay]`` with ``out[−1] = y_init``, ``x[j<0] = x[0]``.

    SKF (25). ``x``, ``out`` : (n,) float64 [ppm]; no validation, no allocation.
    """
    y = y_init
    b = 1.0 - a
    for k in range(x.shape[0]):
        j = k - delay
        xd = x[j] if j >= 0 else x[0]
        y = a * y + b * xd
        out[k] = y
