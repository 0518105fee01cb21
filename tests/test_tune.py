"""finkensim.tune: study-file errors, a tiny study end to end, batched trials = single episodes, and a killed
``finkensim tune`` that resumes without losing a finished trial."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

optuna = pytest.importorskip("optuna")

from finkensim.config import ConfigError  # noqa: E402
from finkensim.default_scenario import load_scenario  # noqa: E402
from finkensim.episode import run_episode  # noqa: E402
from finkensim.tune import evaluate, mean_ci, parse_study, run_study  # noqa: E402

STUDY = """
n_trials = {n}
duration = {duration}
[base.copters]
n = 4
[base.behaviour]
kind = "attraction_repulsion"
[params]
"behaviour.ar_b" = {{ low = 1.0, high = 8.0 }}
"behaviour.wall_check" = {{ choices = ["none", "per_reading"] }}
[objectives]
wall_sticking = "minimize"
cohesion = "minimize"
[evaluation]
n_envs = 4
heldout_envs = 6
[compare.ideal]
"sonar.error" = "none"
"""


def study_text(n=3, duration=1.0, extra=""):
    return STUDY.format(n=n, duration=duration) + extra


@pytest.mark.parametrize("bad, message", [
    ("n_trails = 3\n", "unknown key 'n_trails' \\(did you mean 'n_trials'\\?\\)"),
    ('[params]\n"behaviour.ar_b" = { low = 5.0, high = 1.0 }\n', "low = 5.0, high = 1.0: expected low < high"),
    ('[objectives]\nwall_stiking = "minimize"\n', "unknown metric 'wall_stiking' \\(did you mean 'wall_sticking'\\?\\)"),
    ('[objectives]\ncohesion = "smallest"\n', "cohesion = 'smallest': expected 'minimize' or 'maximize'"),
    ("[evaluation]\nheldout_seed = 0\n", "heldout_seed = 0: expected a seed different from seed = 0"),
    ('[params]\n"behaviour.wall_check" = { choices = ["none", "always"] }\n', "behaviour.wall_check.*'always'"),
    ('[params]\n"behaviour.speeed" = { low = 0.1, high = 1.0 }\n', "speeed"),
    ("[evaluation]\nn_envs = 0\n", "n_envs = 0: expected an integer >= 1"),
])
def test_bad_study_files_name_key_value_and_expectation(bad, message):
    base = {"n": "n_trials = 3\n", "p": '[params]\n"behaviour.ar_b" = { low = 1.0, high = 8.0 }\n',
            "o": '[objectives]\ncohesion = "minimize"\n', "e": ""}
    for key, prefix in (("n_t", "n"), ("[params]", "p"), ("[objectives]", "o"), ("[evaluation]", "e")):
        if bad.startswith(key):
            base[prefix] = bad
    with pytest.raises(ConfigError, match=message):
        parse_study("".join(base.values()))


def test_a_trial_is_one_batched_call_equal_to_single_episodes():
    cfg = load_scenario({"copters": {"n": 4}, "behaviour": {"kind": "attraction_repulsion"}})
    m = evaluate(cfg, 3, seed=2, duration=1.0, metrics=["cohesion", "wall_sticking"])
    one = run_episode(cfg.replace({"simulation.duration": 1.0}), seed=2, env_id=1, metrics=["cohesion"])
    assert m["cohesion"].shape == (3,) and m["cohesion"][1] == one["cohesion"]


def test_mean_ci_is_a_t_interval():
    x = np.array([1.0, 2.0, 3.0, 4.0])
    m, lo, hi = mean_ci(x)
    assert m == 2.5 and hi - m == pytest.approx(3.182446 * np.std(x, ddof=1) / 2, rel=1e-5) and lo == 2 * m - hi


def test_tiny_study_end_to_end(tmp_path):
    res = run_study(study_text(), tmp_path, progress=False)
    trials = res.study.trials
    assert len([t for t in trials if t.state.name == "COMPLETE"]) == 3
    assert trials[0].params == {"behaviour.ar_b": 4.0, "behaviour.wall_check": "none"}  # the defaults go first
    best = json.loads((tmp_path / "best.json").read_text())
    assert best["params"] == res.best and best["defaults"]["behaviour.ar_b"] == 4.0
    c = res.comparison
    assert set(c["variant"]) == {"base", "ideal"} and set(c["metric"]) == {"wall_sticking", "cohesion"}
    assert np.all(c["diff_lo"] <= c["diff"]) and np.all(c["diff"] <= c["diff_hi"])
    for name in ("study.db", "trials.csv", "heldout.csv", "figures/pareto.png", "figures/history_cohesion.png"):
        assert (tmp_path / name).is_file(), name
    # a second call with the same storage adds only the missing trials
    res2 = run_study(study_text(n=4), tmp_path, progress=False, heldout=False, figures=False)
    assert len(res2.study.trials) == 4 and res2.study.trials[0].values == trials[0].values


def _complete(db):
    s = optuna.load_study(study_name="finkensim-tune", storage=f"sqlite:///{db}")
    return {t.number: t.values for t in s.trials if t.state.name == "COMPLETE"}


def test_killed_study_resumes_without_losing_finished_trials(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text(study_text(n=200, duration=3.0))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "finkensim.cli", "tune", str(study), "--out", str(out), "--no-progress",
           "--no-heldout", "--no-figures"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    db = out / "study.db"
    try:
        deadline = time.monotonic() + 600
        done = {}
        while len(done) < 2:
            assert proc.poll() is None, "the study ended before it could be killed"
            assert time.monotonic() < deadline, "no trial finished in time"
            time.sleep(0.5)
            if db.exists():
                try:
                    done = _complete(db)
                except Exception:  # noqa: BLE001 (the database is being created)
                    done = {}
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    before = _complete(db)
    assert len(before) >= 2
    target = len(before) + 2
    r = subprocess.run(cmd + ["--trials", str(target)], env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    after = _complete(db)
    assert len(after) == target
    for number, values in before.items():
        assert after[number] == values


def test_cli_reports_bad_study_file_in_one_line(tmp_path):
    study = tmp_path / "bad.toml"
    study.write_text(study_text(extra='\n[evaluation.more]\n'))
    r = subprocess.run([sys.executable, "-m", "finkensim.cli", "tune", str(study), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "finkensim tune: error:" in r.stderr


def test_two_processes_share_one_study(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text(study_text(n=8, duration=1.0))
    cmd = [sys.executable, "-m", "finkensim.cli", "tune", str(study), "--out", str(tmp_path / "out"), "--no-progress",
           "--no-heldout", "--no-figures"]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err
    s = optuna.load_study(study_name="finkensim-tune", storage=f"sqlite:///{tmp_path / 'out' / 'study.db'}")
    states = [t.state.name for t in s.trials]
    assert states.count("COMPLETE") >= 8 and "FAIL" not in states
    assert sum(t.user_attrs.get("role") == "defaults" for t in s.trials) == 1



def _race_to_pop(url, trial_ids, barrier, results):
    from optuna.trial import TrialState

    from finkensim.tune.storage import open_storage

    storage = open_storage(url)
    storage.get_all_studies()  # connect before the start line
    barrier.wait()
    results.put([tid for tid in trial_ids if storage.set_trial_state_values(tid, TrialState.RUNNING)])


def test_waiting_trials_are_handed_out_once_across_processes(tmp_path):
    """Four processes race to switch the same 40 WAITING trials to RUNNING on one SQLite file: each trial goes to
    exactly one process. (Optuna's plain RDBStorage hands out 1-12 trials twice in this race on SQLite, which ignores
    SELECT FOR UPDATE: that is how the defaults trial of `finkensim tune` ran twice in two processes.)"""
    import multiprocessing as mp

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    url = f"sqlite:///{tmp_path / 'race.db'}"
    study = optuna.create_study(storage=url, study_name="race")
    for i in range(40):
        study.enqueue_trial({"a": i})
    ids = [t._trial_id for t in study.get_trials(deepcopy=False)]
    ctx = mp.get_context("spawn")
    barrier, results = ctx.Barrier(4), ctx.Queue()
    procs = [ctx.Process(target=_race_to_pop, args=(url, ids, barrier, results)) for _ in range(4)]
    for p in procs:
        p.start()
    won = [tid for _ in procs for tid in results.get(timeout=300)]
    for p in procs:
        p.join(timeout=60)
    assert sorted(won) == sorted(ids)
