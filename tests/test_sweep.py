"""Monte-Carlo sweeps: the sweep file, validation before any run, executors giving identical tables,
failing runs, resume after an interruption, outputs, and the ``finkensim sweep`` command."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from scipy import stats

import finkensim.sweep.executors as executors_mod
from finkensim.cli import main
from finkensim.config import ConfigError
from finkensim.episode import run_episode
from finkensim.sweep import Sweep, SweepError, plot_summary, run_sweep, summarize
from finkensim.sweep.summary import factorial_layout
from tests.stats import assert_above_se

# tiny episodes: 2-3 copters x 1 s
SWEEP_TOML = """\
description = "test sweep"
replicates = 2
duration = 1.0
seed = 7

[base.copters]
n = 2

[grid]
"copters.n" = [2, 3]
behaviour.speed = [0.2, 0.5]
"""
N_RUNS = 8
METRIC_COLS = ["run_id", "combination", "copters.n", "behaviour.speed", "replicate", "seed", "cohesion",
               "nearest_neighbour", "wall_sticking", "collisions", "wall_contacts", "fragmentation", "coverage",
               "status", "error"]
FAIL_SEED_ENV = "FINKENSIM_TEST_FAIL_SEED"


def failing_runner(cfg, seed, env_id=0):
    """Module-level (picklable) runner: raises for the seed named in $FINKENSIM_TEST_FAIL_SEED."""
    if str(seed) == os.environ.get(FAIL_SEED_ENV):
        raise RuntimeError(f"injected failure for seed {seed}")
    return run_episode(cfg, seed, env_id)


class Interrupt:
    """Runner that delegates to run_episode and raises KeyboardInterrupt after ``n`` runs (serial only)."""

    calls: list[int] = []
    limit = 3


def interrupting_runner(cfg, seed, env_id=0):
    if len(Interrupt.calls) >= Interrupt.limit:
        raise KeyboardInterrupt
    Interrupt.calls.append(seed)
    return run_episode(cfg, seed, env_id)


@pytest.fixture
def sweep_file(tmp_path) -> Path:
    path = tmp_path / "sweep.toml"
    path.write_text(SWEEP_TOML)
    return path


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted serial sweep, written to disk."""
    d = tmp_path_factory.mktemp("ref")
    (d / "sweep.toml").write_text(SWEEP_TOML)
    df = run_sweep(Sweep.from_toml(d / "sweep.toml"), d / "out", executor="serial", progress=False)
    return df, d / "out"


def _table(df):
    return df[METRIC_COLS].sort_values("run_id").reset_index(drop=True)


# --------------------------------------------------------------------------- the design

def test_grid_design_runs_and_seeds(sweep_file):
    sw = Sweep.from_toml(sweep_file)
    assert sw.parameters == ("copters.n", "behaviour.speed")
    assert sw.combinations == [{"copters.n": 2, "behaviour.speed": 0.2}, {"copters.n": 2, "behaviour.speed": 0.5},
                               {"copters.n": 3, "behaviour.speed": 0.2}, {"copters.n": 3, "behaviour.speed": 0.5}]
    assert sw.n_runs == N_RUNS and sw.duration == 1.0 and sw.configs[3].copters.n == 3
    runs = sw.runs()
    assert [r.run_id for r in runs] == list(range(N_RUNS))
    assert [(r.combination, r.replicate) for r in runs[:3]] == [(0, 0), (0, 1), (1, 0)]
    seeds = [r.seed for r in runs]
    assert len(set(seeds)) == N_RUNS and all(0 <= s < 2**63 for s in seeds)
    # seeds depend on (sweep seed, k, r) only: the same in another sweep with other values and replicates
    other = Sweep.from_toml(SWEEP_TOML.replace("replicates = 2", "replicates = 5").replace("[0.2, 0.5]", "[0.3, 0.9]"))
    assert other.run_seed(1, 1) == sw.run_seed(1, 1) == runs[3].seed
    assert Sweep.from_toml(SWEEP_TOML.replace("seed = 7", "seed = 8")).run_seed(1, 1) != sw.run_seed(1, 1)
    # values take the canonical form of the config (an int for a float key becomes a float)
    assert Sweep.from_toml(SWEEP_TOML.replace("[0.2, 0.5]", "[1, 2]")).combinations[0]["behaviour.speed"] == 1.0


def test_python_api_without_a_file_or_an_output_directory():
    from finkensim.scenario import load_scenario

    sw = Sweep(load_scenario(), {"behaviour.kind": ["hover", "random_walk"]}, replicates=2, duration=1.0,
               metrics="coverage")
    assert sw.design == "grid" and sw.n_runs == 4 and sw.metrics == ("coverage",)
    df = run_sweep(sw, executor="serial", progress=False)
    assert list(df.columns) == ["run_id", "combination", "behaviour.kind", "replicate", "seed", "coverage", "status",
                                "error", "elapsed"]
    assert list(df["behaviour.kind"]) == ["hover", "hover", "random_walk", "random_walk"]
    assert df.attrs["out"] is None and df.attrs["ran"] == [0, 1, 2, 3] and df.attrs["failed"] == []
    # hovering copters stay in their start cells; walking ones visit more
    assert df["coverage"][:2].sum() < df["coverage"][2:].sum()


def test_base_from_a_scenario_file_with_inline_overrides(tmp_path):
    (tmp_path / "scen").mkdir()
    (tmp_path / "scen" / "s.toml").write_text("[copters]\nn = 5\nradius = 0.1\n[behaviour]\nkind = 'hover'\n")
    (tmp_path / "sw.toml").write_text('replicates = 1\n[base]\nconfig = "scen/s.toml"\nprofile = "seed"\n'
                                      '[base.copters]\nradius = 0.12\n')
    sw = Sweep.from_toml(tmp_path / "sw.toml")
    assert sw.design == "single" and sw.n_runs == 1 and sw.parameters == ()
    cfg = sw.configs[0]
    assert (cfg.copters.n, cfg.copters.radius, cfg.behaviour.kind, cfg.profile) == (5, 0.12, "hover", "seed")
    assert cfg.walls.plate_mass == 40.0  # the seed profile applied
    assert sw.duration == 60.0  # no top-level duration: the scenario's


def test_random_design_is_deterministic_and_in_range():
    text = """replicates = 1\nseed = 3\n[random]\nn_samples = 12\n"behaviour.speed" = { low = 0.1, high = 0.5 }
"copters.n" = { low = 2, high = 4 }\n"walls.threshold" = { low = 0.2, high = 2.0, log = true }
behaviour.kind = { choices = ["hover", "random_walk"] }\n"""
    a, b = Sweep.from_toml(text), Sweep.from_toml(text)
    assert a.design == "random" and a.n_combinations == 12
    assert a.combinations == b.combinations
    assert a.combinations != Sweep.from_toml(text.replace("seed = 3", "seed = 4")).combinations
    speeds = [c["behaviour.speed"] for c in a.combinations]
    ns = [c["copters.n"] for c in a.combinations]
    assert all(0.1 <= s < 0.5 for s in speeds) and len(set(speeds)) == 12
    assert all(isinstance(n, int) and 2 <= n <= 4 for n in ns)
    assert all(0.2 <= c["walls.threshold"] <= 2.0 for c in a.combinations)
    assert {c["behaviour.kind"] for c in a.combinations} == {"hover", "random_walk"}


def test_run_episode_is_a_function_of_config_and_seed():
    sw = Sweep.from_toml(SWEEP_TOML)
    cfg = sw.configs[2]
    a = run_episode(cfg, 11)
    assert list(a) == ["cohesion", "nearest_neighbour", "wall_sticking", "collisions", "wall_contacts",
                       "fragmentation", "coverage"]
    assert all(isinstance(v, float) for v in a.values())
    assert run_episode(cfg.replace({"simulation.seed": 99}), 11) == a  # the config's seed is not used
    assert run_episode(cfg, 12) != a and run_episode(cfg, 11, env_id=1) != a
    assert run_episode(cfg, 11, metrics=["coverage"]) == {"coverage": a["coverage"]}
    with pytest.raises(ConfigError, match="at least one step"):
        run_episode(cfg.replace({"simulation.duration": 0.01}), 1)


# --------------------------------------------------------------------------- validation before any run

@pytest.mark.parametrize("edit, message", [
    (('"copters.n" = [2, 3]', '"copters.nn" = [2, 3]'), r"unknown key copters.nn \(did you mean copters.n\?\)"),
    (('"copters.n" = [2, 3]', '"coptrs.n" = [2, 3]'), r"unknown section \[coptrs\].*did you mean 'copters'"),
    (('"copters.n" = [2, 3]', '"copters.n" = []'), r"\[grid\] copters.n = \[\]: expected a non-empty list"),
    (('"copters.n" = [2, 3]', '"copters.n" = [2, "three"]'), r"copters.n = 'three': expected an? integer"),
    (('"copters.n" = [2, 3]', '"copters.n" = [2, 0]'), r"copters.n = 0: expected >= 1"),
    (('"copters.n" = [2, 3]', '"copters.n" = 3'), r"copters.n = 3: expected a list of values"),
    (('"copters.n" = [2, 3]', '"copters.n" = [2, 2]'), r"copters.n lists 2 more than once"),
    (('"copters.n" = [2, 3]', '"simulation.seed" = [1, 2]'), r"simulation.seed cannot be swept"),
    (("replicates = 2", "replicate = 2"), r"unknown key 'replicate' \(did you mean 'replicates'\?\)"),
    (("replicates = 2", "replicates = 0"), r"replicates = 0: expected an integer >= 1"),
    (("replicates = 2", "replicates = 2.5"), r"replicates = 2.5: expected an integer"),
    (("duration = 1.0", "duration = -1.0"), r"duration = -1.0: expected a number of seconds > 0"),
    (("seed = 7", 'seed = 7\nmetrics = ["cohesion", "colisions"]'), r"unknown metric 'colisions' \(did you mean 'collisions'\?\)"),
    (("[base.copters]\nn = 2", "[base.copters]\nnn = 2"), r"\[base\] unknown key copters.nn \(did you mean copters.n\?\)"),
    (("[base.copters]\nn = 2", '[base]\nconfig = "missing.toml"'), r"missing.toml.*does not exist"),
    (("[grid]", '[base.walls]\nhinge_height = 2.0\n[grid]\n"walls.plate_length" = [0.5, 1.5]\n'
                '"walls.hinge_height" = [1.0, 2.0]'),
     r"combination \d+ \(.*walls.plate_length=1.5, walls.hinge_height=1\b.*expected <= walls.hinge_height"),
    (("[grid]", "[random]\nn_samples = 2\n\"copters.n\" = {low = 2, high = 3}\n[grid]"), r"both \[grid\] and \[random\]"),
    (("[grid]", "[grid\n"), r"invalid TOML"),
])
def test_bad_sweep_files_fail_with_a_named_error(edit, message):
    text = SWEEP_TOML.replace(*edit)
    assert text != SWEEP_TOML
    with pytest.raises(SweepError, match=message):
        Sweep.from_toml(text)


def test_closed_loop_behaviours_are_checked_up_front():
    text = SWEEP_TOML.replace("behaviour.speed = [0.2, 0.5]", 'behaviour.kind = ["hover", "attraction_repulsion"]')
    # the swarm rejects attraction-repulsion without sonars: named before any run
    Sweep.from_toml(text)
    with pytest.raises(SweepError, match=r"combination 1 \(copters.n=2, behaviour.kind=attraction_repulsion\)"
                                         r".*needs sonar.enabled = true"):
        Sweep.from_toml(text.replace("[grid]", "[base.sonar]\nenabled = false\n[grid]"))


@pytest.mark.parametrize("spec, message", [
    ('"copters.n" = {low = 2.5, high = 4}', r"copters.n is an integer key"),
    ('"behaviour.speed" = {low = 0.5, high = 0.1}', r"expected low < high"),
    ('"behaviour.speed" = {low = 0.1}', r"expected both low and high"),
    ('"behaviour.speed" = {low = 0.1, hihg = 0.5}', r"unknown key 'hihg' \(did you mean 'high'\?\)"),
    ('"behaviour.kind" = {low = 0, high = 1}', r"use \{choices"),
    ('"behaviour.kind" = {choices = []}', r"non-empty list"),
    ('"behaviour.kind" = {choices = ["hover", "random_wlak"]}', r"did you mean 'random_walk'"),
])
def test_bad_random_designs_fail_with_a_named_error(spec, message):
    with pytest.raises(SweepError, match=message):
        Sweep.from_toml(f"[random]\nn_samples = 3\n{spec}\n")
    with pytest.raises(SweepError, match="n_samples"):
        Sweep.from_toml('[random]\n"behaviour.speed" = {low = 0.1, high = 0.5}\n')


def test_sweep_error_is_a_config_error_and_nothing_runs(tmp_path, monkeypatch):
    assert issubclass(SweepError, ConfigError)
    calls = []
    monkeypatch.setattr(executors_mod, "execute", lambda task: calls.append(task))
    bad = tmp_path / "bad.toml"
    bad.write_text(SWEEP_TOML.replace("[2, 3]", "[2, -1]"))
    with pytest.raises(SweepError):
        run_sweep(bad, tmp_path / "out", executor="serial", progress=False)
    good = Sweep.from_toml(SWEEP_TOML)
    with pytest.raises(SweepError, match=r"executor = 'procss'.*did you mean 'process'"):
        run_sweep(good, tmp_path / "out", executor="procss")
    with pytest.raises(SweepError, match="workers = 0"):
        run_sweep(good, tmp_path / "out", workers=0)
    with pytest.raises(SweepError, match="needs executor 'dask'"):
        run_sweep(good, tmp_path / "out", executor="process", scheduler="tcp://127.0.0.1:8786")
    assert calls == [] and not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- named variants (linked keys)

VARIANTS_TOML = """\
replicates = 2
duration = 1.0
seed = 3

[base.copters]
n = 2

[variants.motion]
still = { "behaviour.kind" = "hover" }
slow = { "behaviour.kind" = "random_walk", "behaviour.speed" = 0.1, "behaviour.redraw_steps" = 5 }
fast = { behaviour.kind = "random_walk", behaviour.speed = 0.6 }

[grid]
"copters.n" = [2, 3]
"""


def test_variants_are_factors_of_linked_keys_crossed_with_the_grid(tmp_path):
    sw = Sweep.from_toml(VARIANTS_TOML)
    assert sw.parameters == ("motion", "copters.n") and sw.design == "grid" and sw.n_combinations == 6
    assert [c["motion"] for c in sw.combinations] == ["still", "still", "slow", "slow", "fast", "fast"]
    assert [c["copters.n"] for c in sw.combinations] == [2, 3] * 3
    assert sw.variants["motion"] == {"still": {"behaviour.kind": "hover"},
                                     "slow": {"behaviour.kind": "random_walk", "behaviour.speed": 0.1,
                                              "behaviour.redraw_steps": 5},
                                     "fast": {"behaviour.kind": "random_walk", "behaviour.speed": 0.6}}
    b = sw.configs
    assert (b[2].behaviour.kind, b[2].behaviour.speed, b[2].behaviour.redraw_steps, b[2].copters.n) == \
        ("random_walk", 0.1, 5, 2)
    # a key a level leaves out keeps its base value
    assert (b[5].behaviour.speed, b[5].behaviour.redraw_steps, b[5].copters.n) == (0.6, 20, 3)
    assert b[0].behaviour.speed == sw.base.behaviour.speed
    # the Python API takes the same mapping
    api = Sweep(sw.base, {"copters.n": [2, 3]}, replicates=2, seed=3, variants=sw.variants)
    assert api.combinations == sw.combinations and api.configs == sw.configs
    assert api.fingerprint() == sw.fingerprint()
    # a renamed level is another sweep (its name is in the results); same configs without variants are not
    renamed = Sweep.from_toml(VARIANTS_TOML.replace("still =", "hovering ="))
    assert renamed.configs == sw.configs and renamed.fingerprint() != sw.fingerprint()
    # variants alone (no [grid]) are a design too
    alone = Sweep.from_toml(VARIANTS_TOML.split("[grid]")[0])
    assert alone.parameters == ("motion",) and alone.design == "grid" and alone.n_combinations == 3

    out = tmp_path / "out"
    df = run_sweep(sw, out, executor="serial", progress=False)
    assert list(df.columns[:4]) == ["run_id", "combination", "motion", "copters.n"]
    assert list(df["motion"]) == ["still"] * 4 + ["slow"] * 4 + ["fast"] * 4
    row = df.iloc[9]
    want = run_episode(sw.configs[int(row["combination"])], int(row["seed"]))
    assert all(row[name] == value for name, value in want.items())
    # hovering copters stay put; walking ones cover more of the arena: by more than 5 SE of the difference of the
    # two means of 4 runs (Welch SE from the runs; pooling the two copter counts only widens it)
    still, fast = (df.loc[df["motion"] == m, "coverage"].to_numpy() for m in ("still", "fast"))
    assert still.mean() < fast.mean()
    se_diff = math.sqrt(still.var(ddof=1) / still.size + fast.var(ddof=1) / fast.size)
    assert_above_se(fast.mean() - still.mean(), 0.0, se_diff, what="coverage of fast minus still copters")
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary["motion"]) == ["still", "still", "slow", "slow", "fast", "fast"]
    import json

    info = json.loads((out / "sweep.json").read_text())
    assert info["parameters"] == ["motion", "copters.n"] and info["variants"]["motion"]["still"] == {
        "behaviour.kind": "hover"}
    # a random design is crossed with the variants as well
    rnd = Sweep.from_toml(VARIANTS_TOML.split("[grid]")[0] + '[random]\nn_samples = 2\n"copters.n" = {low = 2, high = 4}\n')
    assert rnd.design == "random" and rnd.n_combinations == 6 and rnd.parameters == ("motion", "copters.n")


def test_variant_levels_are_checked_as_a_whole():
    text = """replicates = 1\nduration = 1.0\n[variants.curtain]
short = { "walls.plate_length" = 1.5, "walls.hinge_height" = 2.0 }
long = { "walls.plate_length" = 0.5 }
"""
    sw = Sweep.from_toml(text)  # plate_length = 1.5 alone would reach below the floor; with the hinge at 2 m it does not
    assert (sw.configs[0].walls.plate_length, sw.configs[0].walls.hinge_height) == (1.5, 2.0)
    with pytest.raises(SweepError, match=r"\[variants.curtain\] short: walls.plate_length = 1.5: expected <= "
                                         r"walls.hinge_height"):
        Sweep.from_toml(text.replace(', "walls.hinge_height" = 2.0', ""))
    with pytest.raises(SweepError, match=r"variants = 3: expected tables \[variants.<factor>\]"):
        Sweep.from_toml("variants = 3\n")


@pytest.mark.parametrize("edit, message", [
    (('"behaviour.kind" = "hover" }', '"behaviour.knd" = "hover" }'),
     r"\[variants.motion.still\] unknown key behaviour.knd \(did you mean behaviour.kind\?\)"),
    (('still = { "behaviour.kind" = "hover" }', 'still = "hover"'),
     r"\[variants.motion\] still = 'hover': expected a table of dotted config keys"),
    (("behaviour.speed = 0.6", "behaviour.speed = -0.6"), r"\[variants.motion\] fast: behaviour.speed = -0.6"),
    (("behaviour.speed = 0.6", 'behaviour.speed = 0.1, "behaviour.redraw_steps" = 5'),
     r"levels 'slow' and 'fast' give the same configuration"),
    (('still = { "behaviour.kind" = "hover" }', 'still = { "behaviour.kind" = "hover", "copters.n" = 4 }'),
     r"\[variants.motion\] still sets copters.n, which \[grid\] also sets"),
    (("[grid]", '[variants.more]\nbig = { "behaviour.speed" = 0.9 }\n[grid]'),
     r"\[variants.more\] big sets behaviour.speed, which \[variants.motion\] also sets"),
    (("[variants.motion]", "[variants.seed]"), r"factor name 'seed' clashes with a results column"),
    (("[variants.motion]", "[variants.coverage]"), r"factor name 'coverage' clashes with a results column"),
    (("[variants.motion]", '[variants."copters.n"]'), r"without dots"),
    (("[variants.motion]", '[variants.x]\n[variants.motion]'), r"\[variants.x\] is empty"),
    (('still = { "behaviour.kind" = "hover" }', 'still = { "simulation.seed" = 4 }'),
     r"simulation.seed cannot be swept"),
])
def test_bad_variants_fail_with_a_named_error(edit, message):
    text = VARIANTS_TOML.replace(*edit)
    assert text != VARIANTS_TOML
    with pytest.raises(SweepError, match=message):
        Sweep.from_toml(text)


def test_summary_plot_groups_a_factorial_design_by_its_last_parameter():
    sw = Sweep.from_toml(VARIANTS_TOML)
    summary = pd.DataFrame([{**c, "combination": k, "cohesion_mean": 1.0 + k, "cohesion_ci_low": 0.5 + k,
                             "cohesion_ci_high": 1.5 + k} for k, c in enumerate(sw.combinations)])
    groups, series = factorial_layout(summary, sw.parameters)
    assert groups == [("still",), ("slow",), ("fast",)] and series == [2, 3]
    fig = plot_summary(summary, sw.parameters, ["cohesion"])
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["still", "slow", "fast"]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["2", "3"]
    # not a full factorial (or one parameter): one point per combination along x
    assert factorial_layout(summary.iloc[:5], sw.parameters) is None
    assert factorial_layout(summary, ["motion"]) is None


# --------------------------------------------------------------------------- executors

def test_serial_results_and_outputs(reference):
    df, out = reference
    assert list(df["run_id"]) == list(range(N_RUNS))
    assert (df["status"] == "ok").all() and (df["error"] == "").all()
    assert list(df.columns) == METRIC_COLS[:-2] + ["status", "error", "elapsed"]
    assert df["copters.n"].dtype == np.int64 and df["behaviour.speed"].dtype == np.float64
    assert (df["elapsed"] > 0).all()
    # each row is exactly run_episode(config of the combination, seed)
    sw = Sweep.from_toml(SWEEP_TOML)
    row = df.iloc[5]
    want = run_episode(sw.configs[int(row["combination"])], int(row["seed"]))
    for name, value in want.items():
        assert row[name] == value, name
    assert sorted(p.name for p in (out / "parts").iterdir()) == [f"run-{i:05d}.parquet" for i in range(N_RUNS)]
    pd.testing.assert_frame_equal(pd.read_parquet(out / "results.parquet"), df)
    summary = pd.read_csv(out / "summary.csv")
    assert len(summary) == 4 and list(summary["n_ok"]) == [2] * 4
    assert {"cohesion_mean", "cohesion_ci_low", "cohesion_ci_high", "coverage_mean"} <= set(summary.columns)
    with Image.open(out / "summary.png") as im:
        assert im.size[0] > 400


def test_process_pool_and_dask_give_the_serial_table(reference, tmp_path):
    pytest.importorskip("distributed")
    ref = _table(reference[0])
    sw = Sweep.from_toml(SWEEP_TOML)
    pooled = run_sweep(sw, tmp_path / "pool", executor="process", workers=2, progress=False)
    pd.testing.assert_frame_equal(_table(pooled), ref)
    dasked = run_sweep(sw, tmp_path / "dask", executor="dask", workers=2, progress=False)
    pd.testing.assert_frame_equal(_table(dasked), ref)
    pd.testing.assert_frame_equal(_table(pd.read_parquet(tmp_path / "dask" / "results.parquet")), ref)


def test_a_failing_run_keeps_every_other_row(reference, tmp_path, monkeypatch):
    ref = _table(reference[0])
    sw = Sweep.from_toml(SWEEP_TOML)
    bad = sw.runs()[5]
    monkeypatch.setenv(FAIL_SEED_ENV, str(bad.seed))  # inherited by the spawned workers
    df = run_sweep(sw, tmp_path / "out", executor="process", workers=2, progress=False, runner=failing_runner)
    got = _table(df)
    assert df.attrs["failed"] == [5]
    row = got.iloc[5]
    assert row["status"] == "error"
    assert row["error"] == f"RuntimeError: injected failure for seed {bad.seed}"
    assert (row["copters.n"], row["behaviour.speed"], row["combination"], row["replicate"], row["seed"]) == \
        (3, 0.2, 2, 1, bad.seed) == (bad.params["copters.n"], bad.params["behaviour.speed"], bad.combination,
                                     bad.replicate, bad.seed)
    assert all(math.isnan(row[m]) for m in sw.metrics)
    others = got.drop(index=5)
    pd.testing.assert_frame_equal(others, ref.drop(index=5))
    # the failure is on disk too, with its parameters
    part = pd.read_parquet(tmp_path / "out" / "parts" / "run-00005.parquet")
    assert part["status"].iloc[0] == "error" and part["copters.n"].iloc[0] == bad.params["copters.n"]
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert summary.loc[bad.combination, "n_error"] == 1 and summary.loc[bad.combination, "n_ok"] == 1


# --------------------------------------------------------------------------- resume

def test_interrupted_sweep_resumes_to_the_uninterrupted_table(reference, sweep_file, tmp_path):
    ref = _table(reference[0])
    out = tmp_path / "out"
    sw = Sweep.from_toml(sweep_file)
    Interrupt.calls.clear()
    with pytest.raises(KeyboardInterrupt):  # "killed" after 3 finished runs
        run_sweep(sw, out, executor="serial", progress=False, runner=interrupting_runner)
    parts = out / "parts"
    assert sorted(p.name for p in parts.iterdir()) == [f"run-{i:05d}.parquet" for i in range(3)]
    assert not (out / "results.parquet").exists()
    mtimes = {p.name: p.stat().st_mtime_ns for p in parts.iterdir()}
    with pytest.raises(SweepError, match="--resume"):  # forgetting --resume does not discard the finished runs
        run_sweep(sw, out, executor="serial", progress=False)
    df = run_sweep(sw, out, executor="serial", progress=False, resume=True)
    assert df.attrs["ran"] == list(range(3, N_RUNS))
    pd.testing.assert_frame_equal(_table(df), ref)
    assert {p.name: p.stat().st_mtime_ns for p in parts.iterdir() if p.name in mtimes} == mtimes

    # delete some parts: resume re-runs exactly those (on the process pool)
    for i in (1, 6):
        (parts / f"run-{i:05d}.parquet").unlink()
    df = run_sweep(sw, out, executor="process", workers=2, progress=False, resume=True)
    assert df.attrs["ran"] == [1, 6]
    pd.testing.assert_frame_equal(_table(df), ref)
    pd.testing.assert_frame_equal(_table(pd.read_parquet(out / "results.parquet")), ref)
    # nothing missing: nothing runs
    assert run_sweep(sw, out, executor="serial", progress=False, resume=True).attrs["ran"] == []


def test_resume_refuses_another_sweep_and_overwrite_starts_again(reference, tmp_path):
    out = reference[1]
    other = Sweep.from_toml(SWEEP_TOML.replace("replicates = 2", "replicates = 3"))
    with pytest.raises(SweepError, match="different sweep"):
        run_sweep(other, out, executor="serial", progress=False, resume=True)
    copy = tmp_path / "copy"
    import shutil

    shutil.copytree(out, copy)
    df = run_sweep(other, copy, executor="serial", progress=False, overwrite=True)
    assert len(df) == 12 and df.attrs["ran"] == list(range(12))
    assert len(list((copy / "parts").iterdir())) == 12


# --------------------------------------------------------------------------- summary

def test_summary_is_mean_and_student_t_interval():
    values = [1.0, 2.0, 4.0, 7.0]
    df = pd.DataFrame({"run_id": range(6), "combination": [0, 0, 0, 0, 1, 1], "copters.n": [2, 2, 2, 2, 3, 3],
                       "replicate": [0, 1, 2, 3, 0, 1], "seed": range(6),
                       "cohesion": values + [5.0, np.nan], "status": ["ok"] * 4 + ["ok", "error"],
                       "error": [""] * 5 + ["boom"], "elapsed": [0.1] * 6})
    s = summarize(df, ["copters.n"], ["cohesion"])
    lo, hi = stats.t.interval(0.95, 3, loc=np.mean(values), scale=stats.sem(values))
    assert s.loc[0, "cohesion_mean"] == pytest.approx(3.5)
    assert lo < 0  # the t interval reaches below 0; cohesion (m) cannot: the interval is cut there (issue 40)
    assert (s.loc[0, "cohesion_ci_low"], s.loc[0, "cohesion_ci_high"]) == (0.0, pytest.approx(hi))
    assert (s.loc[1, "n_ok"], s.loc[1, "n_error"], s.loc[1, "cohesion_mean"]) == (1, 1, 5.0)
    assert math.isnan(s.loc[1, "cohesion_ci_low"])  # one value: no interval


def test_fraction_intervals_stay_in_zero_one():
    """wall_sticking over 4 seeds: the t interval of [0, 0, 0, 0.3] reaches below 0 and of [1, 1, 1, 0.7] above 1;
    summary.csv cuts both to [0, 1] (issue 40)."""
    for values, (lo_exp, hi_exp) in (([0.0, 0.0, 0.0, 0.3], (0.0, None)), ([1.0, 1.0, 1.0, 0.7], (None, 1.0))):
        df = pd.DataFrame({"run_id": range(4), "combination": [0] * 4, "replicate": range(4), "seed": range(4),
                           "wall_sticking": values, "status": ["ok"] * 4, "error": [""] * 4, "elapsed": [0.1] * 4})
        s = summarize(df, [], ["wall_sticking"])
        lo, hi = stats.t.interval(0.95, 3, loc=np.mean(values), scale=stats.sem(values))
        assert lo < 0 or hi > 1
        assert s.loc[0, "wall_sticking_ci_low"] == (lo_exp if lo_exp is not None else pytest.approx(lo))
        assert s.loc[0, "wall_sticking_ci_high"] == (hi_exp if hi_exp is not None else pytest.approx(hi))


# --------------------------------------------------------------------------- the command line

def test_cli_sweep_end_to_end(sweep_file, tmp_path, capsys, reference):
    out = tmp_path / "cli"
    code = main(["sweep", str(sweep_file), "--out", str(out), "--executor", "serial", "--no-progress"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "8 runs (4 combinations x 2 replicates)" in captured.out
    pd.testing.assert_frame_equal(_table(pd.read_parquet(out / "results.parquet")), _table(reference[0]))
    assert (out / "summary.csv").is_file() and (out / "summary.png").is_file()
    # again without --resume: refused; with --resume: nothing to run
    assert main(["sweep", str(sweep_file), "--out", str(out), "--executor", "serial", "--no-progress"]) == 2
    assert "--resume" in capsys.readouterr().err
    (out / "parts" / "run-00002.parquet").unlink()
    assert main(["sweep", str(sweep_file), "--out", str(out), "--executor", "serial", "--no-progress", "--resume"]) == 0
    assert "1 runs in" in capsys.readouterr().out


def _flaky_episode(cfg, seed, env_id=0, metrics=None):
    if cfg.copters.n == 3 and cfg.behaviour.speed == 0.5:
        raise ValueError("copters collided with the test")
    return run_episode(cfg, seed, env_id, metrics)


def test_cli_reports_failed_runs_with_exit_code_1(sweep_file, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(executors_mod, "run_episode", _flaky_episode)  # serial: runs in this process
    out = tmp_path / "cli"
    code = main(["sweep", str(sweep_file), "--out", str(out), "--executor", "serial", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1
    assert "2 of 8 runs failed" in err
    assert "run 6 (copters.n=3, behaviour.speed=0.5, replicate 0, seed" in err and "ValueError: copters collided" in err
    df = pd.read_parquet(out / "results.parquet")
    assert list(df["status"]) == ["ok"] * 6 + ["error"] * 2


@pytest.mark.parametrize("args, message", [
    (["--executor", "procss"], "invalid choice: 'procss'"),
    (["--workers", "0"], "--workers 0"),
    (["--executor", "serial", "--scheduler", "tcp://127.0.0.1:8786"], "--scheduler needs --executor dask"),
])
def test_cli_bad_options_exit_2(sweep_file, tmp_path, capsys, args, message):
    code = main(["sweep", str(sweep_file), "--out", str(tmp_path / "o"), *args])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("content, message", [
    (SWEEP_TOML.replace('"copters.n"', '"copters.nn"'), "did you mean copters.n?"),
    (SWEEP_TOML.replace("[2, 3]", "[]"), "expected a non-empty list"),
    (SWEEP_TOML.replace("[0.2, 0.5]", '["fast", 0.5]'), "behaviour.speed = 'fast': expected a number"),
    ("[grid\n", "invalid TOML"),
    (None, "does not exist"),
])
def test_cli_bad_sweep_files_exit_2_before_any_run(tmp_path, capsys, content, message):
    path = tmp_path / "s.toml"
    if content is not None:
        path.write_text(content)
    code = main(["sweep", str(path), "--out", str(tmp_path / "o"), "--executor", "serial"])
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("finkensim sweep: error:") and message in lines[0]
    assert not (tmp_path / "o").exists()
