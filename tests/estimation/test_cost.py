"""The declared costs of the estimators: honest upper bounds on what a run allocates."""

from __future__ import annotations

import io
import tracemalloc

import numpy as np
import pytest

from estimation.errors import ConfigError
from estimation.registry import Cost, get_spec, grid_size, names, registry
from estimation.signals import Signals

N_SAMPLES = 4000


def _log(n: int = N_SAMPLES) -> Signals:
    rng = np.random.default_rng(0)
    u1, u2 = rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    return Signals(np.arange(n) * 0.02, {"u1": u1, "u2": u2, "y": u1 * u2 + 0.1 * u1})


def _config(side: int, name: str = "kf") -> dict[str, object]:
    bp = np.linspace(0, 1, side).tolist()
    config: dict[str, object] = {
        "axes": [{"name": "u1", "breakpoints": bp}, {"name": "u2", "breakpoints": bp}],
        "output": "y",
        "sigma_v": 0.05,
    }
    if name in ("kf", "skf", "sskf"):
        config["sigma_w"] = 0.01
    if name in ("kf", "skf", "rls"):
        config["p0"] = 10.0
    if name in ("kf", "skf"):
        config["sensor"] = {"delay_samples": 3}
    return config


def _peak_bytes(name: str, side: int, signals: Signals) -> int:
    """Traced peak of a run as the worker drives it: chunks, the per-sample outputs folded
    into full-length arrays, and every few chunks a state serialised like a stored version
    (``to_dict`` lists, the array rebuilt from them, an ``.npz``)."""
    estimator = get_spec(name).build(_config(side, name))
    n = len(signals)
    tracemalloc.start()
    try:
        outputs: dict[str, np.ndarray] = {}
        status = np.zeros(n, dtype=np.int8)
        for i, snap in enumerate(estimator.run(signals, every=n // 8)):
            a, z = snap.chunk_start, snap.sample
            for key, values in snap.outputs.items():
                outputs.setdefault(key, np.full(n, np.nan))[a:z] = values
            if snap.status is not None:
                status[a:z] = snap.status
            if i % 3 == 0 or snap.done:
                data = snap.state.to_dict()
                arrays = {
                    k: np.asarray(v["data"], dtype=v["dtype"])
                    for k, v in data.items()
                    if isinstance(v, dict)
                }
                buffer = io.BytesIO()
                np.savez(buffer, **arrays)
                buffer.getvalue()
                del data, arrays, buffer
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("side", [10, 20, 30])
def test_kf_memory_model_is_an_upper_bound_within_a_sane_factor(side: int) -> None:
    signals = _log()
    get_spec("kf").build(_config(3)).fit(signals)  # compile outside the trace
    measured = _peak_bytes("kf", side, signals)
    cells, corners = grid_size([side, side])
    predicted = get_spec("kf").cost.memory_bytes(cells, len(signals), corners=corners)
    assert measured <= predicted <= 8 * measured, (side, measured, predicted)


@pytest.mark.parametrize("name", ["skf", "sskf", "rls", "nlms"])
def test_local_filters_memory_model_bounds_a_run(name: str) -> None:
    signals = _log()
    get_spec(name).build(_config(3, name)).fit(signals)
    measured = _peak_bytes(name, 30, signals)
    predicted = get_spec(name).cost.memory_bytes(900, len(signals), corners=4)
    assert measured <= predicted <= 20 * measured, (measured, predicted)


def test_kf_memory_is_quadratic_in_the_cells_and_the_others_linear() -> None:
    kf, skf = get_spec("kf").cost, get_spec("skf").cost
    small, large = kf.memory_bytes(1000, 0), kf.memory_bytes(2000, 0)
    assert large / small == pytest.approx(4.0, rel=0.05)
    assert skf.memory_bytes(200_000, 0) / skf.memory_bytes(100_000, 0) == pytest.approx(2, rel=0.01)
    # a 200×200 KF (the request that took a worker to 21.6 GB) is predicted well above that
    assert kf.memory_bytes(40_000, 7500, corners=4) > 100 * 2**30


@pytest.mark.parametrize("name", names())
def test_every_estimator_declares_a_growing_cost(name: str) -> None:
    cost = get_spec(name).cost
    assert isinstance(cost, Cost)
    assert cost.memory_bytes(10, 2000) > cost.memory_bytes(10, 1000) > 0
    assert cost.work(10, 2000) > cost.work(10, 1000) > 0
    assert cost.version_bytes(100) >= cost.state_bytes(100) > 0


def test_size_of_a_config_comes_from_its_table_or_map() -> None:
    kf = get_spec("kf")
    assert kf.cost.size(kf.config(_config(7))) == (49, 4)
    ekf_map = get_spec("ekf-map")
    assert ekf_map.cost.size(ekf_map.config({"breakpoints": [0.0, 0.1, 0.2]})) == (3, 2)
    assert registry()["uio"].cost.size(registry()["uio"].config({})) == (0, 1)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ({"p0": 1e308}, "p0: 1e.308 is too large"),
        ({"p0": [[1.0, 1.0], [1.0, float("nan")]]}, "p0: must be finite"),
        ({"sigma_w": 1e200}, "sigma_w: 1e.200 is too large"),
        ({"sigma_v": float("inf")}, "sigma_v: must be finite"),
        ({"sensor": {"sigma_f": 1e80}}, "sensor.sigma_f"),
        ({"sensor": {"delay_s": float("inf")}}, "sensor.delay_s: must be finite"),
        ({"gate_sigma": 1e100}, "gate_sigma"),
    ],
)
def test_config_arithmetic_must_stay_finite(extra: dict[str, object], match: str) -> None:
    config = {"axes": [{"name": "u1", "breakpoints": [0.0, 1.0]}] * 1, "output": "y"} | extra
    with pytest.raises(ConfigError, match=match):
        get_spec("kf").build(config)


def test_variances_at_the_bound_keep_the_filters_finite() -> None:
    signals = _log(500)
    for name in ("kf", "skf"):
        config = _config(3) | {"p0": 1e150, "sigma_w": 1e75, "sigma_v": 1e75}
        config["sensor"] = {"delay_samples": 2, "sigma_f": 1e75}
        snap = get_spec(name).build(config).fit(signals)
        assert np.isfinite(snap.table.values).all()
        assert snap.variance is not None
        assert np.isfinite(snap.variance).all()
