"""Fuzz suite (issue 13): malformed configs, sweep files, flight logs and argument lists through the real
command line in subprocesses. Every input must end with a non-zero exit, an error that names the
offending key / array / option, no Python traceback, and no file left behind.

Bounded (about a minute): few examples per category, ``derandomize=True`` so every run tries the same
inputs. ``make fuzz`` sets ``FINKENSIM_FUZZ=full`` and runs the full corpus (:func:`examples` scales every
category up; docs/reliability.md has the counts). The counts of inputs tried and of named errors per category
are printed by the last test (``pytest -s tests/test_fuzz_cli.py``) and kept in :data:`COUNTS`.
"""
from __future__ import annotations

import dataclasses
import io
import json
import math
import os
import pickle
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

from finkensim.config import SECTIONS, ConfigError, config_from_dict
from finkensim.testing.strategies import toml_value as _toml_value

COUNTS: dict[str, list[int]] = defaultdict(lambda: [0, 0])  # category -> [tried, named]
FULL = os.environ.get("FINKENSIM_FUZZ", "") == "full"


def examples(bounded: int, full: int) -> int:
    """Examples per category: ``bounded`` in ``make test``, ``full`` in ``make fuzz`` (FINKENSIM_FUZZ=full)."""
    return full if FULL else bounded
FUZZ = settings(deadline=None, derandomize=True, database=None, print_blob=False,
                phases=[Phase.explicit, Phase.generate],  # no shrinking: each example is a subprocess
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large])


def _cli(args, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "finkensim.cli", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def _listing(d: Path) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*"))


def _expect_named(category: str, args, files: dict[str, bytes], names) -> None:
    """Write ``files`` into a fresh directory, run ``finkensim ARGS`` there; the error must name one of ``names``."""
    COUNTS[category][0] += 1
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for name, data in files.items():
            (d / name).write_bytes(data)
        before = _listing(d)
        r = _cli(args, d)
        out = r.stdout + r.stderr
        assert r.returncode != 0, f"{args}: exit 0\n{out}"
        assert "Traceback" not in out, f"{args}:\n{out}"
        low = out.lower()
        assert any(n.lower() in low for n in names), f"{args}: none of {names} named in\n{out}"
        assert _listing(d) == before, f"{args}: left files behind: {sorted(set(_listing(d)) - set(before))}"
    COUNTS[category][1] += 1


# ------------------------------------------------------------------------------------------
# TOML text
# ------------------------------------------------------------------------------------------

FIELDS = [(sec, f.name) for sec, cls in SECTIONS.items() for f in dataclasses.fields(cls)]
VALUES = st.one_of(
    st.text(alphabet="abcxyz ,.-", max_size=6), st.booleans(), st.lists(st.integers(-3, 3), max_size=3),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**19, 10**19), st.sampled_from([-1, 0, 10**9, 1e300]),
)


@st.composite
def bad_configs(draw):
    """(TOML text, names one of which the error must contain)."""
    kind = draw(st.sampled_from(["value", "value", "value", "unknown_key", "unknown_section", "truncated", "crowded"]))
    if kind == "value":
        sec, key = draw(st.sampled_from(FIELDS))
        value = draw(VALUES)
        try:
            config_from_dict({sec: {key: value}})
            assume(False)  # a valid value is no test of an error
        except ConfigError:
            pass
        return f"[{sec}]\n{key} = {_toml_value(value)}\n", [f"{sec}.{key}"]
    if kind == "unknown_key":
        sec, key = draw(st.sampled_from(FIELDS))
        bad = key + draw(st.sampled_from(["x", "_", "s"]))
        assume((sec, bad) not in FIELDS)
        return f"[{sec}]\n{bad} = 1\n", [f"{sec}.{bad}"]
    if kind == "unknown_section":
        sec = draw(st.sampled_from(list(SECTIONS))) + draw(st.sampled_from(["s", "x"]))
        return f"[{sec}]\nn = 1\n", [sec]
    if kind == "crowded":
        n = draw(st.integers(154, 100000))
        return f"[copters]\nn = {n}\n", ["copters.n"]
    good = "[copters]\nn = 4\nradius = 0.15\n[sonar]\nyaw_deg = [0.0, 90.0, 180.0, -90.0]\n"
    cut = draw(st.integers(1, len(good) - 2))
    text = good[:cut]
    try:
        import tomllib

        config_from_dict(tomllib.loads(text))
        assume(False)  # still a valid file
    except (ConfigError, ValueError):
        pass
    return text, ["toml", "copters", "sonar", "radius", "yaw_deg"]


@settings(FUZZ, max_examples=examples(20, 160))
@given(case=bad_configs(), command=st.sampled_from(["check", "run"]))
def test_fuzz_scenario_configs(case, command):
    text, names = case
    args = ["check", "s.toml"] if command == "check" else ["run", "s.toml", "--out", "o", "--no-gif"]
    _expect_named("scenario config", args, {"s.toml": text.encode()}, names)


# ------------------------------------------------------------------------------------------
# sweep files
# ------------------------------------------------------------------------------------------

GOOD_SWEEP = {"replicates": 2, "duration": 1.0, "seed": 1}


@st.composite
def bad_sweeps(draw):
    kind = draw(st.sampled_from(["top", "top_value", "grid_key", "grid_value", "grid_empty", "metrics", "random"]))
    top = dict(GOOD_SWEEP)
    grid = {"copters.n": [2, 3]}
    extra = ""
    if kind == "top":
        name = draw(st.sampled_from(["replicate", "durations", "seeds", "metric", "grids"]))
        top[name], names = 1, [name]
    elif kind == "top_value":
        name = draw(st.sampled_from(["replicates", "duration", "seed"]))
        top[name] = draw(st.sampled_from([0, -1, "x", 1.5, math.inf, math.nan, [1]]))
        if name == "duration" and isinstance(top[name], float) and top[name] == 1.5:
            top[name] = -1.5
        if name == "seed" and top[name] == 1.5:
            top[name] = -3
        if name == "seed" and isinstance(top[name], int) and top[name] == 0:
            top[name] = -7  # seed 0 is a valid seed (found by the full corpus: an input the generator meant as bad)
        names = [name]
    elif kind == "grid_key":
        sec, key = draw(st.sampled_from(FIELDS))
        bad = f"{sec}.{key}{draw(st.sampled_from(['x', '_']))}"
        grid = {bad: [1, 2]}
        names = [bad]
    elif kind == "grid_value":
        key, value = draw(st.sampled_from([("copters.n", 0), ("copters.n", "six"), ("copters.radius", -1.0),
                                           ("behaviour.kind", "dance"), ("sonar.error", 3), ("copters.n", 5000),
                                           ("simulation.dt", 0.0)]))
        grid = {key: [value]}
        names = [key]
    elif kind == "grid_empty":
        grid = {"behaviour.speed": []}
        names = ["behaviour.speed"]
    elif kind == "metrics":
        top["metrics"] = [draw(st.sampled_from(["cohesionn", "speed", "x"]))]
        names = ["metrics", top["metrics"][0]]
    else:
        grid = None
        spec = draw(st.sampled_from([{"low": 2.0, "high": 1.0}, {"low": "a", "high": 1.0}, {"choices": []}]))
        extra = f"[random]\nn_samples = 4\n\"behaviour.speed\" = {_toml_value(spec)}\n"
        names = ["behaviour.speed"]
    text = "".join(f"{k} = {_toml_value(v)}\n" for k, v in top.items())
    if grid is not None:
        text += "[grid]\n" + "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in grid.items())
    return text + extra, names


@settings(FUZZ, max_examples=examples(10, 110))
@given(case=bad_sweeps(), command=st.sampled_from(["check", "sweep"]))
def test_fuzz_sweep_files(case, command):
    text, names = case
    args = ["check", "w.toml"] if command == "check" else ["sweep", "w.toml", "--out", "o", "--no-progress"]
    _expect_named("sweep file", args, {"w.toml": text.encode()}, names)


# ------------------------------------------------------------------------------------------
# flight logs
# ------------------------------------------------------------------------------------------

def _good_arrays(T=30, N=3) -> dict:
    rng = np.random.default_rng(1)
    pose = np.stack([rng.uniform(0.5, 2.5, (T, N)), rng.uniform(0.5, 3.5, (T, N)), rng.uniform(-3, 3, (T, N))], -1)
    rg = rng.uniform(0.3, 2.0, (T, N, N))
    rg[:, np.arange(N), np.arange(N)] = 0.0
    return {"format": np.array("finkensim-flightlog/1"), "t": 0.05 * np.arange(T), "arena": np.array([3.0, 4.0]),
            "pose": pose, "copter_ids": np.array([f"cf{i}" for i in range(N)]),
            "ultrasonic": rng.uniform(0.2, 2.5, (T, N, 4)), "ultrasonic_yaw": np.array([0.0, 1.5708, 3.1416, -1.5708]),
            "ultrasonic_offset": np.array(0.05), "ranging": rg, "imu_acc": rng.normal(0, 0.3, (T, N, 2)),
            "imu_gyro": rng.normal(0, 0.1, (T, N)), "meta": np.array(json.dumps({"copter_radius": 0.15}))}


NUMERIC = ["t", "arena", "pose", "ultrasonic", "ultrasonic_yaw", "ranging", "imu_acc", "imu_gyro"]


def _npz(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


class Blob(bytes):
    """File content with a short repr (hypothesis prints failing examples)."""

    label = ""

    def __repr__(self):
        return f"<{len(self)} bytes: {self.label}>"


@st.composite
def bad_logs(draw):
    """(file bytes, names one of which the error must contain)."""
    data, names = draw(_bad_log_parts())
    blob = Blob(data)
    blob.label = "/".join(names)
    return blob, names


@st.composite
def _bad_log_parts(draw):
    a = _good_arrays()
    kind = draw(st.sampled_from(["dtype", "shape", "units", "nonfinite", "missing", "format", "truncated",
                                 "pickle", "not_archive", "negative", "diagonal", "ids", "meta"]))
    if kind == "dtype":
        name = draw(st.sampled_from(NUMERIC + ["copter_ids"]))
        to = draw(st.sampled_from(["int", "str", "bool", "complex", "object"]))
        if to == "int":
            assume(name not in ("arena",) and name != "copter_ids")
            a[name] = np.round(np.nan_to_num(a[name])).astype(np.int64)
        elif to == "str":
            assume(name != "copter_ids")
            a[name] = a[name].astype(str)
        elif to == "bool":
            a[name] = np.ones(np.shape(a[name]), dtype=bool)
        elif to == "complex":
            a[name] = np.asarray(a[name], dtype=complex) if name != "copter_ids" else np.zeros(3, complex)
        else:
            a[name] = np.array([{"x": 1}] * 3, dtype=object)
            return _pickled_npz(a), [name, "pickle"]
        return _npz(a), [name]
    if kind == "shape":
        name = draw(st.sampled_from(NUMERIC))
        how = draw(st.sampled_from(["drop", "extra", "short"]))
        v = a[name]
        a[name] = v[..., 0] if how == "drop" and v.ndim > 1 else v[None] if how in ("drop", "extra") else v[:-1]
        return _npz(a), [name, "t", "copter_ids", "ultrasonic_yaw"]
    if kind == "units":
        name, factor, words = draw(st.sampled_from([
            ("pose", 100.0, ["pose"]), ("arena", 100.0, ["arena"]), ("t", 1000.0, ["t has", "milliseconds"]),
            ("ultrasonic", 100.0, ["ultrasonic"]), ("ranging", 1000.0, ["ranging"]), ("imu_acc", 1000.0, ["imu_acc"])]))
        if name == "pose":
            a["pose"] = a["pose"] * np.array([100.0, 100.0, 1.0])
        else:
            a[name] = a[name] * factor
        return _npz(a), words
    if kind == "nonfinite":
        name = draw(st.sampled_from(["t", "pose", "arena", "ultrasonic", "ranging", "imu_acc"]))
        value = draw(st.sampled_from([np.inf, -np.inf] + ([np.nan] if name in ("t", "pose", "arena") else [])))
        idx = tuple(draw(st.integers(0, s - 1)) for s in a[name].shape)
        if name == "ranging":
            assume(idx[1] != idx[2])
        a[name] = a[name].copy()
        a[name][idx] = value
        return _npz(a), [name]
    if kind == "missing":
        name = draw(st.sampled_from(["t", "arena", "pose", "copter_ids", "ultrasonic_yaw", "imu_gyro"]))
        del a[name]
        return _npz(a), [name]
    if kind == "format":
        a["format"] = np.array(draw(st.sampled_from(["finkensim-flightlog/2", "", "flightlog"])))
        return _npz(a), ["format"]
    if kind == "truncated":
        data = _npz(a)
        return data[: draw(st.integers(0, len(data) - 1))], ["f.npz"]
    if kind == "pickle":
        return pickle.dumps({k: v.tolist() for k, v in a.items()}), ["f.npz"]
    if kind == "not_archive":
        return draw(st.binary(min_size=0, max_size=64)), ["f.npz"]
    if kind == "negative":
        name = draw(st.sampled_from(["ultrasonic", "ranging"]))
        a[name] = a[name].copy()
        a[name][3, 0, 1] = -0.5
        return _npz(a), [name]
    if kind == "diagonal":
        a["ranging"] = a["ranging"].copy()
        a["ranging"][2, 1, 1] = draw(st.sampled_from([0.1, np.nan]))
        return _npz(a), ["ranging"]
    if kind == "ids":
        a["copter_ids"] = np.array(["a", "b", "a"])
        return _npz(a), ["copter_ids"]
    a["meta"] = np.array(draw(st.sampled_from(["{not json", "[1, 2]", '{"copter_radius": -1}', '{"copter_radius": 15}'])))
    return _npz(a), ["meta"]


def _pickled_npz(arrays: dict) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # object arrays are pickled inside the archive
    return buf.getvalue()


@settings(FUZZ, max_examples=examples(40, 220))
@given(case=bad_logs(), command=st.sampled_from(["check", "check", "gap"]))
def test_fuzz_flight_logs(case, command):
    data, names = case
    args = ["check", "f.npz"] if command == "check" else ["gap", "f.npz", "--out", "o", "--no-progress"]
    _expect_named("flight log", args, {"f.npz": data}, names)


# ------------------------------------------------------------------------------------------
# argument lists
# ------------------------------------------------------------------------------------------

BAD_ARGS = [
    (["run", "--duration", "inf"], ["duration"]), (["run", "--duration", "x"], ["--duration"]),
    (["run", "--duration", "-1"], ["duration"]), (["run", "--seed", "-1"], ["seed"]),
    (["run", "--seed", "1.5"], ["--seed"]), (["run", "--out", ""], ["--out"]), (["run", "--out", "a_file"], ["--out"]),
    (["run", "missing.toml"], ["missing.toml"]), (["run", "--bogus"], ["--bogus"]),
    (["sweep"], ["sweep"]), (["sweep", "missing.toml"], ["missing.toml"]),
    (["sweep", "w.toml", "--workers", "0"], ["--workers"]), (["sweep", "w.toml", "--executor", "threads"], ["--executor"]),
    (["sweep", "w.toml", "--scheduler", "tcp://x:1", "--executor", "serial"], ["--scheduler"]),
    (["sweep", "w.toml", "--out", ""], ["--out"]),
    (["gap"], ["gap"]), (["gap", "missing.npz"], ["missing.npz"]), (["gap", "a_file"], ["a_file"]),
    (["gap-validate", "--duration", "inf"], ["--duration"]), (["gap-validate", "--duration", "1e7"], ["--duration"]),
    (["gap-validate", "--seed", "-1"], ["--seed"]), (["gap-validate", "--trials", "0"], ["--trials"]),
    (["gap-validate", "--cases", "nope"], ["nope"]), (["gap-validate", "--out", "a_file"], ["--out"]),
    (["check"], ["check"]), (["check", "missing.npz"], ["missing.npz"]), (["check", "--arena", "1"], ["--arena"]),
    ([], ["command"]), (["fly"], ["fly"]),
    (["check", "--arena", "3,x", "w.toml"], ["--arena"]), (["check", "--arena", "0", "4", "w.toml"], ["--arena"]),
    (["check", "--arena", "3,4"], ["FILE"]), (["check", "a_file"], ["a_file"]),
    (["gap", "w.toml"], ["w.toml", "--config"]), (["gap", "w.toml", "--effects", "nosuch"], ["nosuch"]),
    (["tune"], ["tune"]), (["tune", "missing.toml"], ["missing.toml"]), (["tune", "w.toml", "--trials", "0"], ["--trials"]),
    (["import"], ["--arena"]), (["import", "--arena", "3,4", "--out", "x.npz"], ["--tracking"]),
    (["import", "--arena", "3", "--tracking", "a_file", "--out", "x.npz"], ["--arena"]),
]


@settings(FUZZ, max_examples=examples(20, 80))
@given(case=st.sampled_from(BAD_ARGS), shuffle_noise=st.booleans())
def test_fuzz_argument_lists(case, shuffle_noise):
    args, names = case
    if shuffle_noise and args and args[0] in ("run", "gap-validate"):
        args = args + ["--no-progress"] if args[0] == "gap-validate" else args + ["--no-gif"]
    files = {"a_file": b"not a directory\n",
             "w.toml": b"replicates = 1\nduration = 1.0\n[grid]\n\"copters.n\" = [2]\n"}
    _expect_named("argument list", args, files, names)


def test_fuzz_counts():
    """The counts of inputs tried and named per category (printed with ``pytest -s``)."""
    lines = [f"{cat}: {tried} tried, {named} named errors" for cat, (tried, named) in sorted(COUNTS.items())]
    total = [sum(v[0] for v in COUNTS.values()), sum(v[1] for v in COUNTS.values())]
    print("\nfuzz counts: " + "; ".join(lines) + f"; total {total[0]} tried, {total[1]} named")
    if COUNTS:  # empty when this test runs alone
        assert total[0] == total[1]
