"""finkensim.importing: asynchronous recordings into flight logs.

Unit checks of every named error, properties of the reading placement (never interpolated, one reading per sample,
order kept), pose interpolation across ±π, the clock-offset estimate (recovered, or refused when the data cannot
decide), and the round trip of the issue: a flight simulated at 100 Hz, exported asynchronously (tracking 100 Hz,
sonars 20 Hz with jitter, ranging 10 Hz, a known clock offset), imported from CSV by the CLI with
``--clock-offset auto``, diagnosed against the same config: the offset within one sonar sample and no significant
gap; and with an offset one sonar sample too late, the diagnosis names ``latency``.
"""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.flightlog import FlightLogError
from finkensim.importing import (ClockOffsetError, Recording, RecordingError, build_flight, check_recording,
                                 parse_channel, place_readings, read_csv, to_recording, write_csv)
from finkensim.importing.poses import TrackedPoses
from tests.stats import assert_within_se

YAW4 = np.radians([0.0, 90.0, 180.0, -90.0])


def tracking_table(n_copters=2, T=200, rate=100.0, t0=0.0, moving=True):
    rows = []
    for c in range(n_copters):
        t = t0 + np.arange(T) / rate
        x = 1.0 + 0.5 * c + (0.3 * np.sin(0.7 * t + c) if moving else 0 * t)
        y = 1.5 + (0.4 * np.cos(0.5 * t + 2 * c) if moving else 0 * t)
        yaw = (0.2 * t + c) if moving else 0 * t
        rows.append(pd.DataFrame({"t": t, "copter": f"cf{c + 1}", "x": x, "y": y, "yaw": yaw}))
    return pd.concat(rows, ignore_index=True)


def readings_table(rows):
    return pd.DataFrame(rows, columns=["t", "copter", "channel", "value"])


def rec(tracking=None, readings=None):
    return Recording(tracking=tracking_table() if tracking is None else tracking,
                     readings=readings_table([]) if readings is None else readings, source="test")


# ---------------------------------------------------------------------------------------- named errors

@pytest.mark.parametrize("name, hint", [("ultrasonic/x", "ultrasonic/0"), ("imu/acc_z", "imu/acc_x"),
                                        ("sonar/0", None), ("ranging", None)])
def test_unknown_channel_is_named(name, hint):
    with pytest.raises(RecordingError, match="unknown channel") as e:
        parse_channel(name)
    assert repr(name) in str(e.value)
    if hint:
        assert "did you mean" in str(e.value)


def test_channels_parse():
    assert parse_channel("ultrasonic/3").index == 3
    assert parse_channel("ranging/cf7").other == "cf7"
    assert parse_channel("imu/gyro").axis == 2


def test_missing_tracking_column():
    with pytest.raises(RecordingError, match="tracking: missing column.*'yaw'"):
        check_recording(rec(tracking=tracking_table().drop(columns="yaw")))


def test_unsorted_and_duplicated_tracking_times():
    tr = tracking_table()
    tr.loc[[5, 6], "t"] = tr.loc[[6, 5], "t"].to_numpy()
    with pytest.raises(RecordingError, match="copter 'cf1' times are not increasing at row 6"):
        check_recording(rec(tracking=tr))
    tr = tracking_table()
    tr.loc[6, "t"] = tr.loc[5, "t"]
    with pytest.raises(RecordingError, match="times are repeated"):
        check_recording(rec(tracking=tr))


def test_duplicated_reading_times_in_one_stream():
    rd = readings_table([(0.5, "cf1", "ultrasonic/0", 1.0), (0.5, "cf1", "ultrasonic/0", 1.1),
                         (0.5, "cf1", "ultrasonic/1", 1.2)])
    with pytest.raises(RecordingError, match="stream 'cf1:ultrasonic/0' times are repeated"):
        check_recording(rec(readings=rd))


def test_readings_of_an_untracked_copter():
    rd = readings_table([(0.5, "cf9", "ultrasonic/0", 1.0)])
    with pytest.raises(RecordingError, match="copter 'cf9' has readings but no tracking"):
        check_recording(rec(readings=rd))


def test_ranging_to_an_untracked_copter_and_to_itself():
    with pytest.raises(RecordingError, match="ranges to 'cf3'.*did you mean 'ranging/cf1'|ranges to 'cf3'"):
        check_recording(rec(readings=readings_table([(0.5, "cf1", "ranging/cf3", 1.0)])))
    with pytest.raises(RecordingError, match="ranging channel to itself"):
        check_recording(rec(readings=readings_table([(0.5, "cf1", "ranging/cf1", 1.0)])))


def test_times_in_milliseconds():
    tr = tracking_table()
    tr["t"] *= 1000.0
    with pytest.raises(RecordingError, match="looks like milliseconds"):
        check_recording(rec(tracking=tr))
    rd = readings_table([(1000.0 * k, "cf1", "imu/gyro", 0.0) for k in range(5)])
    with pytest.raises(RecordingError, match="readings.*looks like milliseconds"):
        check_recording(rec(readings=rd))


def test_yaw_in_degrees():
    tr = tracking_table()
    tr["yaw"] = np.degrees(tr["yaw"]) + 90.0
    with pytest.raises(RecordingError, match="looks like degrees"):
        check_recording(rec(tracking=tr))


def test_unwrapped_radians_are_not_degrees():
    tr = tracking_table(T=400)
    tr["yaw"] = tr["yaw"] + 0.5 * tr["t"]  # turning slowly past 2π is fine while most values stay below it
    check_recording(rec(tracking=tr))


@pytest.mark.parametrize("scale, unit", [(100.0, "centimetres"), (1000.0, "millimetres")])
def test_positions_and_ranges_in_cm_or_mm(scale, unit):
    tr = tracking_table()
    tr[["x", "y"]] *= scale
    with pytest.raises(RecordingError, match=f"tracking x reaches .* looks like {unit}"):
        build_flight(rec(tracking=tr), (3, 4), clock_offset=0.0)
    rd = readings_table([(0.01 * k, "cf1", "ultrasonic/0", 1.5 * scale) for k in range(50)])
    with pytest.raises(RecordingError, match=f"stream 'cf1:ultrasonic/0' has a median .* looks like {unit}"):
        build_flight(rec(readings=rd), (3, 4), sonar_yaw=YAW4, sonar_offset=0.1, clock_offset=0.0)


def test_sonar_geometry_is_required_and_checked():
    rd = readings_table([(0.01 * k, "cf1", "ultrasonic/4", 1.0) for k in range(50)])
    with pytest.raises(RecordingError, match="sonar_yaw is not given"):
        build_flight(rec(readings=rd), (3, 4), clock_offset=0.0)
    with pytest.raises(RecordingError, match="'ultrasonic/4' but the sonar yaw list has 4 entries"):
        build_flight(rec(readings=rd), (3, 4), sonar_yaw=YAW4, sonar_offset=0.1, clock_offset=0.0)


@pytest.mark.parametrize("kw, match", [(dict(clock_offset="soon"), "expected 'auto' or a number"),
                                       (dict(arena=(3,)), "expected \\(width, length\\)"),
                                       (dict(arena=(3, -4)), "two positive numbers"),
                                       (dict(clock_offset=math.inf), "finite number"),
                                       (dict(clock_offset=0.0, rate=-5), "positive number of samples")])
def test_bad_arguments(kw, match):
    kw = {"arena": (3, 4), **kw}
    with pytest.raises(RecordingError, match=match):
        build_flight(rec(), **kw)


def test_csv_errors_name_file_column_and_line(tmp_path):
    p = tmp_path / "track.csv"
    p.write_text("t,copter,x,y,yaw\n0.0,cf1,1,1,0\n0.01,cf1,abc,1,0\n")
    with pytest.raises(FlightLogError, match=r"tracking CSV .*column 'x' at line 3 \(copter 'cf1'\)"):
        read_csv(p)
    p.write_text("t,copter,x,y,yaw\n0.0,cf1,1,1,0\n0.01,cf1,1,1,0\n")
    q = tmp_path / "read.csv"
    q.write_text("t,copter,chan,value\n")
    with pytest.raises(FlightLogError, match="readings CSV .*missing column.*'channel'"):
        read_csv(p, q)
    q.write_text("t,copter,channel,value\n0.0,cf1,imu/gyro,\n0.01,cf1,imu/gyro,fast\n")
    with pytest.raises(FlightLogError, match=r"column 'value' at line 3 .*NaN or empty = no reading"):
        read_csv(p, q)


# ---------------------------------------------------------------------------------------- placement

@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2), st.floats(0.0, 2.0, allow_nan=False)), min_size=1, max_size=80),
       st.sampled_from([0.01, 0.05, 0.1]))
def test_placement_keeps_readings_unchanged_and_in_order(items, dt):
    stream = np.array([s for s, _ in items], dtype=np.int64)
    times = np.array([t for _, t in items])
    order = np.lexsort((times, stream))
    stream, times = stream[order], times[order]
    keep = np.ones(times.size, bool)
    keep[1:] = ~((stream[1:] == stream[:-1]) & (times[1:] == times[:-1]))  # strictly increasing per stream
    stream, times = stream[keep], times[keep]
    K = 15
    sample, reason = place_readings(times, stream, 0.1, dt, K)
    placed = sample >= 0
    assert np.all((reason == 0) == placed)
    assert np.all(sample[placed] < K)
    # one reading per (stream, sample), at most one period from its own time, order kept within each stream
    keys = stream[placed] * K + sample[placed]
    assert np.unique(keys).size == keys.size
    assert np.all(np.abs(times[placed] - (0.1 + dt * sample[placed])) < dt * (1 + 1e-9))
    for s in np.unique(stream):
        m = placed & (stream == s)
        assert np.all(np.diff(sample[m]) > 0)
    # a reading inside the time base is only dropped when its own sample is taken by another reading
    inside = np.rint((times - 0.1) / dt).astype(int)
    assert np.all((reason == 1) == ((inside < 0) | (inside >= K)))


def test_built_flight_holds_exactly_the_input_values():
    rng = np.random.default_rng(3)
    rows = []
    for c in ("cf1", "cf2"):
        for s in range(4):
            t = np.sort(rng.uniform(0.1, 1.8, 30))
            t = t[np.concatenate([[True], np.diff(t) > 1e-6])]
            rows += [(ti, c, f"ultrasonic/{s}", v) for ti, v in zip(t, rng.uniform(0.2, 2.5, t.size))]
    rd = readings_table(rows)
    log = build_flight(rec(readings=rd), (3, 4), sonar_yaw=YAW4, sonar_offset=0.1, clock_offset=0.0)
    got = log.ultrasonic[np.isfinite(log.ultrasonic)]
    assert np.isin(got, rd["value"].to_numpy()).all()  # never interpolated
    dropped = sum(log.meta["import"]["dropped"].values())
    assert got.size + dropped == len(rd)
    assert log.meta["import"]["readings_placed"]["ultrasonic"] == got.size
    off = log.extras["ultrasonic_time_offset"]
    assert np.all(np.abs(off[np.isfinite(off)]) < 0.01 + 1e-12)


def test_ranging_expected_marks_recorded_entries_only():
    rd = readings_table([(0.1 * k, "cf1", "ranging/cf2", 1.0 if k % 3 else np.nan) for k in range(1, 15)])
    log = build_flight(rec(readings=rd), (3, 4), clock_offset=0.0)
    e = log.extras["ranging_expected"]
    assert e[:, 0, 1].sum() == 14 and not e[:, 1, 0].any()
    assert np.isnan(log.ranging[e[:, 0, 1], 0, 1]).sum() == 4  # the lost ones are expected but NaN
    assert log.meta["import"]["dropped"]["ranging: lost (NaN) readings"] == 4


def test_yaw_interpolates_through_pi():
    tr = pd.DataFrame({"t": [0.0, 0.1], "copter": "a", "x": 1.0, "y": 1.0, "yaw": [math.pi - 0.1, -math.pi + 0.1]})
    poses = TrackedPoses(check_recording(rec(tracking=tr)))
    yaw = poses.copter(0, np.array([0.05]))[0, 2]
    assert abs(abs(yaw) - math.pi) < 1e-9  # through π, not through 0


# ---------------------------------------------------------------------------------------- clock offset

def test_clock_offset_refused_when_the_copters_do_not_move():
    tr = tracking_table(T=1000, moving=False)
    rows = [(0.05 * k, c, f"ultrasonic/{s}", 1.0 + 0.1 * s) for k in range(1, 190) for c in ("cf1", "cf2")
            for s in range(4)]
    with pytest.raises(ClockOffsetError, match="about equally well.*pass the offset"):
        build_flight(rec(tracking=tr, readings=readings_table(rows)), (3, 4), sonar_yaw=YAW4, sonar_offset=0.1,
                     max_offset=0.5)


def test_clock_offset_refused_with_too_few_readings():
    rd = readings_table([(0.05 * k + 0.5, "cf1", "ultrasonic/0", 1.0 + 0.01 * k) for k in range(10)])
    with pytest.raises(ClockOffsetError, match=r"only \d sonar readings with an echo and 0 ranging"):
        build_flight(rec(readings=rd), (3, 4), sonar_yaw=YAW4, sonar_offset=0.1, max_offset=0.2)


# ---------------------------------------------------------------------------------------- round trip

@pytest.fixture(scope="module")
def simulated():
    import finkensim as fs

    cfg = fs.load_config({"simulation": {"dt": 0.01}, "sonar": {"crosstalk": "off"}})
    log, _, _ = fs.simulate_flight(cfg, duration=30.0, seed=3)
    return cfg, log


TRUE_OFFSET = 0.3
# the diagnosis at CI size (as tests/test_gap.py's): a clock offset one sonar sample off is a strong latency, named
# with 12 draws; the round trip without a gap keeps the full size (its power is what checks the import)
CI_GAP = {"gap.draws": 12, "gap.max_samples_per_flight": 300, "gap.fit_max_readings": 5000, "gap.n_boot": 200}


def test_round_trip_csv_cli_auto_offset_and_no_gap(simulated, tmp_path):
    import finkensim as fs
    from finkensim.flightlog import load

    cfg, log = simulated
    rec_ = to_recording(log, tracking_rate=100, sonar_rate=20, ranging_rate=10, jitter=0.1, clock_offset=TRUE_OFFSET,
                        seed=1)
    write_csv(rec_, tmp_path / "track.csv", tmp_path / "read.csv")
    (tmp_path / "scenario.toml").write_text("[simulation]\ndt = 0.01\n[sonar]\ncrosstalk = \"off\"\n")
    cmd = [sys.executable, "-m", "finkensim.cli", "import", "--tracking", str(tmp_path / "track.csv"), "--readings",
           str(tmp_path / "read.csv"), "--arena", "3,4", "--sonar-yaw-deg", "0,90,180,-90", "--sonar-offset",
           str(log.ultrasonic_offset), "--copter-radius", str(log.meta["copter_radius"]), "--altitude",
           str(log.meta["altitude"]), "--config", str(tmp_path / "scenario.toml"), "--out", str(tmp_path / "f.npz")]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    assert "clock offset +0.3" in p.stdout
    imported = load(tmp_path / "f.npz")
    c = imported.meta["import"]["clock_offset"]
    assert abs(c["seconds"] - TRUE_OFFSET) < 0.05  # within one sonar sample (20 Hz): docs/user-guide/import.md's claim
    assert c["uncertainty"] < 0.05
    # and within 5 of its own standard errors (the importer's bootstrap SD of the loss minimum)
    assert_within_se(c["seconds"], TRUE_OFFSET, c["uncertainty"], what="auto clock offset (s)")
    np.testing.assert_allclose(imported.pose[:, :, :2], log.pose[:imported.n_steps, :, :2], atol=0.02)
    verdict = fs.diagnose([imported], ["imported"], cfg).to_spec()["verdict"]
    assert not verdict["significant_gap"], verdict


def test_round_trip_with_a_late_offset_names_latency(simulated):
    import finkensim as fs

    cfg, log = simulated
    rec_ = to_recording(log, clock_offset=TRUE_OFFSET, seed=1)
    wrong = build_flight(rec_, log.arena, sonar_yaw=log.ultrasonic_yaw, sonar_offset=log.ultrasonic_offset,
                         copter_radius=log.meta["copter_radius"], altitude=log.meta["altitude"],
                         clock_offset=TRUE_OFFSET + 0.05)  # one sonar sample too late
    verdict = fs.diagnose([wrong], ["wrong offset"], cfg.replace(CI_GAP)).to_spec()["verdict"]
    assert verdict["significant_gap"] and verdict["effect"] == "latency", verdict


def test_round_trip_with_an_early_offset_names_a_negative_latency(simulated):
    """Readings placed one sonar sample too early describe the world after their time stamp: ``latency``
    with a negative lag of the delayed sensors (not pose noise, which widens instead of shifting)."""
    import finkensim as fs

    cfg, log = simulated
    rec_ = to_recording(log, clock_offset=TRUE_OFFSET, seed=1)
    wrong = build_flight(rec_, log.arena, sonar_yaw=log.ultrasonic_yaw, sonar_offset=log.ultrasonic_offset,
                         copter_radius=log.meta["copter_radius"], altitude=log.meta["altitude"],
                         clock_offset=TRUE_OFFSET - 0.05)
    rep = fs.diagnose([wrong], ["early offset"], cfg.replace(CI_GAP)).to_spec()
    assert rep["verdict"]["significant_gap"] and rep["verdict"]["effect"] == "latency", rep["verdict"]
    lat = next(e for e in rep["effects"] if e["name"] == "latency")["params"]
    assert -0.06 <= lat["ultrasonic"] <= -0.04, lat


def test_cli_errors_are_one_line(tmp_path):
    base = [sys.executable, "-m", "finkensim.cli", "import"]
    cases = [
        (["--arena", "3", "--out", str(tmp_path / "x.npz"), "--tracking", "t.csv"], "--arena '3': expected a positive width and length"),
        (["--arena", "3,4", "--out", str(tmp_path / "x.npz")], "an input is required"),
        (["--arena", "3,4", "--out", str(tmp_path / "x.npz"), "--bag", "b.bag"], "--bag needs --topics"),
        (["--arena", "3,4", "--out", str(tmp_path / "no" / "x.npz"), "--tracking", "t.csv"], "does not exist"),
        (["--arena", "3,4", "--out", str(tmp_path / "x.npz"), "--tracking", "t.csv", "--clock-offset", "later"],
         "--clock-offset 'later'"),
        (["--arena", "3,4", "--out", str(tmp_path / "x.npz"), "--tracking", str(tmp_path / "none.csv")],
         "file does not exist"),
    ]
    for args, match in cases:
        p = subprocess.run(base + args, capture_output=True, text=True, timeout=120)
        assert p.returncode == 2, (args, p.stderr)
        assert match in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
        assert "Traceback" not in p.stderr
