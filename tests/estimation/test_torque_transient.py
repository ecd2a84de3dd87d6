"""The optional TQ §VI "transient at 24 s" of the SI speed profile (estimation/plants/torque.py,
``simulate_si_torque(transient_24s=True)``): off by default, a set-point step at 24 s when on."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.errors import ConfigError
from estimation.plants.torque import (
    SPEED_REF_CHANNEL,
    TRANSIENT_24S_RPM,
    TRANSIENT_24S_S,
    simulate_si_torque,
)
from estimation.plants.torque_params import SiEngineParams

DURATION_S = 25.0


@pytest.mark.slow
def test_the_speed_profile_steps_at_24_s_only_when_enabled() -> None:
    rates = {"rate_hz": 200.0, "internal_rate_hz": 2000.0}  # coarse: only the profile matters
    plain, _ = simulate_si_torque(seed=0, duration_s=DURATION_S, **rates)
    stepped, _ = simulate_si_torque(seed=0, duration_s=DURATION_S, transient_24s=True, **rates)
    t = stepped.time
    before, after = t < TRANSIENT_24S_S - 1e-9, t >= TRANSIENT_24S_S + 1e-9
    last = SiEngineParams().profile_speeds_rpm[-1]
    assert np.all(plain[SPEED_REF_CHANNEL][t >= 14.0 + 1e-9] == last)
    assert np.all(stepped[SPEED_REF_CHANNEL][before & (t >= 14.0 + 1e-9)] == last)
    assert np.all(stepped[SPEED_REF_CHANNEL][after] == TRANSIENT_24S_RPM)
    # the same operating point before the step; the engine follows the new set-point after it
    settled = before & (t >= 20.0)
    gap = stepped["speed_rpm"][settled].mean() - plain["speed_rpm"][settled].mean()
    assert abs(gap) < 1.0
    rise = (
        stepped["speed_rpm"][t >= DURATION_S - 0.2].mean()
        - plain["speed_rpm"][t >= DURATION_S - 0.2].mean()
    )
    assert rise > 0.5 * (TRANSIENT_24S_RPM - last)


def test_a_profile_that_already_reaches_24_s_is_refused() -> None:
    params = SiEngineParams(profile_times_s=(0.0, 25.0), profile_speeds_rpm=(2200.0, 2000.0))
    with pytest.raises(ConfigError, match="transient_24s"):
        simulate_si_torque(seed=0, duration_s=1.0, params=params, transient_24s=True)
