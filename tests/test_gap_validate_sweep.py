"""The validation machinery itself: pairs, the conventions axis, Wilson intervals, resumable trials."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from finkensim.cli import main
from finkensim.config import load_config
from finkensim.flightlog import FlightLog
from finkensim.gap.validation import sweep as validate_sweep
from finkensim.gap.validation.conventions import NO_ECHO, NO_ECHO_DRAWN, NOISE, Conventions, draw_conventions
from finkensim.gap.validation.cases import CASES, all_pairs, get_case, pair_case
from finkensim.gap.validation.tables import confusion, effect_pairs, exactly_withheld, paired, pair_grid, wilson
from tests.stats import assert_proportion_within_se, assert_std_within_se, assert_within_se


def test_wilson_interval_matches_statsmodels_formula_values():
    # reference values: Wilson (1927) score interval, e.g. 19/20 → (0.7639, 0.9911)
    lo, hi = wilson(19, 20)
    assert lo == pytest.approx(0.76387, abs=1e-4) and hi == pytest.approx(0.99111, abs=1e-4)
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.27753, abs=1e-4)
    assert all(math.isnan(x) for x in wilson(0, 0))


def test_wilson_interval_covers_at_the_nominal_rate():
    """Coverage of p = 0.9 with n = 20 over all outcomes, weighted by their binomial probability: ≥ 0.93."""
    n, p = 20, 0.9
    cover = sum(stats.binom.pmf(k, n, p) for k in range(n + 1) if wilson(k, n)[0] <= p <= wilson(k, n)[1])
    assert cover >= 0.93


def test_pairs_combine_two_effects_and_refuse_clashing_settings():
    pairs = all_pairs()
    singles = [c.name for c in CASES.values() if c.effect is not None]
    assert len(pairs) >= len(singles) * (len(singles) - 1) // 2 - 5  # only a few pairs clash
    assert "crosstalk_geometric+crosstalk_constant" not in pairs  # both set sonar.crosstalk
    case = get_case("sonar_bias+latency")
    assert case.effects == ("sonar_bias", "latency")
    updates, posts, truth = case.make(np.random.default_rng(1))
    assert len(posts) == 2 and any(k.startswith("sonar_bias.") for k in truth)
    with pytest.raises(ValueError, match="both set"):
        pair_case("crosstalk_geometric", "crosstalk_constant").make(np.random.default_rng(0))
    with pytest.raises(KeyError):
        get_case("nonsense+latency")


def test_pair_grid_counts_each_pair_in_its_cell_and_the_pairs_that_reach_the_target(tmp_path):
    rows = ([{"case": "sonar_bias+latency", "correct": c} for c in [True] * 9 + [False]]
            + [{"case": "wall_bulge+latency", "correct": True}] * 4 + [{"case": "null", "correct": True}] * 3)
    grid = pair_grid(rows)
    lines = grid.splitlines()
    assert lines[0] == "| both named | sonar_bias | latency |"  # the effects of the pairs, in catalogue order
    assert lines[2] == "| wall_bulge | — | 4/4 |" and lines[3] == "| sonar_bias |  | 9/10 |"
    lo, hi = wilson(9, 10)
    assert (f"≥ 90% of their trials: 2 of 2; lowest sonar_bias+latency 9/10 (Wilson 95 % {lo:.0%}–{hi:.0%}); "
            "trials per pair 4–10.") in grid
    assert pair_grid([{"case": "null", "correct": True}]) == ""
    assert "1 of 2" in pair_grid(rows + [{"case": "wall_bulge+latency", "correct": False}])  # 4/5 < 90 %

    from finkensim.gap.validation.plot import pair_grid_figure

    assert pair_grid_figure(rows, tmp_path / "pairs.png").stat().st_size > 5_000
    assert pair_grid_figure([{"case": "null", "correct": True}], tmp_path / "none.png") is None
    assert not (tmp_path / "none.png").exists()


def test_case_lists_expand_pairs_once_and_in_order():
    from finkensim.gap.validation.cases import expand_cases

    pairs = all_pairs()
    assert expand_cases(None) == list(CASES)
    assert expand_cases(["pairs"]) == pairs
    assert expand_cases(["null", pairs[3], "pairs"]) == ["null", pairs[3]] + [p for p in pairs if p != pairs[3]]
    assert expand_cases(["null"], pairs=True) == ["null"] + pairs


def test_conventions_axis_draws_every_convention_and_rejects_unknown_ones():
    rng = np.random.default_rng(0)
    draws = [draw_conventions(rng) for _ in range(300)]
    assert {d.no_echo for d in draws} == set(NO_ECHO_DRAWN) and {d.noise for d in draws} == set(NOISE)
    assert min(d.altitude for d in draws) >= 0.3 and max(d.altitude for d in draws) <= 1.2
    assert {d.n_copters for d in draws} == set(range(3, 11))
    with pytest.raises(ValueError, match="no_echo"):
        Conventions(no_echo="none")


def _log_with_sonar(y, hit):
    T, N, S = y.shape
    return FlightLog(t=np.arange(T) * 0.05, arena=np.array([3.0, 4.0]), pose=np.zeros((T, N, 3)),
                     copter_ids=np.array([f"c{i}" for i in range(N)]), ultrasonic=y.copy(),
                     ultrasonic_yaw=np.zeros(S), ultrasonic_offset=0.0, extras={"ultrasonic_hit_type": hit})


@pytest.mark.parametrize("no_echo", NO_ECHO)
def test_no_echo_conventions_rewrite_only_lost_echoes(no_echo):
    cfg = load_config()
    rng = np.random.default_rng(2)
    hit = (rng.random((4000, 3, 4)) < 0.7).astype(np.int64)  # ≈ 14 400 lost echoes
    y = np.where(hit > 0, rng.uniform(0.3, 2.5, hit.shape), cfg.sonar.max_range)
    log = _log_with_sonar(y, hit)
    Conventions(no_echo=no_echo, noise="gaussian").record(log, cfg, rng)
    lost = hit == 0
    np.testing.assert_array_equal(log.ultrasonic[~lost], y[~lost])
    if no_echo == "exact":
        assert np.all(log.ultrasonic[lost] == cfg.sonar.max_range)
    elif no_echo == "zero":
        assert np.all(log.ultrasonic[lost] == 0.0)
    elif no_echo == "nan":
        assert np.all(np.isnan(log.ultrasonic[lost]))
    else:
        v = log.ultrasonic[lost]
        assert np.all(v <= cfg.sonar.max_range) and np.all(v > cfg.sonar.max_range - 5 * cfg.sonar.sigma)
        # clipped half of a symmetric noise: SE √(0.25/n) ≈ 0.0042, 5 SE ≈ 0.021 (4.2 % of 0.5)
        assert_proportion_within_se(v == cfg.sonar.max_range, 0.5, what="share of noisy time-outs clipped to max")


def test_laplace_noise_has_the_configured_standard_deviation():
    cfg = load_config().replace({"sonar.sigma": 0.05})
    rng = np.random.default_rng(3)
    y = np.full((200_000, 2, 4), 1.5)  # n = 1.6 million: the sample kurtosis of heavy tails needs it
    log = _log_with_sonar(y, np.ones(y.shape, dtype=np.int64))
    Conventions(noise="laplace").record(log, cfg, rng)
    e = (log.ultrasonic - 1.5).ravel()
    n = e.size
    # SE of the sample sd for Laplace: σ·√((κ − 1)/4n), κ = 6: 4.4e-5 m, 5 SE = 0.44 % of σ
    assert_std_within_se(e, 0.05, se=0.05 * math.sqrt(5 / (4 * n)), ddof=0, what="Laplace noise std")
    # Laplace excess kurtosis 3 (Gaussian 0). SE of the sample kurtosis √((μ8/μ2⁴ − 4μ4μ6/μ2⁵ + 4μ4³/μ2⁶ − μ4²/μ2⁴)/n)
    # with the Laplace moments μ2k = (2k)!·b^2k: √(1188/n) = 0.027, 5 SE = 0.14 (4.5 % of 3)
    assert_within_se(stats.kurtosis(e), 3.0, math.sqrt(1188 / n), what="Laplace noise excess kurtosis")


def test_exactly_the_withheld_effects_counts_extras_and_misses_per_case_and_for_pairs():
    def row(case, effects, correct=True):
        return {"case": case, "effects": effects, "correct": correct, "significant": True, "named": (effects or [None])[0],
                "unexplained": not effects, "location_ok": None, "param_error": math.nan, "shrink_heldout": 1.0,
                "seconds": 1.0}

    assert exactly_withheld(row("wall_bulge", ["wall_bulge"]))
    assert not exactly_withheld(row("wall_bulge", ["wall_bulge", "pose_noise"]))  # named first, one extra
    assert exactly_withheld(row("sonar_bias+latency", ["latency", "sonar_bias"]))
    assert not exactly_withheld(row("sonar_bias+latency", ["latency", "sonar_bias", "sound_speed"]))
    assert not exactly_withheld(row("sonar_bias+latency", ["latency"], correct=False))
    assert exactly_withheld(row("foreign", []))  # a control: right, and no catalogued effect named
    assert exactly_withheld({"case": "null", "correct": True})  # rows from before the column: no "effects" key
    rows = [row("wall_bulge", ["wall_bulge"])] * 3 + [row("wall_bulge", ["wall_bulge", "sonar_bias"])]
    rows += [row("sonar_bias+latency", ["sonar_bias", "latency"]), row("sonar_bias+latency", ["sonar_bias", "latency", "beam_width"])]
    _, md = confusion(rows)
    lo, hi = wilson(3, 4)
    assert f"| wall_bulge | 4 | 100% (51%–100%) | 75% ({lo:.0%}–{hi:.0%}) |" in md
    assert "exactly the withheld effects" in md.splitlines()[0]
    lo, hi = wilson(1, 2)
    assert f"naming exactly the two withheld effects (none missing, none extra): 50.0% ({lo:.1%}–{hi:.1%}), 1 of 2." in pair_grid(rows)


def test_trials_resume_without_rerunning_finished_ones(tmp_path, monkeypatch):
    calls = []

    def fake(job):
        calls.append(job)
        case, seed, flights, duration, conv = job
        return {"case": case, "seed": seed, "significant": case != "null", "named": None, "unexplained": False,
                "correct": True, "location_ok": None, "param_error": math.nan, "shrink_heldout": 1.0,
                "seconds": 0.0, "flights": flights, "duration": duration, "convention_mode": conv,
                "flagged_locations": 0}

    monkeypatch.setattr(validate_sweep, "_one", fake)
    rows = validate_sweep.run_trials(["null", "sonar_bias"], 2, 5, 1, 10.0, "random", tmp_path)
    assert len(rows) == 4 and len(calls) == 4
    with (tmp_path / "trials.jsonl").open("a") as fh:
        fh.write('{"case": "null", "seed": 9, "trunc')  # a run killed mid-write
    rows = validate_sweep.run_trials(["null", "sonar_bias"], 3, 5, 1, 10.0, "random", tmp_path)
    assert len(rows) == 6 and len(calls) == 6  # only the third trial of each case ran
    assert [json.loads(x)["seed"] for x in (tmp_path / "trials.jsonl").read_text().splitlines()[:4]] == [5, 5, 6, 6]
    _, md = confusion(rows)
    assert "Wilson" in md and "| null | 3 | 100% (44%–100%) |" in md
    assert "| **all 2 cases** | 6 | 100.0% (61.0%–100.0%) |" in md  # the pooled row: 6 of 6, Wilson
    assert "| null | 3 | 100% (44%–100%) |" in validate_sweep.summarize(tmp_path)  # a run so far, from its file


def test_a_run_into_trials_of_other_sources_says_so_and_the_matrix_counts_them(tmp_path, monkeypatch):
    import finkensim.numba_cache as nc

    def fake(job):
        case, seed, flights, duration, conv = job
        return {"case": case, "seed": seed, "significant": False, "named": None, "unexplained": False,
                "correct": True, "location_ok": None, "param_error": math.nan, "shrink_heldout": 1.0,
                "seconds": 0.0, "flights": flights, "duration": duration, "convention_mode": conv,
                "flagged_locations": 0}

    monkeypatch.setattr(validate_sweep, "_one", fake)
    notes = []
    monkeypatch.setattr(nc, "source_hash", lambda: "aaaa")
    validate_sweep.run_trials(["null"], 1, 5, 1, 10.0, "random", tmp_path, note=notes.append)
    validate_sweep.run_trials(["null"], 2, 5, 1, 10.0, "random", tmp_path, note=notes.append)
    assert notes == [] and "versions of finkensim" not in validate_sweep.summarize(tmp_path)  # one source: silent
    monkeypatch.setattr(nc, "source_hash", lambda: "bbbb")
    validate_sweep.run_trials(["null"], 3, 5, 1, 10.0, "random", tmp_path, note=notes.append)
    assert len(notes) == 1 and "other finkensim sources (aaaa; these are bbbb)" in notes[0], notes
    assert [r["sources"] for r in validate_sweep.provenance(tmp_path)] == ["aaaa", "aaaa", "bbbb"]
    assert "made by 2 versions of finkensim (sources aaaa, bbbb" in validate_sweep.summarize(tmp_path)
    validate_sweep.run_trials(["null"], 3, 5, 1, 10.0, "random", tmp_path, note=notes.append)
    assert len(notes) == 1 and len(validate_sweep.provenance(tmp_path)) == 3  # nothing to add: no note, no record
    monkeypatch.setattr(nc, "source_hash", lambda: "cccc")
    with pytest.warns(UserWarning, match=r"other finkensim sources \(aaaa, bbbb; these are cccc\)"):
        validate_sweep.run_trials(["null"], 4, 5, 1, 10.0, "random", tmp_path)  # a library call without ``note``


def test_effect_pairs_counts_each_effects_pairs_that_reach_the_target():
    rows = ([{"case": "sonar_bias+latency", "correct": c} for c in [True] * 18 + [False] * 2]
            + [{"case": "wall_bulge+latency", "correct": c} for c in [True] * 17 + [False] * 3]
            + [{"case": "null", "correct": True}])
    lines = effect_pairs(rows).splitlines()
    lo, hi = wilson(17, 20)
    assert lines[2] == f"| wall_bulge | 1 | 0 | wall_bulge+latency 17/20 ({lo:.0%}–{hi:.0%}) | 20–20 |"
    assert lines[3].startswith("| sonar_bias | 1 | 1 | sonar_bias+latency 18/20 ")  # 18 of 20 reaches 90 %
    assert lines[4].startswith("| latency | 2 | 1 | wall_bulge+latency 17/20 ")
    assert effect_pairs(rows, ["imu_bias"]).splitlines()[2] == "| imu_bias | 0 | | | |"
    assert effect_pairs([{"case": "null", "correct": True}]) == ""


def test_parts_of_one_matrix_merge_and_disagreeing_parts_are_refused(tmp_path, capsys):
    row = {"case": "sonar_bias+latency", "seed": 0, "significant": True, "named": "sonar_bias",
           "effects": ["sonar_bias", "latency"], "unexplained": False, "correct": True, "location_ok": None,
           "param_error": math.nan, "shrink_heldout": 1.0, "seconds": 3.0, "flights": 2, "duration": 30.0,
           "convention_mode": "random", "flagged_locations": 0}
    a, b = tmp_path / "a", tmp_path / "b"
    for d, rows in ((a, [row, {**row, "seed": 1}]), (b, [{**row, "seconds": 9.0}, {**row, "seed": 2}])):
        d.mkdir()
        (d / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert sorted(r["seed"] for r in validate_sweep.merged_rows([a, b])) == [0, 1, 2]  # seed 0 once (time aside)
    assert "sonar_bias+latency 3/3" in validate_sweep.summarize(a, b) and "After calibration" not in validate_sweep.summarize(a)
    (b / "trials.jsonl").write_text(json.dumps({**row, "correct": False}) + "\n")
    with pytest.raises(ValueError, match=r"trial sonar_bias\+latency seed 0 differs between .*a and .*b in correct"):
        validate_sweep.merged_rows([a, b])
    (a / "trials.jsonl").write_text(json.dumps({**row, "calibrated_significant": False, "calibrated_gap_ratio": 0.0}) + "\n")
    assert "| **every pair** (1) | 1 | 100 % |" in validate_sweep.summarize(a)  # --calibrate rows: the calibration table


def test_two_diagnoses_are_compared_on_the_trials_they_share():
    row = {"case": "ranging_nlos+ranging_scale", "seed": 1, "significant": True, "unexplained": False,
           "effects": ["ranging_nlos"], "correct": False, "seconds": 20.0, "flights": 2, "duration": 30.0,
           "convention_mode": "random"}
    base = [row, {**row, "seed": 2, "effects": ["ranging_nlos", "ranging_scale"], "correct": True},
            {**row, "seed": 3}]
    new = [{**row, "effects": ["ranging_nlos", "ranging_scale"], "correct": True, "seconds": 40.0},
           {**base[1], "seconds": 30.0}, {**row, "seed": 4}]
    out = paired(new, base)
    lo, hi = wilson(1, 2)
    assert f"| right | 1 (50.0%, {lo:.1%}–{hi:.1%}) | 2 (100.0%, " in out
    assert "| wall seconds per trial (mean, under each run's own load) | 20.0 | 35.0 |" in out
    assert "2 trials in common; 1 changed" in out
    assert "- ranging_nlos+ranging_scale seed 1: ✗ ranging_nlos → ✓ ranging_nlos, ranging_scale" in out
    assert paired(new, [{**row, "duration": 60.0}]) == "no trial in common\n"


@pytest.mark.parametrize("extra,named", [(["--cases", "sonar_bias+sonar_bias"], "sonar_bias+sonar_bias"),
                                         (["--cases", "null", "--scheduler", "tcp://x:1"], "--scheduler"),
                                         (["--cases", "null", "--workers", "0"], "--workers 0")])
def test_gap_validate_names_bad_cases_and_executor_options(extra, named, capsys):
    assert main(["gap-validate", *extra]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err


def _thread_counts():
    import importlib

    import numba
    from threadpoolctl import threadpool_info

    importlib.import_module("sklearn.ensemble")  # loads scikit-learn's OpenMP pool after the worker started

    return numba.get_num_threads(), {pool["num_threads"] for pool in threadpool_info()}


def test_process_workers_compute_on_one_thread():
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    from finkensim.gap.validation.sweep import _worker_init

    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_worker_init, initargs=(os.getpid(),)) as pool:
        numba_threads, pool_threads = pool.submit(_thread_counts).result()
    assert numba_threads == 1
    assert pool_threads <= {1}
