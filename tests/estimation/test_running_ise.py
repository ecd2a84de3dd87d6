"""estimation.metrics.running_ise: the ISE so far (TQ (60)) that the run view draws."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.metrics import running_ise, torque_metrics, torque_window


def test_running_ise_ends_at_the_ise_and_is_flat_outside_the_window() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 40.0, 0.01)
    e = rng.normal(0.0, 2.0, t.size)
    window = torque_window(t)
    assert window == (5.0, 30.0)
    ise = running_ise(t, e, window_s=window)
    assert ise[-1] == pytest.approx(torque_metrics(t, e, window_s=window)["ise"], rel=1e-12)
    assert np.all(ise[t < 5.0] == 0.0)
    assert np.all(ise[t > 30.0] == ise[-1])
    assert np.all(np.diff(ise) >= 0.0)


def test_running_ise_skips_samples_not_computed_yet() -> None:
    t = np.arange(0.0, 10.0, 0.5)
    e = np.ones_like(t)
    e[t >= 8.0] = np.nan  # a live run at t = 8 s
    ise = running_ise(t, e, window_s=(5.0, 30.0))
    assert ise[-1] == pytest.approx(3.0 * 1.0 * 1.0)  # 5.0 … 7.5 s: six samples of 0.5 s
    assert torque_window(np.array([0.0, 1.0, 12.0])) == (5.0, 12.0)
