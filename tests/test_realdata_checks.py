"""What real recordings broke, fixed in general (issue 36 item 2-4, issue 40 item 1), checked on small made-up inputs:
time units and length units judged per stream, a slow radio link accepted, heights through the importer, NaN that
nobody expected is no reading, range limits named or taken from the log, no absurd gap, parameters at a bound
flagged, "too little data to decide", categories named in the report."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import Config
from finkensim.flightlog import FlightLog, FlightLogError, validate
from finkensim.gap.attribute import effects as fx
from finkensim.gap.detect.sufficiency import check_plausible, too_little_data
from finkensim.gap.detect.limits import range_limits
from finkensim.gap.model.params import ModelParams
from finkensim.gap.model.replay import synchronous_pairs
from finkensim.gap.model.replay import GapInputError
from finkensim.gap.report.markdown import bin_text, uniform_features
from finkensim.importing import Recording, RecordingError, build_flight, check_recording, read_csv, write_csv


def tracking(n=3, T=300, rate=100.0, z=None):
    rows = []
    for c in range(n):
        t = np.arange(T) / rate
        df = pd.DataFrame({"t": t, "copter": f"cf{c}", "x": 1.0 + 0.5 * c + 0.1 * np.sin(t), "y": 1.5 + 0 * t,
                           "yaw": 0.1 * t})
        if z is not None:
            df["z"] = z[c]
        rows.append(df)
    return pd.concat(rows, ignore_index=True)


def link(a, b, times, value=1.0):
    return pd.DataFrame({"t": times, "copter": a, "channel": f"ranging/{b}", "value": value})


def test_one_copter_in_milliseconds_among_others_in_seconds_is_named():
    tr = tracking()
    tr.loc[tr.copter == "cf1", "t"] *= 1000.0
    with pytest.raises(RecordingError, match="copter 'cf1'.*looks like milliseconds"):
        check_recording(Recording(tr, link("cf0", "cf2", [])))


def test_a_fast_stream_in_milliseconds_is_named_by_its_span():
    rd = link("cf0", "cf1", np.arange(0, 3000, 10.0))  # 100 Hz in ms: 10 "s" steps, 1000 x the tracked span
    with pytest.raises(RecordingError, match="stream 'cf0:ranging/cf1' spans .* looks like milliseconds"):
        check_recording(Recording(tracking(), rd))


def test_a_slow_radio_link_is_a_normal_stream():
    tr = tracking(T=3000)  # 30 s
    rd = link("cf0", "cf1", np.arange(0.3, 29.0, 2.5))  # a reading every 2.5 s
    log = build_flight(Recording(tr, rd), (4, 4), clock_offset=0.0)
    assert np.isfinite(log.ranging[:, 0, 1]).sum() == rd.shape[0]


def test_one_copters_ranging_in_millimetres_is_named():
    rd = pd.concat([link("cf0", "cf1", np.arange(0.1, 2.9, 0.1), 0.5), link("cf1", "cf0", np.arange(0.1, 2.9, 0.1), 500.0)])
    with pytest.raises(RecordingError, match="stream 'cf1:ranging/cf0' has a median of 500 .* millimetres"):
        build_flight(Recording(tracking(), rd), (4, 4), clock_offset=0.0)


def test_heights_go_through_the_csv_and_the_log(tmp_path):
    rec = Recording(tracking(z=[1.75, 0.5, 0.52]), link("cf0", "cf1", np.arange(0.1, 2.9, 0.5)))
    write_csv(rec, tmp_path / "t.csv", tmp_path / "r.csv")
    assert pd.read_csv(tmp_path / "t.csv").columns.tolist() == ["t", "copter", "x", "y", "yaw", "z"]
    log = build_flight(read_csv(tmp_path / "t.csv", tmp_path / "r.csv"), (4, 4), clock_offset=0.0)
    assert np.allclose(log.extras["z"], [1.75, 0.5, 0.52])
    bad = pd.read_csv(tmp_path / "t.csv", dtype=str)
    bad.loc[3, "z"] = "x"
    bad.to_csv(tmp_path / "t.csv", index=False)
    with pytest.raises(FlightLogError, match="column 'z' at line 5"):
        read_csv(tmp_path / "t.csv", tmp_path / "r.csv")
    log.extras["z"] = log.extras["z"][:, :2]
    with pytest.raises(FlightLogError, match=r"z \(heights\) has shape"):
        validate(log)


def test_nan_nobody_expected_is_no_reading():
    T, N = 400, 3
    rng = np.random.default_rng(0)
    sync = rng.uniform(1, 2, (T, N, N))
    sync[rng.random((T, N, N)) < 0.6] = np.nan  # synchronous with 60 % dropouts: the mode interval stays 1
    assert synchronous_pairs(sync)[~np.eye(N, dtype=bool)].all()
    sparse = np.full((T, N, N), np.nan)
    sparse[::40] = 1.0  # each pair read every 40 samples: its NaNs are not dropouts
    assert not synchronous_pairs(sparse).any()


@settings(max_examples=30, deadline=None)
@given(st.integers(2, 5), st.floats(0.0, 0.6))
def test_random_dropouts_keep_a_pair_synchronous(n, p):
    """Up to 60 % dropouts in 3000 samples: one-sample intervals outnumber two-sample ones by > 7 sd."""
    rng = np.random.default_rng(n)
    r = np.ones((3000, n, n))
    r[rng.random(r.shape) < p] = np.nan
    assert synchronous_pairs(r)[~np.eye(n, dtype=bool)].all()


def _ranging_log(top):
    T, N = 50, 2
    r = np.full((T, N, N), 0.0)
    r[:, 0, 1] = r[:, 1, 0] = np.linspace(1.0, top, T)
    pose = np.zeros((T, N, 3))
    pose[:, :, :2] = 1.0
    return FlightLog(t=np.arange(T) * 0.1, arena=np.array([8.0, 8.0]), pose=pose, copter_ids=np.array(["a", "b"]),
                     ranging=r)


def test_readings_beyond_the_range_limit_are_named_or_taken_from_the_log():
    cfg = Config()
    with pytest.raises(GapInputError, match=r"ranging: .* lie beyond ranging.max_range = 2.5 m \(largest 4.7 m\).*"
                                            "--limits from-log"):
        range_limits(cfg, [_ranging_log(4.7)], ["f.npz"])
    new, notes = range_limits(cfg, [_ranging_log(4.7)], ["f.npz"], "from-log")
    assert new.ranging.max_range == pytest.approx(5.0) and "ranging.max_range = 5" in notes["ranging"]
    same, notes = range_limits(cfg, [_ranging_log(2.4)], ["f.npz"], "from-log")
    assert same is cfg and not notes


def test_absurd_or_non_finite_gaps_are_named():
    check_plausible({"ranging": {"gap": 0.4}})
    for g in (math.nan, math.inf, 5.7e7):
        with pytest.raises(GapInputError, match="ranging: the held-out gap came out as"):
            check_plausible({"ranging": {"gap": g}})


def test_parameters_at_a_bound_are_flagged_but_not_a_neutral_bound():
    base = ModelParams.from_config(Config())
    nlos = fx.REGISTRY["ranging_nlos"]
    assert fx.at_bound(nlos, {"bias": 1.0, "width": 0.35}, base) == ["bias", "width"]
    assert fx.at_bound(nlos, {"bias": 0.3, "width": 0.2}, base) == []
    assert fx.at_bound(fx.REGISTRY["ranging_dropout"], {"a": -100.0, "b": 0.0}, base) == []  # -100 = no dropout
    # a start of None (pose noise: each log's stated value) is no neutral bound
    pose = fx.REGISTRY["pose_noise"]
    assert fx.at_bound(pose, {"sigma_xy": 0.05, "sigma_yaw": 0.1}, base) == ["sigma_xy"]


def test_too_little_data_says_what_cannot_be_decided():
    sizes = {"ranging": {"heldout": 62, "train": 61, "blocks": 18}, "ultrasonic": {"heldout": 5000, "train": 5000,
                                                                                    "blocks": 40}}
    out = too_little_data(sizes, {"ranging": True})
    assert list(out) == ["ranging"] and "too little data to decide which effect explains the ranging gap" in out["ranging"]
    assert "whether ranging has a gap" in too_little_data(sizes, {})["ranging"]


def test_categories_are_named_and_uniform_features_found():
    assert bin_text({"feature": "hit_type", "low": 0.0, "high": 0.5}) == "hit_type = none"
    assert bin_text({"feature": "axis", "low": 2.0, "high": 2.5}) == "axis = gyro"
    assert bin_text({"feature": "speed", "low": 0.2, "high": 0.6}) == "[0.20, 0.60)"
    locs = [{"sensor": "ranging", "channel": "all", "feature": "true_range", "ci": ci} for ci in ([0.1, 0.3], [0.2, 0.4])]
    locs += [{"sensor": "ranging", "channel": "all", "feature": "speed", "ci": ci} for ci in ([0.1, 0.2], [0.3, 0.4])]
    assert uniform_features(locs) == {("ranging", "all"): ["true_range"]}


def test_gap_command_names_readings_beyond_the_limit(tmp_path, capsys):
    from finkensim.cli import main
    from finkensim.flightlog import save

    save(_ranging_log(4.7), tmp_path / "f.npz")
    assert main(["gap", str(tmp_path / "f.npz"), "--out", str(tmp_path / "gap"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "lie beyond ranging.max_range = 2.5 m" in err and "--limits from-log" in err and "Traceback" not in err


def test_the_replays_ranging_table_uses_heights():
    """With the log's z, true_range (and the ideal draws) are 3-D centre distances; without it, horizontal ones; a
    slow pair's readings all stay in the table when the samples are strided."""
    from finkensim.gap.model.predictive import RangingTable
    from finkensim.gap.model.replay import prepare_flights

    log = _ranging_log(3.0)
    log.ranging[:] = np.nan
    log.ranging[:, [0, 1], [0, 1]] = 0.0
    log.ranging[5::7, 0, 1] = 2.0  # a slow link: every 7th sample
    cfg = Config().replace({"gap.max_samples_per_flight": 10})
    flat = RangingTable.build(prepare_flights([log], ["f"], cfg), cfg, 0)
    log.pose[:, 1, 0] = 2.2  # 1.2 m apart horizontally, 1.6 m in height: 2.0 m in 3-D
    log.extras["z"] = np.tile([0.4, 2.0], (log.t.size, 1))
    tall = RangingTable.build(prepare_flights([log], ["f"], cfg), cfg, 0)
    assert flat.n == tall.n == np.isfinite(log.ranging[10:, 0, 1]).sum()  # every reading after the history
    assert np.allclose(tall.features["true_range"], 2.0)
