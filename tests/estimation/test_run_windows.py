"""An estimator run a window of the log at a time is the whole-log run, bit for bit.

:meth:`ChunkedEstimator.run_windows` reads the log through ``read(a, z)`` (here: slices of
the same log, each read recorded) and must yield the snapshots of ``run`` — samples, times,
outputs, status codes, maps, variances, states — for every map filter, with and without a
sensor delay, every torque law, the LPV observer and the EKFs, from the start and resumed, and never
read more than a window plus the delay's rows (or the row before it) at once.
"""

from __future__ import annotations

import numpy as np
import pytest

from estimation.errors import ConfigError, ShapeError, SignalError
from estimation.estimator import Snapshot
from estimation.filters.estimator import TableFilter
from estimation.registry import get_spec
from estimation.scenarios import get_scenario
from estimation.signals import Signals
from estimation.torque import TorqueEstimator
from tests.estimation.test_torque_estimators import NAMES as TORQUE_KINDS
from tests.estimation.test_torque_estimators import build as torque
from tests.estimation.test_torque_estimators import log as torque_log
from tests.factories import KINDS, SENSOR_KINDS, Sensor, random_problem

N = 3000


def _filter(kind: str, config: dict) -> TableFilter:
    built = get_spec(kind).build(config)
    assert isinstance(built, TableFilter)
    return built


def _same(a: Snapshot, b: Snapshot) -> None:
    assert (a.sample, a.n_samples, a.chunk_start) == (b.sample, b.n_samples, b.chunk_start)
    assert a.time_s == b.time_s
    assert a.rejected == b.rejected
    assert a.outputs.keys() == b.outputs.keys()
    for name in a.outputs:
        np.testing.assert_array_equal(a.outputs[name], b.outputs[name])
    np.testing.assert_array_equal(a.status, b.status)
    if a.table is None:
        assert b.table is None
    else:
        assert b.table is not None
        np.testing.assert_array_equal(a.table.values, b.table.values)
    if a.variance is None:
        assert b.variance is None
    else:
        np.testing.assert_array_equal(a.variance, b.variance)
    assert a.state.to_dict().keys() == b.state.to_dict().keys()
    for key, value in a.state.to_dict().items():
        np.testing.assert_array_equal(np.asarray(value), np.asarray(b.state.to_dict()[key]))


class Reader:
    """``read(a, z)`` over a log in memory, recording the rows each call returns."""

    def __init__(self, signals: Signals) -> None:
        self.signals, self.calls = signals, []

    def __call__(self, a: int, z: int) -> Signals:
        self.calls.append((a, z))
        return self.signals.slice(a, z)


def _problems() -> list[tuple[str, str]]:
    cases = [(kind, "no sensor") for kind in KINDS]
    cases += [(kind, "delay in samples") for kind in SENSOR_KINDS]
    cases += [(kind, "delay in seconds") for kind in SENSOR_KINDS[:1]]
    return cases


@pytest.mark.parametrize(("kind", "sensor"), _problems())
def test_windows_give_the_whole_log_run_bit_for_bit(kind: str, sensor: str) -> None:
    with_sensor = sensor != "no sensor"
    problem = random_problem(
        11, n=N, shape=(6, 5), sensor=Sensor(0.6, 3, 0.05) if with_sensor else None
    )
    config = problem.config(kind)
    if sensor == "delay in seconds":
        config["sensor"] = {**config["sensor"], "delay_samples": None, "delay_s": 0.06}
    signals = problem.signals()
    whole = list(_filter(kind, config).run(signals, every=97))
    read = Reader(signals)
    windowed = list(
        _filter(kind, config).run_windows(
            read, N, every=97, window=400, timeline=lambda: signals.time
        )
    )
    assert len(windowed) == len(whole)
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    tau = 3 if with_sensor else 0
    assert len(read.calls) > N // 500  # it did read in windows
    assert max(z - a for a, z in read.calls) <= 485 + tau  # 5 chunks of 97 and the delay


@pytest.mark.parametrize("kind", KINDS)
def test_an_accept_mask_gives_the_whole_log_run_with_it(kind: str) -> None:
    """A gated streamed run: ``accept`` sliced with each window (and its delay rows) gives
    :meth:`TableFilter.run` with the same mask, bit for bit, masked steps status 1."""
    with_sensor = kind in SENSOR_KINDS
    problem = random_problem(13, n=N, shape=(5, 4), sensor=Sensor(0.6, 3, 0.05))
    config = problem.config(kind) if with_sensor else problem.without_sensor().config(kind)
    signals = problem.signals()
    accept = np.random.default_rng(13).random(N) > 0.2
    whole = list(_filter(kind, config).run(signals, every=97, accept=accept))
    windowed = list(
        _filter(kind, config).run_windows(Reader(signals), N, every=97, window=400, accept=accept)
    )
    assert len(windowed) == len(whole)
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    status = np.concatenate([s.status for s in windowed])
    assert np.count_nonzero(status == 1) > N // 10
    with pytest.raises(ShapeError, match="accept mask"):
        next(_filter(kind, config).run_windows(Reader(signals), N, every=97, accept=accept[1:]))


@pytest.mark.parametrize("kind", KINDS)
def test_a_resumed_windowed_run_continues_as_the_whole_log_run(kind: str) -> None:
    problem = random_problem(12, n=N, shape=(4, 4), sensor=Sensor(0.5, 2, 0.05))
    config = problem.config(kind) if kind in SENSOR_KINDS else problem.without_sensor().config(kind)
    signals = problem.signals()
    first = list(_filter(kind, config).run(signals, every=250))
    middle = first[4].state
    whole = list(_filter(kind, config).run(signals, every=250, state=middle))
    windowed = list(
        _filter(kind, config).run_windows(Reader(signals), N, every=250, state=middle, window=600)
    )
    assert len(windowed) == len(whole)
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    done = list(
        _filter(kind, config).run_windows(Reader(signals), N, every=250, state=whole[-1].state)
    )
    assert len(done) == 1
    assert done[0].sample == N
    assert done[0].outputs["prediction"].size == 0


def _jittered(seed: int, n: int) -> Signals:
    """50 Hz with ±10 µs of timestamp jitter: 0.75 s is 37.5 samples, the rounding's tie."""
    problem = random_problem(seed, n=n, sensor=Sensor(0.6, 3, 0.05))
    signals = problem.signals()
    rng = np.random.default_rng(seed)
    time = signals.time + rng.uniform(-1e-5, 1e-5, n)
    return Signals(time, {name: signals[name] for name in signals.names}, signals.units)


@pytest.mark.parametrize("seed", [2, 3, 4])
def test_a_delay_in_seconds_is_resolved_on_the_whole_log_as_by_run(seed: int) -> None:
    """Each window's own median step would round 0.75 s to 37 or 38 samples; the windows
    take the whole log's, from its time column (``timeline``), so the run is ``run``'s."""
    signals = _jittered(seed, N)
    config = random_problem(seed, n=N, sensor=Sensor(0.6, 3, 0.05)).config("skf")
    config["sensor"] = {**config["sensor"], "delay_samples": None, "delay_s": 0.75}
    whole = list(_filter("skf", config).run(signals, every=100))
    read = Reader(signals)
    windowed = list(
        _filter("skf", config).run_windows(
            read, N, every=100, window=300, timeline=lambda: signals.time
        )
    )
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    assert max(z - a for a, z in read.calls) < N  # the time column aside, never read whole


def test_a_one_row_last_window_and_a_finished_state_need_no_sample_period() -> None:
    problem = random_problem(14, n=601, sensor=Sensor(0.6, 0, 0.05))
    config = problem.config("skf")
    config["sensor"] = {**config["sensor"], "delay_samples": None, "delay_s": 0.001}  # τ = 0
    signals = problem.signals()
    whole = list(_filter("skf", config).run(signals, every=100))
    windowed = list(_filter("skf", config).run_windows(Reader(signals), 601, every=100, window=600))
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    done = list(
        _filter("skf", config).run_windows(Reader(signals), 601, every=100, state=whole[-1].state)
    )
    assert [d.sample for d in done] == [601]


def test_a_sample_period_that_varies_is_refused_as_by_run() -> None:
    problem = random_problem(13, n=N, sensor=Sensor(0.6, 3, 0.05))
    config = problem.config("skf")
    config["sensor"] = {**config["sensor"], "delay_samples": None, "delay_s": 0.06}
    signals = problem.signals()
    uneven = np.concatenate([signals.time[:2000], signals.time[1999] + 0.04 * np.arange(1, 1001)])
    slowed = Signals(uneven, {n: signals[n] for n in signals.names}, signals.units)
    with pytest.raises(SignalError) as whole:
        list(_filter("skf", config).run(slowed, every=100))
    with pytest.raises(SignalError) as windowed:
        list(_filter("skf", config).run_windows(Reader(slowed), N, every=100, window=500))
    assert str(windowed.value) == str(whole.value)


@pytest.mark.parametrize("name", TORQUE_KINDS)
def test_a_torque_estimator_in_windows_is_its_whole_log_run(name: str) -> None:
    """Every window takes the whole log's sample period (``timeline``), so the windows of a
    jittered log are the whole run's, resumed as well as from the start."""
    signals = torque_log(N, seed=5)
    rng = np.random.default_rng(5)
    time = signals.time + rng.uniform(-2e-6, 2e-6, N)  # each window's median step differs
    signals = Signals(time, {c: signals[c] for c in signals.names}, signals.units)
    whole = list(torque(name).run(signals, every=97))
    read = Reader(signals)
    windowed = list(
        torque(name).run_windows(read, N, every=97, window=400, timeline=lambda: signals.time)
    )
    assert len(windowed) == len(whole)
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    assert max(z - a for a, z in read.calls) <= 485  # 5 chunks of 97
    middle = whole[7].state
    resumed = list(torque(name).run(signals, every=250, state=middle))
    again = list(torque(name).run_windows(Reader(signals), N, every=250, state=middle, window=600))
    assert [s.sample for s in again] == [s.sample for s in resumed]
    for a, b in zip(resumed, again, strict=True):
        _same(a, b)
    done = list(torque(name).run_windows(Reader(signals), N, every=97, state=whole[-1].state))
    assert [(d.sample, d.outputs) for d in done] == [(N, {})]


def test_a_torque_window_refuses_what_the_whole_run_refuses() -> None:
    signals = torque_log(N, seed=6)
    estimator: TorqueEstimator = torque("uio")
    assert estimator.windowed
    uneven = np.concatenate([signals.time[:2000], signals.time[1999] + 2e-3 * np.arange(1, 1001)])
    slowed = Signals(uneven, {c: signals[c] for c in signals.names}, signals.units)
    with pytest.raises(SignalError) as whole:
        list(estimator.run(slowed, every=100))
    with pytest.raises(SignalError) as windowed:
        list(estimator.run_windows(Reader(slowed), N, every=100, window=500))
    assert str(windowed.value) == str(whole.value)
    reject = np.ones(N, dtype=bool)
    reject[2500] = False
    with pytest.raises(ConfigError, match="integrates every sample"):
        list(estimator.run_windows(Reader(signals), N, every=100, accept=reject))
    with pytest.raises(ConfigError, match="time column has 10 samples"):
        next(estimator.run_windows(Reader(signals), N, every=100, timeline=lambda: uneven[:10]))


def _lpv_case(source: str) -> tuple[Signals, dict]:
    """40 s of the WHTC air path (0.1 s samples): ρ from the log's channels with the plant's
    own model (``mismatch="none"``), or computed by the observer's drawn model."""
    mismatch = "none" if source == "channels" else "nominal"
    scenario = get_scenario("maf-whtc")
    data = scenario.build(seed=3, duration_s=40.0, mismatch=mismatch)
    config = {**scenario.default_config("lpv", data), "fill": "quadratic"}
    assert config.get("rho_source", "channels") == source
    return data.signals, config


@pytest.mark.parametrize("source", ["channels", "model"])
def test_the_lpv_observer_in_windows_is_its_whole_log_run(source: str) -> None:
    """The plan's pass gives each window the whole log's ρ box, mean T_em and mask count;
    each window reads the row before it (ṗ_im, h, Δω_t). Snapshots, the filled final map and
    states are the whole run's bit for bit, with an accept mask, and resumed."""
    signals, config = _lpv_case(source)
    n = len(signals)
    accept = np.ones(n, dtype=bool)
    accept[120:160] = False
    whole = list(get_spec("lpv").build(config).run(signals, every=37, accept=accept))
    read = Reader(signals)
    windowed = list(
        get_spec("lpv").build(config).run_windows(read, n, every=37, window=100, accept=accept)
    )
    assert len(windowed) == len(whole) > n // 100
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
    assert whole[-1].rejected["mask"] >= 40
    assert max(z - a for a, z in read.calls) <= 112  # 3 chunks and the row before, plan too
    middle = whole[len(whole) // 2].state
    resumed = list(
        get_spec("lpv").build(config).run(signals, every=50, state=middle, accept=accept)
    )
    again = list(
        get_spec("lpv")
        .build(config)
        .run_windows(Reader(signals), n, every=50, state=middle, window=120, accept=accept)
    )
    assert len(again) == len(resumed)
    for a, b in zip(resumed, again, strict=True):
        _same(a, b)


@pytest.fixture(scope="module")
def ekf_log() -> Signals:
    """30 s of the WHTC air path with a MAF error over W (0.1 s samples)."""
    return get_scenario("maf-1d-whtc").build(seed=2, duration_s=30.0, mismatch="nominal").signals


@pytest.mark.parametrize("name", ["ekf-def", "ekf-aug", "ekf-map"])
def test_an_ekf_in_windows_is_its_whole_log_run(name: str, ekf_log: Signals) -> None:
    """Each window reads the row before it, from which the kernel propagates its first
    sample; snapshots (diagnostics too), maps, variances and states are the whole run's bit
    for bit, with a mask, a second output, and resumed."""
    config = {"outputs": ["maf", "p_im"]}
    n = len(ekf_log)
    accept = np.ones(n, dtype=bool)
    accept[100:130] = False
    whole = list(get_spec(name).build(config).run(ekf_log, every=23, accept=accept))
    read = Reader(ekf_log)
    windowed = list(
        get_spec(name).build(config).run_windows(read, n, every=23, window=60, accept=accept)
    )
    assert len(windowed) == len(whole) > n // 60
    for a, b in zip(whole, windowed, strict=True):
        _same(a, b)
        assert a.metrics == b.metrics
    assert whole[-1].rejected["mask"] == 30
    assert max(z - a for a, z in read.calls) <= 70  # 3 chunks and the row before
    middle = whole[len(whole) // 2].state
    resumed = list(get_spec(name).build(config).run(ekf_log, every=40, state=middle))
    again = list(
        get_spec(name).build(config).run_windows(Reader(ekf_log), n, every=40, state=middle)
    )
    assert len(again) == len(resumed)
    for a, b in zip(resumed, again, strict=True):
        _same(a, b)


def test_an_ekf_window_names_a_bad_sample_by_its_place_in_the_log(ekf_log: Signals) -> None:
    channels = dict(ekf_log.channels)
    channels["fuel_mg_per_cycle"] = channels["fuel_mg_per_cycle"].copy()
    channels["fuel_mg_per_cycle"][205] = -1.0
    bad = Signals(ekf_log.time, channels, ekf_log.units)
    ekf = get_spec("ekf-aug").build({})
    with pytest.raises(ConfigError, match="at sample 205"):
        list(ekf.run_windows(Reader(bad), len(bad), every=50, window=100))
    with pytest.raises(ConfigError, match="at least two samples"):
        list(ekf.run_windows(Reader(bad), 1, every=50))
