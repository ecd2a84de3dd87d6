"""Calibration files: A2L import, values (HEX/S19/DCM/CDFX) and channel matching.

See docs/calibration.md.
"""
