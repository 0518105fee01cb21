"""Fuzz suite, continued: study files (``tune``, ``check``) and importer inputs (``import``, ``check``) through
the real command line, with the machinery of :mod:`tests.test_fuzz_cli` (a named error, exit code 2, no
traceback, nothing left behind). Bounded in ``make test``; ``make fuzz`` runs the full corpus.
"""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.test_fuzz_cli import FUZZ, _expect_named, _toml_value, examples

pytest.importorskip("optuna")

STUDY = {
    "n_trials": "n_trials = 2\n", "duration": "duration = 0.5\n",
    "params": '[params]\n"behaviour.ar_b" = { low = 1.0, high = 8.0 }\n',
    "objectives": '[objectives]\ncohesion = "minimize"\n',
    "evaluation": "[evaluation]\nn_envs = 2\nheldout_envs = 2\n",
    "base": '[base.behaviour]\nkind = "attraction_repulsion"\n',
}


@st.composite
def bad_studies(draw):
    """(TOML text, names one of which the error must contain)."""
    parts = dict(STUDY)
    kind = draw(st.sampled_from(["top", "n_trials", "range", "metric", "direction", "evaluation", "sampler",
                                 "storage", "combination", "missing", "duration", "param_key"]))
    if kind == "top":
        key = draw(st.sampled_from(["n_trails", "seeds", "objective", "param", "sample"]))
        parts["n_trials"] = f"n_trials = 2\n{key} = 1\n"
        names = [key]
    elif kind == "n_trials":
        value = draw(st.sampled_from([0, -3, 1.5, "x", [1], math.inf]))
        parts["n_trials"] = f"n_trials = {_toml_value(value)}\n"
        names = ["n_trials"]
    elif kind == "range":
        lo, hi = draw(st.sampled_from([(5.0, 1.0), ("a", 2.0), (1.0, math.nan), (-1e9, 1e9), (2.0, 2.0)]))
        parts["params"] = f'[params]\n"behaviour.ar_b" = {{ low = {_toml_value(lo)}, high = {_toml_value(hi)} }}\n'
        names = ["behaviour.ar_b"]
    elif kind == "metric":
        m = draw(st.sampled_from(["cohesio", "speed", "wall_stiking", ""]))
        parts["objectives"] = f'[objectives]\n"{m}" = "minimize"\n'
        names = ["objectives"]
    elif kind == "direction":
        d = draw(st.sampled_from(["min", "smallest", "1", "MAXIMIZE"]))
        parts["objectives"] = f'[objectives]\ncohesion = "{d}"\n'
        names = ["cohesion"]
    elif kind == "evaluation":
        key, value = draw(st.sampled_from([("n_envs", 0), ("n_envs", 10**7), ("heldout_envs", 1), ("seed", -1),
                                           ("heldout_seed", 0), ("n_env", 2), ("n_envs", "many")]))
        parts["evaluation"] = f"[evaluation]\n{key} = {_toml_value(value)}\n"
        names = [key]
    elif kind == "sampler":
        parts["n_trials"] += f'sampler = "{draw(st.sampled_from(["tpee", "grid", "cmaes"]))}"\n'
        names = ["sampler"]
    elif kind == "storage":
        parts["n_trials"] += f"storage = {_toml_value(draw(st.sampled_from(['', 3, True])))}\n"
        names = ["storage"]
    elif kind == "combination":
        off = draw(st.sampled_from(["imu", "ranging", "sonar"]))
        parts["params"] += '"behaviour.wall_check" = { choices = ["none", "sequence"] }\n'
        parts["base"] += f"[base.{off}]\nenabled = false\n"
        names = [f"{off}.enabled"]
    elif kind == "missing":
        gone = draw(st.sampled_from(["n_trials", "params", "objectives"]))
        parts[gone] = ""
        names = [gone]
    elif kind == "duration":
        value = draw(st.sampled_from([0, -1.0, math.inf, "long", 1e-6]))
        parts["duration"] = f"duration = {_toml_value(value)}\n"
        names = ["duration"]
    else:
        key = draw(st.sampled_from(["behaviour.ar_bb", "behaviours.ar_b", "copters.nn"]))
        parts["params"] = f'[params]\n"{key}" = {{ low = 1.0, high = 2.0 }}\n'
        names = [key, f"[{key.split('.')[0]}]"]  # an unknown section is named as such
    order = ["n_trials", "duration", "params", "objectives", "evaluation", "base"]
    return "".join(parts[k] for k in order), names


@settings(FUZZ, max_examples=examples(12, 90))
@given(case=bad_studies(), command=st.sampled_from(["check", "tune"]))
def test_fuzz_study_files(case, command):
    text, names = case
    args = ["check", "s.toml"] if command == "check" else ["tune", "s.toml", "--out", "o", "--no-progress"]
    _expect_named("study file", args, {"s.toml": text.encode()}, names)


TRACK = "t,copter,x,y,yaw\n" + "".join(f"{0.01 * k:.2f},a,{1 + 0.001 * k},1.5,0.1\n{0.01 * k:.2f},b,2,{1 + 0.001 * k},0.2\n"
                                       for k in range(50))
READ = "t,copter,channel,value\n" + "".join(f"{0.05 * k:.2f},a,ranging/b,{1.2 + 0.01 * k}\n" for k in range(10))


@st.composite
def bad_imports(draw):
    """(kind, files, arguments after --arena, --out value, names one of which the error must contain)."""
    files = {"track.csv": TRACK.encode(), "read.csv": READ.encode()}
    args = ["--tracking", "track.csv", "--readings", "read.csv"]
    kind = draw(st.sampled_from(["column", "cell", "ms", "swapped", "unknown_copter", "channel", "latin1_topics",
                                 "topics_toml", "rate", "far_row", "out", "clock", "bag"]))
    if kind == "column":
        bad = draw(st.sampled_from(["time", "x_m", "heading"]))
        files["track.csv"] = TRACK.replace("t,copter,x,y,yaw", "t,copter,x,y,yaw".replace(
            {"time": "t,", "x_m": ",x,", "heading": "yaw"}[bad].strip(","), bad), 1).encode()
        names = [bad, "column"]
    elif kind == "cell":
        line = draw(st.integers(2, 40))
        rows = TRACK.splitlines()
        cells = rows[line - 1].split(",")
        col = draw(st.sampled_from([0, 2, 3, 4]))
        cells[col] = draw(st.sampled_from(["abc", "", "inf", "1,5"]))
        rows[line - 1] = ",".join(cells)
        files["track.csv"] = ("\n".join(rows) + "\n").encode()
        names = ["track.csv"]
    elif kind == "ms":
        rows = TRACK.splitlines()
        out = [rows[0]] + [",".join([str(float(r.split(",")[0]) * 1000.0)] + r.split(",")[1:]) for r in rows[1:]]
        files["track.csv"] = ("\n".join(out) + "\n").encode()
        names = ["milliseconds"]
    elif kind == "swapped":
        args = ["--tracking", "read.csv", "--readings", "track.csv"]
        names = ["--tracking", "readings CSV"]
    elif kind == "unknown_copter":
        files["read.csv"] = READ.replace(",a,", ",zz,").encode()
        names = ["zz"]
    elif kind == "channel":
        ch = draw(st.sampled_from(["sonar/0", "ranging/zz", "imu/acc_z", "ultrasonic/x"]))
        files["read.csv"] = READ.replace("ranging/b", ch).encode()
        names = [ch.split("/")[-1]]
    elif kind == "latin1_topics":
        files["topics.toml"] = b'[[tracking]]\ntopic = "/caf\xe9"\ncopter = "a"\n'
        files["x.bag"] = b"#ROSBAG V2.0\n"
        args = ["--bag", "x.bag", "--topics", "topics.toml"]
        names = ["topics.toml"]
    elif kind == "topics_toml":
        files["topics.toml"] = draw(st.sampled_from([b"[[tracking]\n", b"a = " + b"[" * 3000 + b"]" * 3000 + b"\n",
                                                     b'[[trackin]]\ntopic = "/x"\ncopter = "a"\n']))
        files["x.bag"] = b"#ROSBAG V2.0\n"
        args = ["--bag", "x.bag", "--topics", "topics.toml"]
        names = ["topics"]
    elif kind == "rate":
        args += ["--rate", draw(st.sampled_from(["0", "-5", "inf", "nan", "x"]))]
        names = ["--rate", "rate"]
    elif kind == "far_row":
        files["track.csv"] = (TRACK + "10000000.0,a,1.0,1.5,0.1\n10000000.0,b,2.0,1.0,0.2\n").encode()
        args += ["--rate", "1e3", "--clock-offset", "0"]
        names = ["time base", "memory", "gap"]
    elif kind == "out":
        return kind, files, args + ["--clock-offset", "0"], draw(st.sampled_from(["/proc/x.npz", "track.csv/x.npz"])), \
            ["--out"]
    elif kind == "clock":
        args += ["--clock-offset", draw(st.sampled_from(["soon", "inf", "nan"]))]
        names = ["clock"]
    else:
        files["x.bag"] = draw(st.sampled_from([b"#ROSBAG V2.0\n" + b"\x00" * 40, b"\x89MCAP0\r\n" + b"\x01" * 30]))
        files["topics.toml"] = b'[[tracking]]\ntopic = "/x"\ncopter = "a"\n'
        args = ["--bag", "x.bag", "--topics", "topics.toml"]
        names = ["x.bag"]
    return kind, files, args, "f.npz", names


ONE_FILE_BAD = ("column", "cell", "ms", "channel")  # kinds where one file alone is wrong: check must say so too


@settings(FUZZ, max_examples=examples(12, 90))
@given(case=bad_imports(), check_first=st.booleans())
def test_fuzz_import_inputs(case, check_first):
    kind, files, args, out, names = case
    if check_first and kind in ONE_FILE_BAD and "ranging/zz" not in files["read.csv"].decode():
        # check agrees with import on the same files
        checked = [a for a in args if a.endswith(".csv")]
        _expect_named("import input (check)", ["check", *checked], files, names)
        return
    _expect_named("import input", ["import", "--arena", "3,4", *args, "--out", out], files, names)
