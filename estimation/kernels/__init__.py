"""Compiled numba kernels.

Kernels take arrays, write into them or into ``out`` arrays, and do no validation:
the public modules (:mod:`estimation.table`, :mod:`estimation.filters`) validate and call them.
"""
