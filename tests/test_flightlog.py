"""Flight-log format version 1 (spec: docs/formats/flightlog.md): round trips, every loader error, CSV import."""
from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from finkensim.testing import strategies as fst
from finkensim.flightlog import (
    DEFAULT_SONAR_YAW,
    FORMAT,
    FlightLog,
    FlightLogError,
    from_csv,
    load,
    save,
    validate,
)

# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------


def make_log(T=20, N=3, S=4, *, ultrasonic=True, ranging=True, imu=True, seed=0, meta=None, extras=None) -> FlightLog:
    """A small valid log: 3 x 4 m arena, copters well inside, a few NaN readings."""
    rng = np.random.default_rng(seed)
    t = 0.05 * np.arange(T) + 1.0
    pose = np.stack(
        [rng.uniform(0.3, 2.7, (T, N)), rng.uniform(0.3, 3.7, (T, N)), rng.uniform(-math.pi, math.pi, (T, N))], axis=-1
    )
    kw = {}
    if ultrasonic:
        us = rng.uniform(0.2, 3.0, (T, N, S))
        us[rng.random((T, N, S)) < 0.2] = np.nan
        yaw = np.array(DEFAULT_SONAR_YAW[:S] + tuple(0.1 * k for k in range(max(0, S - 4))))
        kw.update(ultrasonic=us, ultrasonic_yaw=yaw, ultrasonic_offset=0.05)
    if ranging:
        rg = rng.uniform(0.2, 2.5, (T, N, N))
        rg[rng.random((T, N, N)) < 0.2] = np.nan
        rg[:, np.arange(N), np.arange(N)] = 0.0
        kw.update(ranging=rg)
    if imu:
        acc = rng.normal(0.0, 0.5, (T, N, 2))
        acc[0, 0, 0] = np.nan
        kw.update(imu_acc=acc, imu_gyro=rng.normal(0.0, 0.3, (T, N)))
    return FlightLog(
        t=t,
        arena=np.array([3.0, 4.0]),
        pose=pose,
        copter_ids=np.array([f"cf{k}" for k in range(N)]),
        meta={"copter_radius": 0.15, "altitude": 0.6, "source": "test"} if meta is None else meta,
        extras={} if extras is None else extras,
        **kw,
    )


def raw_arrays(log: FlightLog) -> dict:
    """The arrays save() would write, for building broken files by hand."""
    out = {"format": np.array(FORMAT), "meta": np.array(json.dumps(log.meta))}
    for name in ("t", "arena", "pose", "copter_ids", "ultrasonic", "ultrasonic_yaw", "ultrasonic_offset",
                 "ranging", "imu_acc", "imu_gyro"):
        v = getattr(log, name)
        if v is not None:
            out[name] = np.asarray(v)
    return out


def write_npz(path: Path, arrays: dict) -> Path:
    with open(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path


def assert_error(fn, *words):
    """fn() raises FlightLogError whose message contains every word (case-insensitive)."""
    with pytest.raises(FlightLogError) as info:
        fn()
    msg = str(info.value)
    for w in words:
        assert w.lower() in msg.lower(), f"{w!r} not in error message: {msg}"
    return msg


def broken(**changes) -> FlightLog:
    log = make_log()
    for k, v in changes.items():
        setattr(log, k, v)
    return log


# ------------------------------------------------------------------------------------------
# round trips
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("ultrasonic", [True, False])
@pytest.mark.parametrize("ranging", [True, False])
@pytest.mark.parametrize("imu", [True, False])
def test_round_trip_with_and_without_blocks(tmp_path, ultrasonic, ranging, imu):
    log = make_log(ultrasonic=ultrasonic, ranging=ranging, imu=imu)
    validate(log)
    path = tmp_path / "flight.npz"
    save(log, path)
    back = load(path)
    assert back == log and back.equals(log)
    assert back.has_ultrasonic == ultrasonic and back.has_ranging == ranging and back.has_imu == imu
    assert back.n_steps == 20 and back.n_copters == 3 and back.n_sonars == (4 if ultrasonic else 0)
    for name in ("t", "arena", "pose"):
        assert getattr(back, name).dtype == np.float64


def test_round_trip_keeps_nan_readings(tmp_path):
    log = make_log()
    log.ultrasonic[:, 1, :] = np.nan  # copter 1 never hears anything
    save(log, tmp_path / "f.npz")
    back = load(tmp_path / "f.npz")
    np.testing.assert_array_equal(np.isnan(back.ultrasonic), np.isnan(log.ultrasonic))
    np.testing.assert_array_equal(np.isnan(back.ranging), np.isnan(log.ranging))
    assert np.isnan(back.imu_acc[0, 0, 0])
    assert np.isnan(back.ultrasonic).sum() == np.isnan(log.ultrasonic).sum() > 0


def test_round_trip_keeps_extra_arrays_and_meta(tmp_path):
    extras = {"battery": np.linspace(12.6, 11.1, 20), "labels": np.array(["start", "end"]), "flags": np.arange(4, dtype=np.int8)}
    meta = {"copter_radius": 0.12, "source": "arena 2024-05-01", "tracking_sigma_xy": 0.002, "custom": {"a": [1, 2]}}
    log = make_log(meta=meta, extras=extras)
    save(log, tmp_path / "f.npz")
    back = load(tmp_path / "f.npz")
    assert back == log
    assert back.meta == meta
    assert set(back.extras) == set(extras)
    assert back.extras["flags"].dtype == np.int8
    np.testing.assert_array_equal(back.extras["labels"], extras["labels"])


def test_file_layout_has_no_pickles(tmp_path):
    path = tmp_path / "flight.log"  # no .npz suffix: save must not append one
    save(make_log(), path)
    assert path.exists() and not (tmp_path / "flight.log.npz").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["flight.log"]  # no temporary file left
    with np.load(path, allow_pickle=False) as z:
        assert z["format"].shape == () and str(z["format"]) == FORMAT
        assert z["copter_ids"].dtype.kind == "U"
        assert z["meta"].shape == () and json.loads(str(z["meta"]))["copter_radius"] == 0.15
        assert z["ultrasonic_offset"].shape == ()
        assert all(z[k].dtype != object for k in z.files)


def test_equality_is_nan_aware_and_detects_differences():
    a, b = make_log(), make_log()
    assert a == b
    b.ultrasonic[3, 1, 2] = 1.234
    assert a != b
    c = make_log()
    c.extras["x"] = np.zeros(2)
    assert a != c
    d = make_log()
    d.meta["source"] = "other"
    assert not a.equals(d)
    assert a != make_log(ranging=False)


def test_properties_without_blocks():
    log = make_log(ultrasonic=False, ranging=False, imu=False)
    assert (log.n_steps, log.n_copters, log.n_sonars) == (20, 3, 0)
    assert not (log.has_ultrasonic or log.has_ranging or log.has_imu)


def test_integer_arrays_are_accepted_as_numbers(tmp_path):
    arrays = raw_arrays(make_log(ultrasonic=False, ranging=False, imu=False))
    arrays["arena"] = np.array([3, 4])
    back = load(write_npz(tmp_path / "f.npz", arrays))
    assert back.arena.dtype == np.float64 and back.arena.tolist() == [3.0, 4.0]


def random_logs():
    """Valid logs of 1-6 samples, 1-4 copters, 1-5 sonars, any blocks and NaN patterns (all missing included),
    in finkensim's own or imported conventions (extras, unwrapped yaw, any clock): the public strategy."""
    return st.booleans().flatmap(lambda imported: fst.flight_logs(n_steps=(1, 6), n_copters=(1, 4), n_sonars=(1, 5),
                                                                  conventions=imported))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_logs())
def test_round_trip_random_shapes_and_nan_patterns(log):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.npz"
        save(log, path)
        back = load(path)
    assert back == log
    for name in ("ultrasonic", "ranging", "imu_gyro"):
        if getattr(log, name) is not None:
            np.testing.assert_array_equal(np.isnan(getattr(back, name)), np.isnan(getattr(log, name)))


# ------------------------------------------------------------------------------------------
# loader errors: file level
# ------------------------------------------------------------------------------------------


def test_missing_file_is_named(tmp_path):
    assert_error(lambda: load(tmp_path / "nope.npz"), "nope.npz", "does not exist")


def test_non_npz_file_is_named(tmp_path):
    p = tmp_path / "notes.npz"
    p.write_text("t,copter,x,y,yaw\n0,a,1,1,0\n")
    assert_error(lambda: load(p), "notes.npz", ".npz")


def test_single_npy_file_is_rejected(tmp_path):
    p = tmp_path / "arr.npy"
    np.save(p, np.zeros(3))
    assert_error(lambda: load(p), "arr.npy", "expected an .npz")


def test_object_array_is_rejected(tmp_path):
    arrays = raw_arrays(make_log())
    arrays["payload"] = np.array([{"a": 1}, None], dtype=object)
    p = tmp_path / "pickled.npz"
    np.savez(p, **arrays)  # np.savez allows pickles by default
    assert_error(lambda: load(p), "pickled.npz", "payload", "object")


def test_missing_format(tmp_path):
    arrays = raw_arrays(make_log())
    del arrays["format"]
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "f.npz", "format", "missing", FORMAT)


@pytest.mark.parametrize("value", ["finkensim-flightlog/2", "finkensim-flightlog", ""])
def test_wrong_format(tmp_path, value):
    arrays = raw_arrays(make_log())
    arrays["format"] = np.array(value)
    msg = assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "format", "expected exactly", FORMAT)
    assert repr(value) in msg


def test_format_not_a_scalar(tmp_path):
    arrays = raw_arrays(make_log())
    arrays["format"] = np.array([FORMAT])
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "format", "shape (1,)", "0-d")


def test_format_is_checked_even_without_validation(tmp_path):
    arrays = raw_arrays(make_log())
    arrays["format"] = np.array("something-else/1")
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays), validate=False), "format")


@pytest.mark.parametrize("name", ["t", "arena", "pose", "copter_ids"])
def test_missing_required_array_is_named(tmp_path, name):
    arrays = raw_arrays(make_log())
    del arrays[name]
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), name, "missing")


def test_validation_errors_in_files_name_the_file(tmp_path):
    arrays = raw_arrays(make_log())
    arrays["t"] = arrays["t"][::-1].copy()
    assert_error(lambda: load(write_npz(tmp_path / "bad_t.npz", arrays)), "bad_t.npz", "t is not strictly increasing")
    log = load(tmp_path / "bad_t.npz", validate=False)  # still readable for repair
    assert log.t[0] > log.t[-1]


# ------------------------------------------------------------------------------------------
# loader errors: content (validate)
# ------------------------------------------------------------------------------------------


def test_shape_pose_message_names_expected_shape():
    log = broken(pose=np.zeros((20, 3, 2)))
    msg = assert_error(lambda: validate(log), "pose has shape (20, 3, 2)", "expected (T, N, 3) = (20, 3, 3)")
    assert "len(t)" in msg


@pytest.mark.parametrize(
    "name, shape, expected",
    [
        ("pose", (19, 3, 3), "(T, N, 3) = (20, 3, 3)"),
        ("pose", (20, 2, 3), "(T, N, 3) = (20, 3, 3)"),
        ("ultrasonic", (20, 3, 5), "(T, N, S) = (20, 3, 4)"),
        ("ultrasonic", (21, 3, 4), "(T, N, S) = (20, 3, 4)"),
        ("ranging", (20, 3, 2), "(T, N, N) = (20, 3, 3)"),
        ("imu_acc", (20, 3, 3), "(T, N, 2) = (20, 3, 2)"),
        ("imu_gyro", (20, 4), "(T, N) = (20, 3)"),
        ("arena", (3,), "(2,)"),
        ("t", (20, 1), "(T,)"),
        ("copter_ids", (3, 1), "(N,)"),
        ("ultrasonic_yaw", (4, 1), "(S,)"),
    ],
)
def test_shapes_that_disagree(name, shape, expected):
    value = np.full(shape, "a") if name == "copter_ids" else np.ones(shape)
    log = broken(**{name: value})
    assert_error(lambda: validate(log), f"{name} has shape", expected)


def test_ultrasonic_offset_must_be_scalar(tmp_path):
    arrays = raw_arrays(make_log())
    arrays["ultrasonic_offset"] = np.array([0.05])
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "ultrasonic_offset has shape (1,)", "scalar")


def test_empty_log_is_rejected():
    log = make_log(T=1, ultrasonic=False, ranging=False, imu=False)
    log.t, log.pose = np.zeros(0), np.zeros((0, 3, 3))
    assert_error(lambda: validate(log), "t is empty", "at least one sample")


@pytest.mark.parametrize("i", [0, 7, 18])
def test_non_increasing_t(i):
    log = make_log()
    log.t[i + 1] = log.t[i]
    assert_error(lambda: validate(log), "t is not strictly increasing", f"t[{i}]", f"t[{i + 1}]")


def test_non_finite_t():
    log = make_log()
    log.t[5] = np.nan
    assert_error(lambda: validate(log), "t[5]", "finite")


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_pose(value):
    log = make_log()
    log.pose[4, 2, 1] = value
    assert_error(lambda: validate(log), "pose", "non-finite", "cf2", "step 4")


def test_non_finite_yaw_is_an_error_too():
    log = make_log()
    log.pose[0, 0, 2] = np.nan
    assert_error(lambda: validate(log), "pose", "non-finite", "yaw")


def test_pose_outside_arena_by_more_than_radius():
    log = make_log()
    log.pose[6, 1, 0] = 3.0 + 0.2  # 0.2 m beyond x = width, radius 0.15
    assert_error(lambda: validate(log), "pose is outside the arena", "cf1", "step 6", "copter_radius = 0.15")


def test_pose_outside_arena_within_radius_is_fine():
    log = make_log()
    log.pose[6, 1, 0] = -0.14
    log.pose[7, 2, 1] = 4.0 + 0.14
    validate(log)


def test_pose_outside_uses_meta_copter_radius():
    log = make_log(meta={"copter_radius": 0.3})
    log.pose[6, 1, 1] = -0.25
    validate(log)  # inside the 0.3 m margin
    log.meta = {}  # default 0.15 m
    assert_error(lambda: validate(log), "pose is outside the arena", "copter_radius = 0.15")


def test_pose_with_centred_origin_gets_a_hint():
    log = make_log()
    log.pose[..., 0] -= 1.5
    log.pose[..., 1] -= 2.0
    assert_error(lambda: validate(log), "pose is outside the arena", "centre")


def test_negative_ultrasonic():
    log = make_log()
    log.ultrasonic[2, 1, 3] = -0.3
    assert_error(lambda: validate(log), "ultrasonic", "negative", "-0.3", "cf1", "sonar 3", ">= 0")


def test_negative_ranging():
    log = make_log()
    log.ranging[2, 0, 1] = -0.1
    assert_error(lambda: validate(log), "ranging", "negative", "cf0", ">= 0")


def test_nan_readings_are_not_negative():
    log = make_log()
    log.ultrasonic[:] = np.nan
    log.ranging[:, 0, 1] = np.nan
    validate(log)


@pytest.mark.parametrize("value", [0.1, np.nan, -0.0 - 1e-9])
def test_ranging_diagonal_not_zero(value):
    log = make_log()
    log.ranging[3, 2, 2] = value
    assert_error(lambda: validate(log), "ranging diagonal", "cf2", "step 3", "exactly 0")


@pytest.mark.parametrize("name", ["ultrasonic", "ranging", "imu_acc"])
def test_infinite_readings_are_rejected(name):
    log = make_log()
    getattr(log, name)[1, 0, 1] = np.inf
    assert_error(lambda: validate(log), name, "infinite", "NaN")


# -- units ---------------------------------------------------------------------------------


@pytest.mark.parametrize("arena, unit, factor", [((300.0, 400.0), "centimetres", "100"), ((3000.0, 4000.0), "millimetres", "1000")])
def test_arena_in_cm_or_mm(arena, unit, factor):
    log = make_log()
    log.arena = np.array(arena)
    log.pose[..., :2] *= float(factor)
    assert_error(lambda: validate(log), "arena", f"looks like {unit}", f"divide by {factor}")


@pytest.mark.parametrize("factor, unit", [(100.0, "centimetres"), (1000.0, "millimetres")])
def test_pose_in_cm_or_mm_with_arena_in_m(factor, unit):
    log = make_log()
    log.pose[..., :2] *= factor
    assert_error(lambda: validate(log), "pose", f"look like {unit}", f"divide by {int(factor)}")


@pytest.mark.parametrize("name", ["ultrasonic", "ranging"])
@pytest.mark.parametrize("factor, unit", [(100.0, "centimetres"), (1000.0, "millimetres")])
def test_readings_in_cm_or_mm(name, factor, unit):
    log = make_log()
    setattr(log, name, getattr(log, name) * factor)
    assert_error(lambda: validate(log), name, "median", f"looks like {unit}", f"divide by {int(factor)}")


def test_imu_acc_in_cm():
    log = make_log()
    log.imu_acc = np.full_like(log.imu_acc, 98.0)
    assert_error(lambda: validate(log), "imu_acc", "looks like cm/s^2", "divide by 100")


@pytest.mark.parametrize(
    "change, words",
    [
        ({"ultrasonic_offset": 5.0}, ["ultrasonic_offset = 5", "centimetres"]),
        ({"meta": {"copter_radius": 15.0}}, ["copter_radius", "centimetres"]),
        ({"meta": {"altitude": 600.0}}, ["altitude", "millimetres"]),
    ],
)
def test_scalar_lengths_in_cm_or_mm(change, words):
    assert_error(lambda: validate(broken(**change)), *words)


def test_sonar_yaw_in_degrees():
    log = make_log()
    log.ultrasonic_yaw = np.array([0.0, 90.0, 180.0, -90.0])
    assert_error(lambda: validate(log), "ultrasonic_yaw", "degrees")


def test_unit_check_can_be_turned_off_but_never_rescales(tmp_path):
    log = make_log()
    log.ultrasonic = log.ultrasonic * 100
    with pytest.raises(FlightLogError):
        validate(log)
    validate(log, check_units=False)
    save(log, tmp_path / "f.npz", check_units=False)
    with pytest.raises(FlightLogError, match="centimetres"):
        load(tmp_path / "f.npz")
    back = load(tmp_path / "f.npz", check_units=False)
    np.testing.assert_array_equal(back.ultrasonic, log.ultrasonic)


# -- blocks, dtypes, ids, meta -------------------------------------------------------------


@pytest.mark.parametrize(
    "drop, present, missing",
    [
        ("ultrasonic_yaw", "ultrasonic", "ultrasonic_yaw"),
        ("ultrasonic_offset", "ultrasonic", "ultrasonic_offset"),
        ("ultrasonic", "ultrasonic_yaw", "ultrasonic"),
        ("imu_gyro", "imu_acc", "imu_gyro"),
        ("imu_acc", "imu_gyro", "imu_acc"),
    ],
)
def test_optional_blocks_are_all_or_nothing(tmp_path, drop, present, missing):
    log = broken(**{drop: None})
    msg = assert_error(lambda: validate(log), "all-or-nothing", f"{missing} is missing")
    assert present in msg
    arrays = raw_arrays(make_log())
    del arrays[drop]
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "all-or-nothing", missing)


def test_duplicate_copter_ids():
    log = broken(copter_ids=np.array(["cf0", "cf1", "cf0"]))
    assert_error(lambda: validate(log), "copter_ids", "duplicates", "cf0", "unique")


@pytest.mark.parametrize(
    "name, value, dtype_word",
    [
        ("pose", np.full((20, 3, 3), "1.0"), "str"),
        ("t", np.ones(20, dtype=bool), "bool"),
        ("ranging", np.zeros((20, 3, 3), dtype=complex), "complex"),
        ("arena", np.array([3.0, 4.0], dtype=object), "object"),
    ],
)
def test_non_numeric_arrays(name, value, dtype_word):
    assert_error(lambda: validate(broken(**{name: value})), name, "dtype", dtype_word, "expected float64")


@pytest.mark.parametrize("name", ["pose", "t", "ultrasonic", "ranging", "imu_gyro", "ultrasonic_yaw"])
def test_integer_arrays_other_than_arena_are_errors_not_truncations(tmp_path, name):
    """spec: an integer pose is an error, not a truncation (issue 13 item 4); in memory and in files."""
    log = make_log()
    value = np.asarray(getattr(log, name))
    as_int = np.round(np.nan_to_num(value, nan=1.0) * (100 if name == "t" else 1)).astype(np.int64)
    msg = assert_error(lambda: validate(broken(**{name: as_int})), name, "integer dtype int64", "expected float64")
    assert "nothing is converted" in msg
    arrays = raw_arrays(log)
    arrays[name] = as_int
    path = write_npz(tmp_path / "int.npz", arrays)
    for check in (True, False):
        assert_error(lambda: load(path, validate=check), "int.npz", name, "integer dtype", "float64")


def test_t_in_milliseconds_gets_a_unit_hint(tmp_path):
    log = make_log()
    msg = assert_error(lambda: validate(broken(t=log.t * 1000.0)), "t", "median sample step 50", "milliseconds",
                       "divide by 1000")
    validate(broken(t=log.t * 1000.0), check_units=False)  # the heuristic can be turned off
    p = tmp_path / "ms.csv"
    p.write_text("t,copter,x,y,yaw\n0,a,1,1,0\n10,a,1,1,0\n20,a,1,1,0\n")
    assert_error(lambda: from_csv(p, (3, 4)), "ms.csv", "milliseconds")
    assert "centimetres" not in msg


def test_non_numeric_array_in_file(tmp_path):
    arrays = raw_arrays(make_log())
    arrays["ultrasonic"] = arrays["ultrasonic"].astype(str)
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "f.npz", "ultrasonic", "dtype")


def test_copter_ids_must_be_strings(tmp_path):
    assert_error(lambda: validate(broken(copter_ids=np.arange(3))), "copter_ids", "dtype", "str")
    arrays = raw_arrays(make_log())
    arrays["copter_ids"] = np.arange(3)
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "copter_ids", "str")


@pytest.mark.parametrize("text, words", [("[1, 2]", ["meta", "JSON object"]), ("{bad", ["meta", "not valid JSON"]),
                                         ('"copter"', ["meta", "JSON object"]), ('{"a": NaN}', ["meta", "not valid JSON"])])
def test_meta_not_a_json_object_in_file(tmp_path, text, words):
    arrays = raw_arrays(make_log())
    arrays["meta"] = np.array(text)
    assert_error(lambda: load(write_npz(tmp_path / "f.npz", arrays)), "f.npz", *words)


def test_meta_without_file_defaults_to_empty(tmp_path):
    arrays = raw_arrays(make_log())
    del arrays["meta"]
    assert load(write_npz(tmp_path / "f.npz", arrays)).meta == {}


@pytest.mark.parametrize(
    "meta, words",
    [
        (["not", "a", "dict"], ["meta", "JSON object"]),
        ({"copter_radius": -0.1}, ["meta['copter_radius']", "> 0"]),
        ({"copter_radius": "big"}, ["meta['copter_radius']", "number"]),
        ({"tracking_sigma_xy": -1.0}, ["tracking_sigma_xy", ">= 0"]),
        ({"source": 3}, ["meta['source']", "str"]),
        ({"when": object()}, ["meta", "not valid JSON"]),
        ({"x": float("nan")}, ["meta", "not valid JSON"]),
        ({1: "a"}, ["meta", "str keys"]),
    ],
)
def test_bad_meta_objects(meta, words):
    assert_error(lambda: validate(broken(meta=meta)), *words)


def test_meta_numpy_scalars_are_saved_as_numbers(tmp_path):
    log = make_log(meta={"copter_radius": np.float32(0.125), "n": np.int64(3)})
    save(log, tmp_path / "f.npz")
    assert load(tmp_path / "f.npz").meta == {"copter_radius": 0.125, "n": 3}


@pytest.mark.parametrize("key, words", [("pose", ["extras['pose']", "clashes"]), ("file", ["extras['file']", "reserved"])])
def test_bad_extra_names(key, words):
    assert_error(lambda: validate(broken(extras={key: np.zeros(2)})), *words)


def test_object_extra_is_rejected_before_saving(tmp_path):
    log = broken(extras={"blob": np.array([None, 1], dtype=object)})
    assert_error(lambda: save(log, tmp_path / "f.npz"), "extras['blob']", "object")
    assert not (tmp_path / "f.npz").exists()


# ------------------------------------------------------------------------------------------
# CSV import
# ------------------------------------------------------------------------------------------


def csv_text(log: FlightLog, order=None, header="t,copter,x,y,yaw") -> str:
    rows = []
    for i, t in enumerate(log.t):
        for c, cid in enumerate(log.copter_ids):
            x, y, yaw = log.pose[i, c]
            rows.append(f"{float(t)!r},{cid},{float(x)!r},{float(y)!r},{float(yaw)!r}")
    if order is not None:
        rows = [rows[k] for k in order]
    return header + "\n" + "\n".join(rows) + "\n"


def test_csv_import_good_file(tmp_path):
    ref = make_log(T=5, N=3, ultrasonic=False, ranging=False, imu=False)
    p = tmp_path / "track.csv"
    p.write_text(csv_text(ref))
    log = from_csv(p, (3.0, 4.0), meta={"altitude": 0.6})
    np.testing.assert_array_equal(log.t, ref.t)
    np.testing.assert_array_equal(log.pose, ref.pose)
    assert log.copter_ids.tolist() == ["cf0", "cf1", "cf2"] and log.copter_ids.dtype.kind == "U"
    assert log.arena.tolist() == [3.0, 4.0]
    assert log.meta == {"altitude": 0.6, "copter_radius": 0.15, "source": "csv:track.csv"}
    assert not (log.has_ultrasonic or log.has_ranging or log.has_imu)
    save(log, tmp_path / "track.npz")
    assert load(tmp_path / "track.npz") == log


def test_csv_unsorted_rows_give_the_same_log(tmp_path):
    ref = make_log(T=6, N=3, ultrasonic=False, ranging=False, imu=False)
    (tmp_path / "sorted.csv").write_text(csv_text(ref))
    order = np.random.default_rng(1).permutation(18)
    (tmp_path / "shuffled.csv").write_text(csv_text(ref, order=order))
    a = from_csv(tmp_path / "sorted.csv", (3, 4))
    b = from_csv(tmp_path / "shuffled.csv", (3, 4))
    assert a.copter_ids.tolist() == b.copter_ids.tolist()
    np.testing.assert_array_equal(a.pose, b.pose)
    np.testing.assert_array_equal(a.t, b.t)


def test_csv_copters_in_natural_order(tmp_path):
    p = tmp_path / "ids.csv"
    p.write_text("t,copter,x,y,yaw\n0,cf10,1,1,0\n0,cf2,2,2,0\n0,cf1,1,2,0\n")
    log = from_csv(p, (3, 4))
    assert log.copter_ids.tolist() == ["cf1", "cf2", "cf10"]
    np.testing.assert_array_equal(log.pose[0, :, :2], [[1, 2], [2, 2], [1, 1]])


def test_csv_numeric_copter_names_stay_strings(tmp_path):
    p = tmp_path / "ids.csv"
    p.write_text("t, copter, x, y, yaw\n0, 7, 1, 1, 0\n0, 07, 2, 2, 0\n")
    assert from_csv(p, (3, 4)).copter_ids.tolist() == ["07", "7"]


@pytest.mark.parametrize(
    "header, words",
    [
        ("t,copter,x,y", ["missing column", "'yaw'"]),
        ("t,copter,x,y,yaw,z", ["unknown column", "'z'"]),
        ("time,copter,x,y,yaw", ["missing column", "'t'", "unknown column", "'time'"]),
    ],
)
def test_csv_missing_or_unknown_column(tmp_path, header, words):
    n = len(header.split(","))
    p = tmp_path / "bad.csv"
    p.write_text(header + "\n" + ",".join(["0", "a"] + ["1"] * (n - 2)) + "\n")
    assert_error(lambda: from_csv(p, (3, 4)), "bad.csv", *words, "t, copter, x, y, yaw")


def test_csv_without_header(tmp_path):
    p = tmp_path / "nohead.csv"
    p.write_text("0,a,1,1,0\n0.1,a,1,1,0\n")
    assert_error(lambda: from_csv(p, (3, 4)), "missing column", "header")


def test_csv_missing_copter_at_a_time(tmp_path):
    ref = make_log(T=4, N=3, ultrasonic=False, ranging=False, imu=False)
    text = csv_text(ref).splitlines()
    del text[1 + 2 * 3 + 1]  # copter cf1 at step 2
    p = tmp_path / "gap.csv"
    p.write_text("\n".join(text) + "\n")
    assert_error(lambda: from_csv(p, (3, 4)), "gap.csv", "copter 'cf1'", f"t = {float(ref.t[2]):.6g} s", "interpolate")


def test_csv_duplicate_row(tmp_path):
    p = tmp_path / "dup.csv"
    p.write_text("t,copter,x,y,yaw\n0,a,1,1,0\n0,a,1.1,1,0\n")
    assert_error(lambda: from_csv(p, (3, 4)), "copter 'a'", "more than one row", "lines 2 and 3")


@pytest.mark.parametrize("cell", ["", "abc", "nan"])
def test_csv_bad_cell(tmp_path, cell):
    p = tmp_path / "cell.csv"
    p.write_text(f"t,copter,x,y,yaw\n0,a,1,1,0\n0,b,{cell},1,0\n")
    assert_error(lambda: from_csv(p, (3, 4)), "column 'x'", "line 3", "finite number")


def test_csv_in_centimetres_gets_a_unit_hint(tmp_path):
    p = tmp_path / "cm.csv"
    p.write_text("t,copter,x,y,yaw\n0,a,150,200,0\n0,b,100,300,0\n")
    assert_error(lambda: from_csv(p, (3, 4)), "cm.csv", "pose", "centimetres", "divide by 100")


def test_csv_missing_file_and_conflicting_radius(tmp_path):
    assert_error(lambda: from_csv(tmp_path / "none.csv", (3, 4)), "none.csv", "does not exist")
    p = tmp_path / "ok.csv"
    p.write_text("t,copter,x,y,yaw\n0,a,1,1,0\n")
    assert_error(lambda: from_csv(p, (3, 4), meta={"copter_radius": 0.2}), "copter_radius", "disagrees")
    assert from_csv(p, (3, 4), copter_radius=0.2, meta={"copter_radius": 0.2}).meta["copter_radius"] == 0.2
