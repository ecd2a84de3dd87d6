"""Cycle loading (estimation.cycles): durations, known maxima and distances, composition."""

from importlib import resources

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from estimation.cycles import Cycle, list_cycles, load_cycle, make_sdmp
from estimation.errors import ConfigError, SignalError

# name, duration (s), max speed (km/h), distance (km) — published values:
# UDDS 7.45 mi, 56.7 mph; HWFET 10.26 mi, 59.9 mph; US06 8.01 mi, 80.3 mph;
# WLTC class 3b 23.27 km, 131.3 km/h; NEDC 11.007 km (ECE-15 4 x 1.013 + EUDC 6.955), 120 km/h;
# FTP-75 11.04 mi, 56.7 mph.
VEHICLE_CYCLES = [
    ("udds", 1369.0, 91.2, 11.99),
    ("hwfet", 765.0, 96.4, 16.51),
    ("us06", 600.0, 129.2, 12.89),
    ("wltc3b", 1800.0, 131.3, 23.27),
    ("nedc", 1180.0, 120.0, 11.007),
    ("ftp75", 1874.0, 91.2, 17.77),
]


@pytest.mark.parametrize(("name", "duration_s", "vmax_kmh", "distance_km"), VEHICLE_CYCLES)
def test_vehicle_cycle_duration_speed_and_distance(name, duration_s, vmax_kmh, distance_km):
    c = load_cycle(name)
    assert c.kind == "vehicle"
    assert c.name == name
    assert c.duration_s == duration_s
    assert_array_equal(c.time_s, np.arange(duration_s + 1))  # 1 Hz from t = 0
    assert c.speed_kmh.min() >= 0.0
    assert c.speed_kmh.max() == pytest.approx(vmax_kmh, abs=0.15)
    assert c.distance_km == pytest.approx(distance_km, rel=0.01)
    assert c.speed_kmh[0] == 0.0
    assert c.speed_kmh[-1] == 0.0
    assert c.source


def test_whtc_is_normalised_engine_cycle():
    c = load_cycle("whtc")
    assert c.kind == "engine"
    assert c.speed_kmh is None
    assert c.duration_s == 1800.0
    assert_array_equal(c.time_s, np.arange(1801.0))
    assert c.speed_pct.min() >= 0.0
    assert c.speed_pct.max() <= 100.0
    assert c.torque_pct.max() <= 100.0
    # Motoring points ('m' in the file) become -100 % (full drag); count them independently.
    text = (resources.files("estimation.cycles") / "data" / "whtc.txt").read_text()
    n_motoring = sum(line.split()[-1] == "m" for line in text.splitlines()[2:] if line.strip())
    assert n_motoring > 300
    assert np.count_nonzero(c.torque_pct == -100.0) == n_motoring
    assert np.count_nonzero(c.torque_pct < 0) == n_motoring
    # Spot values straight from the file: t = 8 s "15.8 30.9", t = 30 s "52.1 m".
    assert (c.speed_pct[8], c.torque_pct[8]) == (15.8, 30.9)
    assert (c.speed_pct[30], c.torque_pct[30]) == (52.1, -100.0)
    assert (c.speed_pct[0], c.torque_pct[0]) == (0.0, 0.0)  # prepended idle point


def test_ftp75_is_udds_plus_first_505_s():
    udds = load_cycle("udds")
    ftp = load_cycle("ftp75")
    assert ftp.time_s.size == udds.time_s.size + 505
    assert_array_equal(ftp.speed_kmh[: udds.time_s.size], udds.speed_kmh)
    assert_array_equal(ftp.speed_kmh[udds.time_s.size :], udds.speed_kmh[1:506])
    assert_array_equal(np.diff(ftp.time_s), 1.0)  # time continues without a gap
    bag1_km = float(np.trapezoid(udds.speed_kmh[:506], udds.time_s[:506]) / 3600)
    assert ftp.distance_km == pytest.approx(udds.distance_km + bag1_km, rel=1e-12)


def test_list_cycles_and_every_name_loads():
    names = list_cycles()
    assert set(names) == {"udds", "hwfet", "us06", "wltc3b", "nedc", "ftp75", "whtc", "sdmp"}
    for name in names:
        c = load_cycle(name)
        assert isinstance(c, Cycle)
        assert np.all(np.isfinite(c.time_s))
    assert load_cycle(" UDDS ").name == "udds"


def test_unknown_cycle_lists_valid_names():
    with pytest.raises(ConfigError, match=r"unknown cycle 'etc'; valid names: udds, hwfet"):
        load_cycle("etc")
    with pytest.raises(ValueError, match="valid names"):
        load_cycle("ftp72")


def test_data_files_ship_in_the_package():
    data = resources.files("estimation.cycles") / "data"
    for filename in ("udds.csv", "hwfet.csv", "us06.csv", "wltc_3b.csv", "nedc.txt", "whtc.txt"):
        assert (data / filename).is_file()
    assert "GTR No. 4" in (data / "SOURCES.md").read_text(encoding="utf-8")


def test_cycle_arrays_are_read_only_and_validated():
    c = load_cycle("us06")
    with pytest.raises(ValueError, match="read-only"):
        c.speed_kmh[0] = 1.0
    with pytest.raises(SignalError, match=r"negative speed -1 km/h at 1 s"):
        Cycle("bad", "vehicle", np.arange(3.0), "test", speed_kmh=[0.0, -1.0, 0.0])
    with pytest.raises(SignalError, match="needs speed_pct"):
        Cycle("bad", "engine", np.arange(3.0), "test", torque_pct=np.zeros(3))
    with pytest.raises(SignalError, match="strictly increasing"):
        Cycle("bad", "vehicle", [0.0, 0.0, 1.0], "test", speed_kmh=np.zeros(3))


def test_sdmp_is_deterministic_for_a_seed():
    a, b = make_sdmp(seed=3), make_sdmp(seed=3)
    assert_array_equal(a.speed_kmh, b.speed_kmh)
    assert_array_equal(a.grade_pct, b.grade_pct)
    c = make_sdmp(seed=4)
    assert not np.array_equal(a.speed_kmh, c.speed_kmh)
    assert_array_equal(load_cycle("sdmp").speed_kmh, make_sdmp(seed=0).speed_kmh)


def test_sdmp_has_sharp_speed_and_grade_changes():
    c = make_sdmp(seed=0, duration_s=1200)
    assert c.duration_s == 1200.0
    v, grade = c.speed_kmh, c.grade_pct
    a_ms2 = np.diff(v) / 3.6
    assert v.min() >= 0.0
    assert v.max() <= 110.0
    assert a_ms2.max() <= 3.2 + 1e-9  # acceleration draw U(1.8, 3.2) m/s², power-capped
    assert a_ms2.min() >= -5.0 - 1e-9  # braking U(2.5, 5) m/s²
    assert np.count_nonzero(a_ms2 > 1.5) >= 60  # many hard accelerations ...
    assert np.count_nonzero(a_ms2 < -2.5) >= 60  # ... and hard brakings
    stops = np.count_nonzero((v[1:] == 0.0) & (v[:-1] > 0.0))
    assert stops >= 2
    assert (v[0], v[-1]) == (0.0, 0.0)
    assert grade.max() > 4.0
    assert grade.min() < -4.0  # climbs and descents
    assert np.abs(grade).max() <= 9.0
    # blended: a step of at most 18 % spread by the 21-tap Hann window (sum 11) -> <= 1.64 %/s
    assert np.abs(np.diff(grade)).max() <= 18.0 / 11.0
    # Still a drivable cycle: the speed trace is 20-ish km in 20 minutes.
    assert 10.0 < c.distance_km < 30.0


def test_sdmp_rejects_too_short():
    with pytest.raises(ConfigError, match="duration_s must be an integer >= 120"):
        make_sdmp(duration_s=60)
