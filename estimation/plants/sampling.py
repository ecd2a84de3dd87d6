"""How the simulators sample: a fixed-step integration decimated to the output rate."""

from __future__ import annotations

from estimation.errors import ConfigError


def decimation(rate_hz: float, internal_rate_hz: float) -> int:
    """Integration steps per output sample, ``internal_rate_hz / rate_hz`` (both > 0).

    The simulators point-sample every n-th integration step, so the ratio must be a whole
    number ≥ 1 (within 1e-9 relative); a :class:`ConfigError` quoting both rates if not.
    """
    ratio = internal_rate_hz / rate_hz
    n = round(ratio)
    if n < 1 or abs(ratio - n) > 1e-9 * ratio:
        raise ConfigError(
            f"internal_rate_hz ({internal_rate_hz:g}) must be an integer multiple of rate_hz "
            f"({rate_hz:g}): internal_rate_hz / rate_hz = {ratio:g} is not a whole number ≥ 1"
        )
    return n
