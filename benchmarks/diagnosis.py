"""``python -m benchmarks.diagnosis [--no-gap-timing]``: what a diagnosis costs (``make bench``, section "diagnosis").

* **Validation trials** (:data:`TRIALS`): one ``finkensim gap-validate`` trial each (2 flights × 30 s, random
  recording conventions, :func:`finkensim.gap.validation.cases.run_case`), singles and pairs, in this process on one numba
  thread, as the process-pool workers of ``gap-validate --executor process`` run them. Measured: CPU seconds
  (``time.process_time``) of each trial after a warm-up trial (the kernels compiled or loaded first), and the
  verdict (right / wrong), so a change that cuts time also shows whether it changed an answer.
* **The pairs matrix**, estimated: (mean trial CPU of these trials) × the matrix's trials (every pair of today's
  catalogue × :data:`PAIRS_MATRIX_SEEDS`) ÷ the machine's cores.
* **The verdict sample** (``--sample FILE``, a run of ``python -m benchmarks.diagnosis_agreement run --sample
  verdict``): its median and mean trial against the same targets, with its right and exact verdicts.
* **Where the trials' CPU goes**: CPU seconds of each effect's fits (:meth:`~finkensim.gap.diagnosis.Diagnosis.fit`,
  every round) and of the held-out scoring, summed over the trials.
* **examples/gap_timing.py** (``finkensim gap`` on 10 copters × 10 min, in a subprocess): wall-clock seconds and peak
  resident memory, as the example prints them; and the same command on a flight of 1 h (:data:`MEMORY_DURATION`)
  for the peak memory target.

Timings are measured in this run on a machine that others may share: the load average before and after is printed
with them. No test asserts a time.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import importlib
import io
import os
import pstats
import re
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

#: (case, seed) of the timed trials: the issue's examples (latency, sound speed, geometric cross-talk, the curtain
#: bulge with a sonar bias, the dearest) and a few more singles and pairs
TRIALS = (("latency", 51), ("latency", 52), ("latency", 53), ("sound_speed", 51),
          ("sound_speed+crosstalk_geometric", 51), ("wall_bulge+sonar_bias", 5), ("imu_bias", 51),
          ("ranging_nlos+sonar_bias", 51))
FLIGHTS, DURATION = 2, 30.0  # per trial, as in the validation matrices
PAIRS_MATRIX_SEEDS = 20  # trials per pair in the pairs matrix (docs/validation)
TARGET_TRIAL_CPU = 3.0  # s, median warm trial
TARGET_MATRIX_HOURS = 1.0
TARGET_GAP_TIMING = 5.0  # s, examples/gap_timing.py
TARGET_PEAK_GB = 1.0  # GB, peak resident memory of `finkensim gap` on 1 h of 10 copters
MEMORY_DURATION = 3600.0  # s, the flight of the memory target
WARMUP = ("wall_bulge+sonar_bias", 5)


@contextlib.contextmanager
def fit_clock():
    """While active, CPU seconds (``time.process_time``) of :meth:`~finkensim.gap.diagnosis.Diagnosis.fit` per effect
    and of :meth:`~finkensim.gap.diagnosis.Diagnosis.score_heldout` (key "(held-out scoring)") are summed into the
    yielded dict (name → [calls, seconds]); the methods are restored on exit. Nested calls (a joint fit calls no
    ``fit``) are not double counted: ``fit`` and ``score_heldout`` do not call each other."""
    diagnose = importlib.import_module("finkensim.gap.diagnosis")
    cls = diagnose.Diagnosis
    fit, score = cls.fit, cls.score_heldout
    clock: dict = {}

    def add(name, t0):
        c = clock.setdefault(name, [0, 0.0])
        c[0] += 1
        c[1] += time.process_time() - t0

    def timed_fit(self, effect, current):
        t0 = time.process_time()
        try:
            return fit(self, effect, current)
        finally:
            add(effect.name, t0)

    def timed_score(self, res, *args, **kwargs):
        t0 = time.process_time()
        try:
            return score(self, res, *args, **kwargs)
        finally:
            add("(held-out scoring)", t0)

    cls.fit, cls.score_heldout = timed_fit, timed_score
    try:
        yield clock
    finally:
        cls.fit, cls.score_heldout = fit, score


def pairs_matrix_trials() -> int:
    """Trials of the pairs matrix of today's catalogue: every pair (:func:`~finkensim.gap.validation.cases.all_pairs`)
    × :data:`PAIRS_MATRIX_SEEDS`."""
    from finkensim.gap.validation.cases import all_pairs

    return len(all_pairs()) * PAIRS_MATRIX_SEEDS


def verdict_sample(path: str) -> dict:
    """The CPU seconds and verdicts of a verdict-sample run (``python -m benchmarks.diagnosis_agreement run --sample
    verdict --out FILE``): trials, median and mean CPU s, right and exactly counts."""
    import json

    with open(path) as fh:
        rows = [json.loads(line) for line in fh if line.strip()]
    cpu = [r["cpu_s"] for r in rows]
    return dict(path=path, trials=len(rows), median_cpu_s=statistics.median(cpu), mean_cpu_s=statistics.mean(cpu),
                right=sum(r["correct"] for r in rows), exactly=sum(bool(r.get("exactly")) for r in rows))


def time_trials(trials=TRIALS, log=print, warmup=WARMUP, duration: float = DURATION, threads: int = 1,
                profile: bool = False, clock: dict | None = None) -> list[dict]:
    """CPU seconds and verdict of each (case, seed) trial of :data:`FLIGHTS` flights × ``duration`` s, after the
    ``warmup`` trial (None: none), on ``threads`` numba threads (the thread count is restored). ``profile``: also
    each trial's 30 costliest functions by cumulative CPU time (cProfile on the CPU clock), text under "profile".
    ``clock``: a dict that receives the timed trials' CPU seconds per effect fitted (see :func:`fit_clock`)."""
    import numba

    from finkensim.gap.validation.cases import run_case

    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    rows = []
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if warmup is not None:
                run_case(*warmup, FLIGHTS, duration, conventions="random")
            for case, seed in trials:
                prof = cProfile.Profile(time.process_time) if profile else None
                t0 = time.process_time()
                if prof is not None:
                    prof.enable()
                with fit_clock() as fits:
                    row = run_case(case, seed, FLIGHTS, duration, conventions="random")
                cpu = time.process_time() - t0
                for name, (calls, seconds) in fits.items():
                    if clock is not None:
                        c = clock.setdefault(name, [0, 0.0])
                        c[0] += calls
                        c[1] += seconds
                rows.append(dict(case=case, seed=seed, cpu_s=cpu, correct=bool(row["correct"]),
                                 effects=list(row["effects"]), threads=threads))
                if prof is not None:
                    prof.disable()
                    text = io.StringIO()
                    pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(30)
                    rows[-1]["profile"] = text.getvalue()
                log(f"diagnosis: {case} seed {seed}: {cpu:.1f} s CPU, {'right' if row['correct'] else 'wrong'}")
    finally:
        numba.set_num_threads(before)
    return rows


def gap_timing(duration: float = 600.0) -> dict:
    """Run examples/gap_timing.py in a subprocess: its wall-clock seconds and peak memory (GB), or an error."""
    out = subprocess.run([sys.executable, str(REPO / "examples" / "gap_timing.py"), "--duration", f"{duration:g}",
                          "--out", str(REPO / "out" / "bench" / "gap_timing")],
                         capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    m = re.search(r"([\d.]+) s wall clock, peak resident memory ([\d.]+) GB", out.stdout)
    if out.returncode != 0 or m is None:
        return dict(error=(out.stderr.strip().splitlines() or ["no output"])[-1])
    return dict(duration=duration, seconds=float(m.group(1)), peak_gb=float(m.group(2)))


def run(log=print, with_gap_timing: bool = True, with_memory: bool = True, sample: str | None = None) -> dict:
    """The section's measurements: :data:`TRIALS` timed (:func:`time_trials`) with their CPU per effect fitted,
    the pairs matrix estimated, ``examples/gap_timing.py`` on 10 min (``with_gap_timing``) and on
    :data:`MEMORY_DURATION` s (``with_memory``, for the peak memory); ``sample``: a verdict-sample file
    (:func:`verdict_sample`) whose figures are judged against the targets too. Returns the numbers and their
    "markdown"."""
    load0 = os.getloadavg()
    clock: dict = {}
    trials = time_trials(log=log, clock=clock)
    cpu = [r["cpu_s"] for r in trials]
    n_matrix = pairs_matrix_trials()
    res = dict(trials=trials, median_cpu_s=statistics.median(cpu), cores=os.cpu_count() or 1,
               matrix_trials=n_matrix, matrix_hours=statistics.mean(cpu) * n_matrix / (os.cpu_count() or 1) / 3600,
               fits=clock)
    if sample is not None:
        res["sample"] = verdict_sample(sample)
    if with_gap_timing:
        log("diagnosis: examples/gap_timing.py (10 copters x 10 min)")
        res["gap_timing"] = gap_timing()
    if with_memory:
        log(f"diagnosis: examples/gap_timing.py (10 copters x {MEMORY_DURATION:g} s, peak memory)")
        res["memory"] = gap_timing(MEMORY_DURATION)
    res["load"] = [round(x, 2) for x in load0 + os.getloadavg()]
    res["markdown"] = markdown(res)
    return res


def _met(ok: bool) -> str:
    return "yes" if ok else "**no**"


def markdown(res: dict) -> str:
    """The section "Diagnosis" of ``make bench``'s report from :func:`run`'s numbers (a missing measurement reads
    "not measured")."""
    L = ["## Diagnosis", "",
         f"Validation trials ({FLIGHTS} flights × {DURATION:g} s, random conventions, warm kernels, one numba thread "
         f"as in `gap-validate --executor process`); CPU seconds per trial (`benchmarks/diagnosis.py`). Load average "
         f"{' '.join(map(str, res['load'][:3]))} → {' '.join(map(str, res['load'][3:]))}.", "",
         "| case | seed | CPU s | verdict |", "|---|---:|---:|---|"]
    for r in res["trials"]:
        L.append(f"| {r['case']} | {r['seed']} | {r['cpu_s']:.1f} | {'right' if r['correct'] else 'wrong'} |")
    fits = res.get("fits")
    if fits:
        total = sum(r["cpu_s"] for r in res["trials"])
        L += ["", f"Where these trials' {total:.1f} CPU s go: each effect's fits (every round) and the held-out scoring "
              "(the rest: simulating the flights, tables, locations, joint fits, the report).", "",
              "| fitted | calls | CPU s | share |", "|---|---:|---:|---:|"]
        for name, (calls, seconds) in sorted(fits.items(), key=lambda kv: -kv[1][1]):
            L.append(f"| {name} | {calls} | {seconds:.1f} | {100 * seconds / total:.0f} % |")
    gt, mem = res.get("gap_timing"), res.get("memory")
    L += ["", "| target | measured | met |", "|---|---:|---|",
          f"| warm validation trial ≤ {TARGET_TRIAL_CPU:g} s of CPU (median) | {res['median_cpu_s']:.1f} s | "
          f"{_met(res['median_cpu_s'] <= TARGET_TRIAL_CPU)} |",
          f"| pairs matrix ({res['matrix_trials']} trials) on {res['cores']} cores ≤ {TARGET_MATRIX_HOURS:g} h "
          f"(mean trial above × trials ÷ cores) | {res['matrix_hours']:.1f} h | "
          f"{_met(res['matrix_hours'] <= TARGET_MATRIX_HOURS)} |"]
    vs = res.get("sample")
    if vs is not None:
        hours = vs["mean_cpu_s"] * res["matrix_trials"] / res["cores"] / 3600
        L += [f"| verdict sample (`{vs['path']}`, {vs['trials']} trials, {vs['right']} right, {vs['exactly']} "
              f"exactly): median trial ≤ {TARGET_TRIAL_CPU:g} s of CPU | {vs['median_cpu_s']:.1f} s | "
              f"{_met(vs['median_cpu_s'] <= TARGET_TRIAL_CPU)} |",
              f"| pairs matrix from the verdict sample's mean trial ({vs['mean_cpu_s']:.1f} s) ≤ "
              f"{TARGET_MATRIX_HOURS:g} h | {hours:.1f} h | {_met(hours <= TARGET_MATRIX_HOURS)} |"]
    if gt is None:
        L.append(f"| examples/gap_timing.py ≤ {TARGET_GAP_TIMING:g} s | — | not measured |")
    elif "error" in gt:
        L.append(f"| examples/gap_timing.py ≤ {TARGET_GAP_TIMING:g} s | error: {gt['error']} | — |")
    else:
        L.append(f"| examples/gap_timing.py (10 copters × {gt['duration']:g} s) ≤ {TARGET_GAP_TIMING:g} s | "
                 f"{gt['seconds']:.1f} s, peak {gt['peak_gb']:.2f} GB | {_met(gt['seconds'] <= TARGET_GAP_TIMING)} |")
    label = f"peak memory of `finkensim gap` on 10 copters × {MEMORY_DURATION / 3600:g} h ≤ {TARGET_PEAK_GB:g} GB"
    if mem is None:
        L.append(f"| {label} | — | not measured |")
    elif "error" in mem:
        L.append(f"| {label} | error: {mem['error']} | — |")
    else:
        L.append(f"| {label} | {mem['peak_gb']:.2f} GB ({mem['seconds']:.0f} s wall clock) | "
                 f"{_met(mem['peak_gb'] <= TARGET_PEAK_GB)} |")
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-gap-timing", action="store_true", help="only the validation trials")
    ap.add_argument("--no-memory", action="store_true", help="skip the 1 h flight of the peak memory target")
    ap.add_argument("--trials", nargs="+", default=None, metavar="CASE:SEED",
                    help="time these trials only (the first once more before, as the warm-up), e.g. latency:51")
    ap.add_argument("--threads", type=int, default=1, help="numba threads of the trials (default 1)")
    ap.add_argument("--profile", action="store_true", help="with --trials: print where each trial's CPU goes")
    ap.add_argument("--sample", default=None, metavar="FILE",
                    help="also judge a verdict-sample run (benchmarks.diagnosis_agreement run --sample verdict)")
    a = ap.parse_args(argv)
    log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
    if a.trials:
        trials = [(t.rsplit(":", 1)[0], int(t.rsplit(":", 1)[1])) for t in a.trials]
        for r in time_trials(trials, log=log, warmup=trials[0], threads=a.threads, profile=a.profile):
            print(f"{r['case']} seed {r['seed']}: {r['cpu_s']:.2f} s CPU on {r['threads']} numba thread(s) "
                  f"(OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', 'unset')}), "
                  f"{'right' if r['correct'] else 'wrong'}; load average {os.getloadavg()[0]:.1f}")
            print(r.get("profile", ""), end="")
        return 0
    print(run(log=log, with_gap_timing=not a.no_gap_timing, with_memory=not (a.no_gap_timing or a.no_memory),
              sample=a.sample)["markdown"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
