"""Fuzz cases for the defects of issue 40: each input once produced silently wrong data, a traceback, a late
refusal or two commands that disagreed. Every case goes through the real command line (a subprocess, as in
:mod:`tests.test_fuzz_cli`) and must end in a named error (exit 2, no traceback, nothing left behind) or in the
documented behaviour.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from tests.test_fuzz_cli import _expect_named, _good_arrays, _npz


# ------------------------------------------------------------------------------------------
# item 2: flight logs whose units or text types are wrong pass no longer
# ------------------------------------------------------------------------------------------

def _log_with(**changes) -> bytes:
    a = _good_arrays(T=changes.pop("T", 30))
    for k, v in changes.items():
        a[k] = v(a) if callable(v) else v
    return _npz(a)


MS_LOGS = {  # t in ms from fast trackers: a median step of 1 to 5 "s" over more than an hour of "s"
    f"{hz} Hz": _log_with(T=int(4000 * hz / 1000) + 2, t=lambda a, hz=hz: (1000.0 / hz) * np.arange(a["pose"].shape[0]))
    for hz in (200, 250, 500, 1000)
}


@pytest.mark.parametrize("command", ["check", "gap"])
@pytest.mark.parametrize("rate", sorted(MS_LOGS))
def test_time_in_milliseconds_from_a_fast_tracker(rate, command):
    args = ["check", "f.npz"] if command == "check" else ["gap", "f.npz", "--out", "o", "--no-progress"]
    _expect_named("issue 40: flight log units", args, {"f.npz": MS_LOGS[rate]}, ["milliseconds"])


def _yaw_degrees(a):
    pose = a["pose"].copy()
    pose[..., 2] = np.random.default_rng(3).uniform(-180, 180, pose.shape[:2])
    return pose


def _yaw_degrees_slow(a):  # a slowly turning copter: mostly beyond 2 pi in degrees
    pose = a["pose"].copy()
    pose[..., 2] = np.linspace(20.0, 170.0, pose.shape[0])[:, None]
    return pose


@pytest.mark.parametrize("command", ["check", "gap"])
@pytest.mark.parametrize("make", [_yaw_degrees, _yaw_degrees_slow], ids=["random", "slow"])
def test_yaw_in_degrees(make, command):
    args = ["check", "f.npz"] if command == "check" else ["gap", "f.npz", "--out", "o", "--no-progress"]
    _expect_named("issue 40: flight log units", args, {"f.npz": _log_with(pose=make)}, ["degrees"])


@pytest.mark.parametrize("name", ["format", "meta", "copter_ids"])
def test_text_arrays_stored_as_bytes(name):
    enc = {"format": lambda a: np.array(b"finkensim-flightlog/1"),
           "meta": lambda a: np.array(json.dumps({"copter_radius": 0.15}).encode()),
           "copter_ids": lambda a: np.array([b"cf0", b"cf1", b"cf2"])}[name]
    _expect_named("issue 40: flight log text", ["check", "f.npz"], {"f.npz": _log_with(**{name: enc})},
                  [f"{name} has dtype", "bytes"])


# ------------------------------------------------------------------------------------------
# item 3 and 13: gap checks --heldout and --effects before reading any flight
# ------------------------------------------------------------------------------------------

GOOD = _log_with()


@pytest.mark.parametrize("args,names", [
    (["gap", "a.npz", "--heldout", "nosuch.npz"], ["nosuch.npz"]),
    (["gap", "a.npz", "--heldout", "a.npz"], ["single flight"]),
    (["gap", "a.npz", "b.npz", "--heldout", "nosuch.npz"], ["nosuch.npz"]),
    (["gap", "a.npz", "b.npz", "--heldout", "a.npz", "b.npz"], ["every flight"]),
    (["gap", "a.npz", "--effects", "nosuch"], ["nosuch"]),
])
def test_gap_arguments_checked_first(args, names):
    _expect_named("issue 40: gap arguments", args + ["--out", "o", "--no-progress"], {"a.npz": GOOD, "b.npz": GOOD},
                  names)


# ------------------------------------------------------------------------------------------
# items 4, 5, 7, 9, 10: tune refuses a changed study, resumes to the same trials, names storage errors
# ------------------------------------------------------------------------------------------

TINY_STUDY = """
n_trials = {n}
duration = 0.5
seed = 3
[base.copters]
n = 3
[base.behaviour]
kind = "attraction_repulsion"
[params]
"behaviour.ar_b" = {{ low = {low}, high = 8.0 }}
"behaviour.w_t" = {{ low = 0.0, high = 1.0 }}
[objectives]
cohesion = "minimize"
[evaluation]
n_envs = 2
heldout_envs = 2
"""


def _table(study):
    """(params, values) of the finished trials in order: what a resumed study must reproduce."""
    return [(t.params, t.values) for t in study.trials if t.state.name == "COMPLETE"]


def _interrupting(real, at: int, how: type[BaseException]):
    calls = []

    def evaluate(*args, **kwargs):
        calls.append(1)
        if len(calls) == at:
            raise how()
        return real(*args, **kwargs)

    return evaluate


@pytest.mark.parametrize("how", ["ctrl-c", "kill"])
def test_tune_resumes_to_the_uninterrupted_table(tmp_path, monkeypatch, how):
    pytest.importorskip("optuna")
    import subprocess
    import sys

    import finkensim.tune.run as tune_run
    from finkensim.tune import run_study

    text = TINY_STUDY.format(n=6, low=1.0)
    whole = _table(run_study(text, tmp_path / "whole", progress=False, heldout=False, figures=False).study)
    real = tune_run.evaluate
    # Ctrl-C (or SIGTERM, which the CLI turns into Ctrl-C) in trial 4; "kill": the process dies in trial 4 without
    # a word (SystemExit passes Optuna by, as SIGKILL would) and its pid is then gone
    monkeypatch.setattr(tune_run, "evaluate", _interrupting(real, 4, KeyboardInterrupt if how == "ctrl-c" else SystemExit))
    with pytest.raises((KeyboardInterrupt, SystemExit)):
        run_study(text, tmp_path / "cut", progress=False, heldout=False, figures=False)
    monkeypatch.setattr(tune_run, "evaluate", real)
    if how == "kill":
        import optuna

        st = optuna.load_study(study_name="finkensim-tune", storage=f"sqlite:///{tmp_path / 'cut' / 'study.db'}")
        running = [t for t in st.trials if t.state.name == "RUNNING"]
        assert len(running) == 1
        gone = subprocess.Popen([sys.executable, "-c", "pass"])
        gone.wait()
        st._storage.set_trial_user_attr(running[0]._trial_id, "pid", gone.pid)
    resumed = run_study(text, tmp_path / "cut", progress=False, heldout=False, figures=False).study
    assert _table(resumed) == whole
    states = [t.state.name for t in resumed.trials]
    assert states.count("FAIL") == 1 and "RUNNING" not in states  # the stopped trial is FAIL, re-queued


def test_tune_refuses_a_changed_study_in_an_old_directory(tmp_path):
    pytest.importorskip("optuna")
    from finkensim.config import ConfigError
    from finkensim.tune import run_study

    run_study(TINY_STUDY.format(n=2, low=1.0), tmp_path, progress=False, heldout=False, figures=False)
    kept = (tmp_path / "study.toml").read_text()
    with pytest.raises(ConfigError, match="different study file.*params"):
        run_study(TINY_STUDY.format(n=2, low=5.0), tmp_path, progress=False, heldout=False, figures=False)
    assert (tmp_path / "study.toml").read_text() == kept
    # more trials of the same study are a resume, not a change
    res = run_study(TINY_STUDY.format(n=3, low=1.0), tmp_path, progress=False, heldout=False, figures=False)
    assert len(_table(res.study)) == 3


STUDY_FILE = TINY_STUDY.format(n=2, low=1.0).encode()


@pytest.mark.parametrize("args,names", [
    (["tune", "s.toml", "--out", "/proc/finkensim-x"], ["/proc/finkensim-x"]),
    (["tune", "s.toml", "--out", "a_file/x"], ["a_file/x"]),
    (["tune", "s.toml", "--out", "o", "--storage", "bogus://nowhere"], ["bogus://nowhere"]),
    (["tune", "s.toml", "--out", "o", "--storage", "postgresql://user@localhost/db"], ["postgresql://user@localhost/db"]),
    (["tune", "s.toml", "--out", "o", "--storage", "."], ["storage"]),
])
def test_tune_storage_and_output_errors(args, names):
    _expect_named("issue 40: tune output", args, {"s.toml": STUDY_FILE, "a_file": b"x"}, names)


@pytest.mark.parametrize("extra,names", [
    ("", ["n_envs", "memory"]),  # 10^6 environments of 60 s: about 170 GB
    ('"behaviour.wall_check" = { choices = ["none", "sequence"] }\n', ["imu.enabled", "combination"]),
])
def test_tune_refuses_impossible_studies_before_a_trial(extra, names):
    text = TINY_STUDY.format(n=2, low=1.0)
    if extra:
        text = text.replace("[objectives]", extra + "[base.imu]\nenabled = false\n[objectives]")
    else:
        text = text.replace("n_envs = 2", "n_envs = 1000000").replace("duration = 0.5", "duration = 60.0")
    for command in (["tune", "s.toml", "--out", "o"], ["check", "s.toml"]):
        _expect_named("issue 40: study files", command, {"s.toml": text.encode()}, names)


@pytest.mark.parametrize("value", ["inf", "-1", "nan", "lots"])
def test_memory_override_must_be_a_finite_number(value, monkeypatch):
    monkeypatch.setenv("FINKENSIM_MEMORY_AVAILABLE", value)
    _expect_named("issue 40: environment", ["run", "--out", "o", "--no-gif"], {}, ["FINKENSIM_MEMORY_AVAILABLE"])


# ------------------------------------------------------------------------------------------
# item 6: TOML nested deeper than the parser follows
# ------------------------------------------------------------------------------------------

DEEP = {"array": "a = " + "[" * 5000 + "]" * 5000 + "\n", "table": "a = " + "{b = " * 600 + "1" + "}" * 600 + "\n",
        "sweep": 'replicates = 1\n[grid]\n"copters.n" = ' + "[" * 3000 + "]" * 3000 + "\n"}


@pytest.mark.parametrize("command", [["check", "s.toml"], ["run", "s.toml", "--out", "o", "--no-gif"],
                                     ["sweep", "s.toml", "--out", "o"], ["tune", "s.toml", "--out", "o"]])
@pytest.mark.parametrize("shape", sorted(DEEP))
def test_deeply_nested_toml(shape, command):
    _expect_named("issue 40: TOML", command, {"s.toml": DEEP[shape].encode()}, ["nested too deeply"])


# ------------------------------------------------------------------------------------------
# item 11: sweeps refused before they build their design
# ------------------------------------------------------------------------------------------

HUGE_SWEEPS = {
    "replicates 1e9": 'replicates = 1000000000\nduration = 1.0\n[grid]\n"copters.n" = [2, 3]\n',
    "n_samples 1e8": 'replicates = 1\nduration = 1.0\n[random]\nn_samples = 100000000\n'
                     '"behaviour.speed" = { low = 0.1, high = 0.5 }\n',
    "3e6-point grid": 'replicates = 1\nduration = 1.0\n[grid]\n"behaviour.speed" = ['
                      + ", ".join(f"{0.1 + 1e-5 * i:.5f}" for i in range(3000)) + ']\n"copters.radius" = ['
                      + ", ".join(f"{0.1 + 1e-4 * i:.4f}" for i in range(1000)) + "]\n",
}


@pytest.mark.parametrize("command", [["check", "w.toml"], ["sweep", "w.toml", "--out", "o", "--no-progress"]])
@pytest.mark.parametrize("name", sorted(HUGE_SWEEPS))
def test_huge_sweeps_refused_early(name, command):
    _expect_named("issue 40: sizes", command, {"w.toml": HUGE_SWEEPS[name].encode()},
                  ["memory", "combinations"])


# ------------------------------------------------------------------------------------------
# item 12: check agrees with run, sweep and tune; every file kind the CLI reads is checked
# ------------------------------------------------------------------------------------------

RUN_REFUSES = {
    "min_range > max_range": "[sonar]\nmin_range = 3.0\nmax_range = 2.0\n",
    "missing mixture file": '[ranging]\nmixture_file = "nosuch.json"\n',
    "binary mixture file": '[ranging]\nmixture_file = "noise.bin"\n',
    "wall check without its sensor": '[behaviour]\nkind = "attraction_repulsion"\nwall_check = "sequence"\n'
                                     "[imu]\nenabled = false\n",
    "duration below a step": "[simulation]\nduration = 0.001\n",
}


@pytest.mark.parametrize("command", [["check", "s.toml"], ["run", "s.toml", "--out", "o", "--no-gif"]])
@pytest.mark.parametrize("name", sorted(RUN_REFUSES))
def test_check_refuses_what_run_refuses(name, command):
    files = {"s.toml": RUN_REFUSES[name].encode(), "noise.bin": bytes(range(256))}
    _expect_named("issue 40: check = run", command, files, ["sonar.min_range", "mixture", "imu.enabled", "duration"])


def _cli_ok(args, files: dict, cwd):
    from tests.test_fuzz_cli import _cli

    for name, data in files.items():
        (cwd / name).write_bytes(data)
    r = _cli(args, cwd)
    assert "Traceback" not in r.stdout + r.stderr
    return r


def test_check_warns_as_run_does_about_min_separation(tmp_path):
    import os
    import subprocess
    import sys

    (tmp_path / "s.toml").write_bytes(b"[copters]\nn = 30\nmin_separation = 5.0\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}  # the warning is the point here
    r = subprocess.run([sys.executable, "-m", "finkensim.cli", "check", "s.toml"], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "warning: copters.min_separation" in r.stderr, r.stderr


def test_check_accepts_every_file_kind_the_cli_reads(tmp_path):
    from pathlib import Path

    examples = Path(__file__).resolve().parents[1] / "examples"
    files = {"tune.toml": (examples / "tune.toml").read_bytes(),
             "track.csv": b"t,copter,x,y,yaw\n0,a,1,1,0\n0.1,a,1.1,1,0\n",
             "read.csv": b"t,copter,channel,value\n0,a,ultrasonic/0,1.0\n0.1,a,imu/gyro,0.1\n",
             "topics.toml": b'[[tracking]]\ntopic = "/vicon/a"\ncopter = "a"\n',
             "f.npz": GOOD}
    r = _cli_ok(["check", *files], files, tmp_path)
    assert r.returncode == 0, r.stderr
    for kind in ("study", "flight log", "readings CSV", "topics file"):
        assert kind in r.stdout


@pytest.mark.parametrize("name,data,words", [
    ("track.csv", b"t,copter,x,y,yaw\n0,a,1,1,0\n", ["tracking CSV", "finkensim import"]),
    ("read.csv", b"t,copter,channel,value\n0,a,ultrasonic/0,1.0\n", ["readings CSV", "finkensim import"]),
    ("s.toml", b"[copters]\nn = 3\n", ["scenario", "--config"]),
])
def test_gap_names_what_a_file_is(name, data, words):
    _expect_named("issue 40: file kinds", ["gap", name, "--out", "o", "--no-progress"], {name: data}, words)


# ------------------------------------------------------------------------------------------
# item 13: one vocabulary
# ------------------------------------------------------------------------------------------

TRACK = b"t,copter,x,y,yaw\n" + b"".join(f"{0.01 * k:.2f},a,1.0,1.5,0.1\n".encode() for k in range(20))


@pytest.mark.parametrize("arena", [["3,4"], ["3", "4"]])
def test_arena_takes_both_forms_in_check_and_import(arena, tmp_path):
    r = _cli_ok(["check", "track.csv", "--arena", *arena], {"track.csv": TRACK}, tmp_path)
    assert r.returncode == 0 and "arena 3 x 4 m" in r.stdout, r.stderr
    r = _cli_ok(["check", "--arena", *arena, "track.csv"], {}, tmp_path)  # files may follow --arena W L
    assert r.returncode == 0 and "arena 3 x 4 m" in r.stdout, r.stderr
    r = _cli_ok(["import", "--tracking", "track.csv", "--arena", *arena, "--out", "new/dir/f.npz"], {}, tmp_path)
    assert r.returncode == 0 and (tmp_path / "new" / "dir" / "f.npz").is_file(), r.stderr


def test_int_copter_ids_are_named_with_their_dtype():
    _expect_named("issue 40: flight log text", ["check", "f.npz"],
                  {"f.npz": _log_with(copter_ids=np.array([1, 2, 3]))}, ["copter_ids has dtype int64"])


def test_tune_help_shows_one_percent_sign():
    from tests.test_fuzz_cli import _cli
    from pathlib import Path

    r = _cli(["tune", "--help"], Path("."))
    assert r.returncode == 0 and "95% CIs" in " ".join(r.stdout.split()) and "%%" not in r.stdout


# ------------------------------------------------------------------------------------------
# item 10: Ctrl-C and SIGTERM end sweep and tune with one line
# ------------------------------------------------------------------------------------------

#: seconds a command may take to end after the signal before the test calls it hung (its pool or cluster teardown)
SIGNAL_TO_EXIT_S = 900


def _signal_when(args, cwd, ready, sig):
    """Start ``finkensim ARGS`` in its own process group (as a terminal job), send ``sig`` to the whole group once
    ``ready()`` is true; returns (exit code, stderr).

    No clock decides: the command may take any time to get ready (on a cold kernel cache its workers compile first,
    minutes on a loaded machine), and the test fails only if it ends before it is ready or does not end after the
    signal (``SIGNAL_TO_EXIT_S``, a bound for a hang, not a speed)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    env = {**os.environ, "MPLBACKEND": "Agg"}
    p = subprocess.Popen([sys.executable, "-m", "finkensim.cli", *args], cwd=cwd, env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        while not ready():
            assert p.poll() is None, f"ended before the signal (exit code {p.returncode}): {p.stderr.read()}"
            time.sleep(0.3)
        os.killpg(p.pid, sig)
        _, err = p.communicate(timeout=SIGNAL_TO_EXIT_S)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    return p.returncode, err


@pytest.mark.parametrize("executor", ["process", "dask"])
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_interrupted_sweep_says_one_line(executor, sig, tmp_path):
    import signal

    if executor == "dask":
        pytest.importorskip("distributed")
    (tmp_path / "w.toml").write_text('replicates = 400\nduration = 5.0\n[grid]\n"copters.n" = [3]\n')
    parts = tmp_path / "o" / "parts"
    code, err = _signal_when(["sweep", "w.toml", "--out", "o", "--executor", executor, "--workers", "2",
                              "--no-progress"], tmp_path, lambda: parts.is_dir() and any(parts.iterdir()),
                             getattr(signal, sig))
    assert code == (130 if sig == "SIGINT" else 143), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_interrupted_gap_validate_says_one_line(sig, tmp_path):
    """gap-validate on a process pool, signalled (the whole process group, as a terminal does) after its first
    trial: one line, the signal's exit code, and the finished trials kept for the same command to continue."""
    import json
    import signal

    rows = tmp_path / "o" / "trials.jsonl"
    code, err = _signal_when(["gap-validate", "--cases", "null", "--trials", "40", "--duration", "10", "--out", "o",
                              "--executor", "process", "--workers", "2", "--no-progress"], tmp_path,
                             lambda: rows.exists() and rows.read_text().strip() != "", getattr(signal, sig))
    assert code == (130 if sig == "SIGINT" else 143), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "the same command continues" in err, err
    kept = [json.loads(line) for line in rows.read_text().splitlines()]
    assert 1 <= len(kept) < 40 and all(r["case"] == "null" for r in kept)


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_interrupted_tune_says_one_line(sig, tmp_path):
    import signal
    import sqlite3

    pytest.importorskip("optuna")
    (tmp_path / "s.toml").write_text(TINY_STUDY.format(n=500, low=1.0))
    db = tmp_path / "o" / "study.db"

    def one_done():
        if not db.exists():
            return False
        try:
            with sqlite3.connect(db) as con:
                return con.execute("select count(*) from trials where state = 'COMPLETE'").fetchone()[0] >= 1
        except sqlite3.Error:
            return False

    code, err = _signal_when(["tune", "s.toml", "--out", "o", "--no-progress", "--no-heldout", "--no-figures"],
                             tmp_path, one_done, getattr(signal, sig))
    assert code == (130 if sig == "SIGINT" else 143), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err


def test_the_dask_sync_cancel_noise_is_dropped_and_nothing_else():
    """A SIGTERM that lands before distributed's ``sync`` bound its future makes its cancel callback raise a NameError,
    which tornado logs with a traceback (seen once in a clean clone's suite): that record, and only that one, is
    dropped."""
    import logging

    from finkensim.sweep.run import drop_interrupt_noise

    def record(message, exc):
        return logging.LogRecord("tornado.application", logging.ERROR, __file__, 1, message, (), (type(exc), exc, None))

    drop_interrupt_noise()
    drop_interrupt_noise()  # once only
    logger = logging.getLogger("tornado.application")
    assert len(logger.filters) >= 1
    noise = "Exception in callback functools.partial(<function sync.<locals>.cancel at 0x7f65590ee700>)"
    assert not logger.filter(record(noise, NameError("future")))
    assert logger.filter(record("Exception in callback functools.partial(<function other>)", NameError("x")))
    assert logger.filter(record(noise, ValueError("a real error")))


def test_a_local_clusters_errors_are_dropped_only_after_an_interrupt():
    """A SIGTERM to the sweep's process group ends the Dask workers too; the scheduler then logged "Couldn't gather
    keys" before the sweep's one line (seen in a full suite): once an interrupt is requested such records are
    dropped, before it they pass, and CRITICAL ones always pass."""
    import logging

    from finkensim.sweep import executors
    from finkensim.sweep.run import drop_interrupt_noise

    drop_interrupt_noise()
    logger = logging.getLogger("distributed.scheduler")

    def passes(level):
        return logger.filter(logging.LogRecord(logger.name, level, __file__, 1, "Couldn't gather keys", (), None))

    executors._REQUESTED.clear()
    assert passes(logging.ERROR)
    executors._REQUESTED.set()
    try:
        assert not passes(logging.ERROR) and not passes(logging.WARNING) and passes(logging.CRITICAL)
    finally:
        executors._REQUESTED.clear()
