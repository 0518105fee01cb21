"""``python -m benchmarks.run --quick`` runs end to end (no timing assertions), and the two
implementations of the comparison workload agree."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_bench_quick_runs(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, "-m", "benchmarks.run", "--quick", "--no-peers", "--out", str(tmp_path)],
                       cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    md = (tmp_path / "bench.md").read_text()
    assert "(a) Comparison workload" in md and "Scaling at fixed density" in md
    res = json.loads((tmp_path / "bench.json").read_text())
    assert res["meta"]["quick"] is True
    assert {(r["N"], r["B"]) for r in res["compare"]} == {(4, 1), (4, 64), (10, 1), (10, 64)}
    for r in res["compare"]:
        for impl in ("finkensim", "numpy"):
            assert r[impl]["env_steps_per_s"] > 0 and r[impl]["peak_bytes_per_env"] > 0
    assert [r["N"] for r in res["scaling"]["rows"]] == [10, 100]
    assert (tmp_path / "scaling.png").exists()
    assert "finkensim / NumPy" in p.stdout
    assert "VMAS: not measured (--no-peers)" in md and "## Targets (from this run)" in md


def test_targets_are_judged_from_the_run():
    """The targets table compares this run's figures with the thresholds; what the run did not measure says so."""
    from benchmarks.run import targets

    res = dict(compare=[dict(N=10, B=1024, finkensim=dict(env_steps_per_s=3.0e5), ratio_numpy=12.0, ratio_vmas=80.0),
                        dict(N=10, B=1, finkensim=dict(env_steps_per_s=1.0e5), ratio_numpy=20.0, ratio_vmas=6000.0)],
               finken=dict(status="", rows=[dict(N=10, B=1024, env_steps_per_s=1.2e5)]),
               compile=[dict(workload="finken", cold=dict(first_call_s=20.0), warm=dict(first_call_s=0.5))])
    by_target = {t["target"]: (t["measured"], t["met"]) for t in targets(res)}
    assert by_target["comparison workload ≥ 40× VMAS (N = 10, B = 1024)"] == ("80×", True)
    assert by_target["comparison workload ≥ 5,000× VMAS (N = 10, B = 1)"] == ("6,000×", True)
    assert by_target["comparison workload ≥ 15× plain NumPy (N = 10, B = 1024)"] == ("12.0×", False)
    assert not any("≤ 3×" in t or "cold JIT" in t for t in by_target)  # retired by issue 43
    assert by_target["warm (cached) first call, full workload ≤ 1 s"] == ("0.50 s", True)
    assert by_target["Gymnasium vector env ≥ 100 k env-steps/s (N = 10, B = 1024, sensors on)"] == (None, None)


def test_comparison_workload_numba_equals_numpy():
    from benchmarks.workloads import CompareWorkload

    for n, b in ((1, 2), (4, 3), (10, 5)):
        a, c = CompareWorkload(n, b, "finkensim", seed=7), CompareWorkload(n, b, "numpy", seed=7)
        for _ in range(5):
            a.run(3)
            c.run(3)
            np.testing.assert_allclose(a.pos, c.pos, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.sonar, c.sonar, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.dist, c.dist, rtol=0, atol=1e-9)
        assert np.all(a.sonar <= 3.0) and np.all(a.sonar >= 0.0)


def test_engine_scaling_measures_small_swarms_and_draws_the_figure(tmp_path):
    """Section (d) of make bench on two tiny sizes (grid off at 8, on at 64 copters): positive costs, the spread of
    the grid column, a markdown table, the figure — and --plot redraws it from a saved bench.json."""
    from benchmarks import engine_scaling

    res = engine_scaling.run(log=lambda m: None, sizes=(8, 64), brute_max=8, out_dir=tmp_path)
    rows = res["rows"]
    assert [r["N"] for r in rows] == [8, 64] and all(r["grid_us"] > 0 for r in rows)
    assert rows[0]["brute_us"] > 0 and rows[1]["brute_us"] is None
    g = [r["grid_us"] for r in rows]
    assert res["spread"] == max(g) / np.sqrt(max(g) * min(g)) - 1.0
    assert "| 64 |" in res["markdown"] and (tmp_path / "engine_scaling.png").stat().st_size > 10_000
    assert all(r["local_us"] > 0 for r in rows) and res["local_spread"] >= 0
    # the copters in range, against a plain count on the same settled swarm
    sim, state = engine_scaling.settled(64, True)
    pos = np.asarray(state.world.pos[0])
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    same_slot = (np.arange(64)[:, None] % 4) == (np.arange(64)[None, :] % 4)  # round robin over 4 slots
    off_diagonal = ~np.eye(64, dtype=bool)
    expect = ((d <= 6.0) & same_slot & off_diagonal).sum(1).mean(), ((d <= 2.5) & off_diagonal).sum(1).mean()
    assert (sim.cfg.sonar.schedule, sim.cfg.sonar.n_slots, sim.cfg.sonar.max_range) == ("round_robin", 4, 3.0)
    assert engine_scaling.copters_in_range(sim, state) == pytest.approx(expect, rel=1e-12)
    assert rows[1]["crosstalk_peers"] == pytest.approx(expect[0]) and rows[1]["ranging_peers"] == pytest.approx(expect[1])
    (tmp_path / "bench.json").write_text(json.dumps({"engine_scaling": res}))
    engine_scaling.main(["--plot", str(tmp_path / "bench.json"), str(tmp_path / "again.png")])
    assert (tmp_path / "again.png").stat().st_size > 10_000


def test_vector_env_step_split_adds_up():
    """benchmarks.envs_bench --split: the timed parts of a vector-env step are positive and within the step."""
    pytest.importorskip("gymnasium")
    from benchmarks.envs_bench import step_split

    r = step_split(b=4, steps=3)
    parts = [r["compiled step_ms"], r["reward_ms"], r["observation_ms"]]
    assert all(p > 0 for p in parts) and sum(parts) <= r["step_ms"]
    assert r["env_steps_per_s"] == pytest.approx(4 * 1e3 / r["step_ms"])


def test_vector_env_sensor_split_times_each_sensor_set():
    """benchmarks.envs_bench --sensors: one positive time per sensor set, and the numba thread count is restored."""
    import numba

    from benchmarks.envs_bench import SENSOR_SETS, sensor_split

    threads = numba.get_num_threads()
    r = sensor_split(b=3, steps=1, warm=1)
    assert list(r) == [label for label, _ in SENSOR_SETS]
    assert all(v > 0 for v in r.values())
    assert numba.get_num_threads() == threads


def test_perf_map_names_freshly_compiled_functions(tmp_path):
    """benchmarks.perf_map: perf's map file lists a function numba just compiled, at its address, by its name."""
    from numba import njit

    from benchmarks.perf_map import compiled_functions, write_perf_map

    @njit  # not cached: its module keeps the symbols
    def perf_map_probe(x):
        return x * 2.0 + 1.0

    assert perf_map_probe(1.0) == 3.0
    path = write_perf_map(tmp_path / "perf.map")
    lines = [line.split() for line in path.read_text().splitlines()]
    named = {name: (int(a, 16), int(s, 16)) for a, s, name in lines}
    probe = [name for name in named if "perf_map_probe" in name]
    assert probe, "the probe function is not in the map"
    addr, size = named[probe[0]]
    assert addr in compiled_functions() and size > 0
    starts = sorted(a for a, _ in named.values())
    assert all(a + s <= b for (a, s), b in zip(sorted(named.values()), starts[1:]))  # no overlaps


def test_breakdown_times_every_kernel_and_reports_against_the_comparison():
    """``benchmarks.breakdown`` (in ``make bench``'s report) on a small swarm: every kernel timed (> 0), the
    markdown's sum and ratio from those figures, and the report's ratio from the comparison's one-thread rate."""
    from benchmarks import breakdown

    r = breakdown.breakdown(4, 8, reps=1)
    us = r["us_per_env_step"]
    assert all(v > 0 for v in us.values()) and len(us) == 8
    assert 0.0 <= r["plates_at_rest"] <= 1.0 and 0.0 <= r["plates_active"] <= 1.0
    total = sum(v for k, v in us.items() if not k.startswith("  "))
    md = breakdown.markdown(r, compare_us=total / 4)
    assert f"| sum | {total:.2f} |" in md and "the sum above is 4.0× that" in md
    assert "N = 4, B = 8, one thread" in md and "comparison" not in breakdown.markdown(r)
    # make bench's report takes the comparison's one-thread rate of the same N and B from the same run
    from benchmarks.run import report

    meta = dict(time="t", python="3", numpy="2", numba="0", numba_threads=2, cpus=2, load_start="0", load_end="0",
                quick=False, threads=[1, 2])
    cmp = dict(N=10, B=8, finkensim=dict(env_steps_per_s=3e5, copter_steps_per_s=3e6, threads=2,
                                         steps_per_s_by_threads={"1": 2e5, "2": 3e5}, peak_bytes_per_env=1.0),
               numpy=dict(env_steps_per_s=1e4, copter_steps_per_s=1e5, peak_bytes_per_env=1.0), ratio_numpy=30.0)
    md = report(dict(meta=meta, compare=[cmp], breakdown=dict(r, N=10)))
    assert "takes 5.00 µs per env-step on one thread" in md and "3× would allow 15.00 µs" in md


def test_diagnosis_section_reports_trials_and_targets():
    """benchmarks.diagnosis times a trial (CPU s, verdict) and renders the section with its targets (no timing
    assertion: whether a target is met depends on the machine)."""
    from benchmarks import diagnosis

    clock = {}
    rows = diagnosis.time_trials((("null", 3),), log=lambda m: None, warmup=None, duration=20.0, clock=clock)
    assert [(r["case"], r["seed"]) for r in rows] == [("null", 3)]
    assert rows[0]["cpu_s"] > 0 and isinstance(rows[0]["correct"], bool)
    # every catalogued effect on the null trial's sensors was fitted at least once, each fit's CPU counted
    assert "sonar_bias" in clock and clock["sonar_bias"][0] >= 1 and clock["sonar_bias"][1] > 0
    assert sum(s for _, s in clock.values()) <= rows[0]["cpu_s"] + 1e-6
    from finkensim.gap.diagnosis import Diagnosis
    assert Diagnosis.fit.__name__ == "fit"  # the clock is taken off again
    res = dict(trials=rows, median_cpu_s=rows[0]["cpu_s"], cores=2, matrix_trials=3020, matrix_hours=0.5,
               load=[1.0] * 6, fits=clock,
               gap_timing=dict(duration=600.0, seconds=4.0, peak_gb=0.5),
               memory=dict(duration=3600.0, seconds=90.0, peak_gb=1.2))
    md = diagnosis.markdown(res)
    assert md.startswith("## Diagnosis") and "| null | 3 |" in md
    assert "pairs matrix (3020 trials) on 2 cores ≤ 1 h" in md and "| 0.5 h | yes |" in md
    from finkensim.gap.validation.cases import all_pairs
    assert diagnosis.pairs_matrix_trials() == 20 * len(all_pairs())
    sample = dict(path="s.jsonl", trials=40, median_cpu_s=2.5, mean_cpu_s=3.6, right=38, exactly=35)
    md_sample = diagnosis.markdown({**res, "sample": sample})
    assert "40 trials, 38 right, 35 exactly): median trial ≤ 3 s of CPU | 2.5 s | yes |" in md_sample
    assert "mean trial (3.6 s) ≤ 1 h | 1.5 h | **no** |" in md_sample
    assert "4.0 s, peak 0.50 GB | yes |" in md
    assert "10 copters × 1 h ≤ 1 GB | 1.20 GB (90 s wall clock) | **no** |" in md
    assert "| sonar_bias | " in md
    md = diagnosis.markdown({**res, "gap_timing": None, "memory": None})
    assert md.count("not measured") == 2
