"""``python -m benchmarks.run [--quick]`` (``make bench``): throughput, compile time, memory, scaling.

Prints one table and saves it as ``out/bench/bench.md`` and ``out/bench/bench.json``. Every figure
is measured in this run (ratios are only meaningful within one run: the machine is shared):

(a) **comparison workload** (``benchmarks.workloads``: 4 walls, 4 sonar rays per copter hitting
    walls and copters, pairwise distances, kinematic update, no noise) — finkensim's compiled rollout
    vs the plain vectorised NumPy version, and VMAS in the same run whenever ``make bench-peers`` has
    installed it in ``.venv-peers`` (each configuration right after finkensim's and NumPy's, in a subprocess of
    that interpreter; ``--peers-python`` names another one, ``--no-peers`` skips it);
(b) **full FINken workload** — ``finkensim.swarm`` when importable, else "n/a (finkensim.swarm
    missing)" plus the stand-in (``World.rollout`` + batched sensors);
for N ∈ {4, 10, 32, 100} copters × B ∈ {1, 64, 1024} environments;
(c) **RL environments** (``benchmarks.envs_bench``): env-steps/s of the Gymnasium vector env and the
    PettingZoo env at N = 10, B ∈ {1, 64, 1024}, sensors on;
(d) **the full workload against N** (``benchmarks.engine_scaling``): µs per copter-step of ``SwarmSim`` at the
    lab's density for N ∈ {10, 100, 1 000, 10 000}, with the engine's cell grid and (to 1 000) the brute force;
(e) **diagnosis** (``benchmarks.diagnosis``): CPU s of warm gap-validate trials, examples/gap_timing.py.

**Timing.** Each implementation is warmed up (compiled) first, the number of steps per timed call
is calibrated to ≈ ``--seconds``, then the implementations of one configuration are timed in turn,
``--repeats`` times interleaved, and the fastest call counts (the least disturbed by other jobs).
env-steps/s = B·T / time; copter-steps/s = N·B·T / time. finkensim's kernels run with 1 and with
all (2) numba threads and the faster counts (column "threads"), as VMAS's torch threads do in
``make bench-peers``: on a machine shared with other jobs a second thread can lose more to waiting
for a core than it gains. NumPy is single-threaded as it comes.

**JIT compile time**, separately, in subprocesses (``benchmarks.compile_probe``): *cold* = a fresh
empty NUMBA_CACHE_DIR, so the first call compiles and writes the cache; *warm* = the same directory
again, so the first call only loads the cache. Reported: import time and first-call time.

**Peak memory per environment** = tracemalloc's peak over building the workload (state, buffers,
outputs) plus one step, divided by B. NumPy arrays (also those passed to numba kernels) are traced;
memory that numba kernels allocate internally (per-environment work buffers inside ``prange``
bodies, at most a few KiB per environment here) is not; neither is memory shared by all
environments and built once (e.g. the ranging alias table, 2 MB). VMAS: ru_maxrss delta of a fresh
subprocess per configuration (torch's allocator is invisible to tracemalloc) — a different method,
so compare VMAS's memory column with care.

``--quick`` runs a tiny subset (a few seconds with a warm numba cache): workload (a) for N ∈ {4, 10}
× B ∈ {1, 64}, the scaling benchmark for N ∈ {10, 100}, no compile probes and no workloads (b)–(d).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

FULL_N = (4, 10, 32, 100)
FULL_B = (1, 64, 1024)
QUICK_N = (4, 10)
QUICK_B = (1, 64)
MAX_STEPS = 100_000
REPO = Path(__file__).resolve().parent.parent


# ---------------------------------------------------------------------------------------------
# timing and memory


def _time_call(fn, steps: int) -> float:
    t0 = time.perf_counter()
    fn(steps)
    return time.perf_counter() - t0


def measure(runners: dict, seconds: float, repeats: int) -> dict:
    """Seconds per step of each ``runners[name](T)`` (already warmed up): calibrate T per runner so
    one call takes ≈ ``seconds``, then ``repeats`` interleaved rounds; the fastest call counts."""
    steps = {}
    for name, fn in runners.items():
        # grow T until a call is long enough to extrapolate; min of two calls, so that one call that
        # waited for a core (other jobs, or a parallel kernel's worker thread) does not stop it early
        T = 1
        while True:
            t = min(_time_call(fn, T), _time_call(fn, T))
            if t >= seconds / 4 or T >= MAX_STEPS:
                break
            T = min(MAX_STEPS, T * 4)
        steps[name] = max(1, min(MAX_STEPS, int(T * seconds / max(t, 1e-9))))
    best = {name: np.inf for name in runners}
    for _ in range(repeats):
        for name, fn in runners.items():
            best[name] = min(best[name], _time_call(fn, steps[name]) / steps[name])
    return {name: dict(s_per_step=best[name], steps=steps[name]) for name in runners}


def thread_variants(name: str, fn, threads) -> dict:
    """``{name@k: run}`` for each numba thread count k (the fastest is reported, see module doc); each run restores
    the calling thread's numba thread count."""
    import numba

    def make(k):
        def run(T):
            before = numba.get_num_threads()
            numba.set_num_threads(k)
            try:
                fn(T)
            finally:  # the caller's (a notebook's, a test's) thread count is not ours to keep
                numba.set_num_threads(before)
        return run

    return {f"{name}@{k}": make(k) for k in threads}


def best_of_threads(m: dict, name: str) -> tuple[float, int, dict]:
    """(seconds per step, threads, {threads: steps/s factor}) of the fastest ``name@k`` in ``m``."""
    opts = {int(k.split("@")[1]): v for k, v in m.items() if k.startswith(name + "@")}
    k = min(opts, key=lambda t: opts[t]["s_per_step"])
    return opts[k]["s_per_step"], k, {str(t): 1.0 / v["s_per_step"] for t, v in opts.items()}


def peak_bytes(build, steps: int = 1) -> int:
    """tracemalloc peak (bytes) while building a workload with ``build()`` and running ``steps`` steps."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    try:
        wl = build()
        wl.run(steps)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


# ---------------------------------------------------------------------------------------------
# workloads


def peer_python(path: str | None) -> tuple[str | None, str]:
    """(interpreter, why): the Python that has torch and vmas (``path``, else ``.venv-peers/bin/python`` of the
    repository), or (None, the reason it cannot be used)."""
    py = Path(path) if path else REPO / ".venv-peers" / "bin" / "python"
    if not py.exists():
        return None, f"{py} not found (run `make bench-peers` to install VMAS)"
    p = subprocess.run([str(py), "-c", "import torch, vmas"], capture_output=True, text=True, cwd=REPO)
    if p.returncode != 0:
        last = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"exit {p.returncode}"
        return None, f"{py} cannot import torch and vmas: {last}"
    return str(py), ""


def bench_compare(ns, bs, seconds, repeats, log, threads=(1, 2), peers_py: str | None = None) -> list[dict]:
    from .peers.run_vmas import measure_config
    from .workloads import CompareWorkload

    rows = []
    for n in ns:
        for b in bs:
            wls = {impl: CompareWorkload(n, b, impl) for impl in ("finkensim", "numpy")}
            for wl in wls.values():
                wl.run(1)  # compile / first touch
            runners = dict(thread_variants("finkensim", wls["finkensim"].run, threads), numpy=wls["numpy"].run)
            m = measure(runners, seconds, repeats)
            row = dict(N=n, B=b)
            for impl in wls:
                if impl == "finkensim":
                    s, k, by = best_of_threads(m, impl)
                    extra = dict(threads=k, steps_per_s_by_threads={t: b * v for t, v in by.items()})
                else:
                    s, extra = m[impl]["s_per_step"], dict(threads=1)
                row[impl] = dict(env_steps_per_s=b / s, copter_steps_per_s=n * b / s, **extra,
                                 peak_bytes_per_env=peak_bytes(lambda impl=impl: CompareWorkload(n, b, impl)) / b)
            row["ratio_numpy"] = row["finkensim"]["env_steps_per_s"] / row["numpy"]["env_steps_per_s"]
            if peers_py:
                v = measure_config(peers_py, n, b, max(1.0, 4 * seconds), threads, cwd=str(REPO))
                if "error" in v:
                    row["vmas_error"] = v["error"]
                else:
                    row["vmas"] = v
                    row["ratio_vmas"] = row["finkensim"]["env_steps_per_s"] / v["env_steps_per_s"]
            rows.append(row)
            log(f"(a) N={n:4d} B={b:5d}  finkensim {row['finkensim']['env_steps_per_s']:12.0f}  "
                f"numpy {row['numpy']['env_steps_per_s']:10.0f} env-steps/s  (x{row['ratio_numpy']:.1f})"
                + (f"  vmas {row['vmas']['env_steps_per_s']:10.0f} (x{row['ratio_vmas']:.0f})" if "vmas" in row else ""))
    return rows


def bench_finken(ns, bs, seconds, repeats, log, threads=(1, 2)) -> tuple[list[dict], str]:
    import warnings

    from .workloads import FinkenStandIn, FinkenSwarm, swarm_status

    status = swarm_status()
    label = "finkensim.swarm" if status is None else "stand-in: World.rollout + batched sensors"
    cls = FinkenSwarm if status is None else FinkenStandIn
    rows = []
    for n in ns:
        for b in bs:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                try:
                    wl = cls(n, b)
                    wl.run(1)
                except Exception as e:  # noqa: BLE001 - one failing configuration must not hide the rest
                    rows.append(dict(N=n, B=b, impl=label, error=f"{type(e).__name__}: {e}"))
                    log(f"(b) N={n:4d} B={b:5d}  failed: {type(e).__name__}: {e}")
                    continue
                s, k, by = best_of_threads(measure(thread_variants("finken", wl.run, threads), seconds, repeats),
                                           "finken")
                mem = peak_bytes(lambda: cls(n, b)) / b
            rows.append(dict(N=n, B=b, impl=label, env_steps_per_s=b / s, copter_steps_per_s=n * b / s, threads=k,
                             steps_per_s_by_threads={t: b * v for t, v in by.items()}, peak_bytes_per_env=mem))
            log(f"(b) N={n:4d} B={b:5d}  {rows[-1]['env_steps_per_s']:12.0f} env-steps/s  [{label}]")
    return rows, status or ""


def compile_probes(workloads, log) -> list[dict]:
    """Cold (fresh empty cache dir) then warm (same dir) first-call times, in subprocesses."""
    out = []
    root = Path(__file__).resolve().parent.parent
    for wl in workloads:
        with tempfile.TemporaryDirectory(prefix="finkensim-numba-cold-") as cache:
            row = dict(workload=wl)
            for kind in ("cold", "warm"):
                env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(root))
                t0 = time.perf_counter()
                p = subprocess.run([sys.executable, "-m", "benchmarks.compile_probe", wl], capture_output=True,
                                   text=True, cwd=root, env=env)
                wall = time.perf_counter() - t0
                if p.returncode != 0:
                    row[kind] = dict(error=(p.stderr.strip().splitlines() or ["failed"])[-1])
                else:
                    row[kind] = dict(json.loads(p.stdout.strip().splitlines()[-1]), process_s=wall)
                log(f"compile {wl} {kind}: {row[kind]}")
            out.append(row)
    return out


# ---------------------------------------------------------------------------------------------
# report


def _rate(x) -> str:
    if x is None:
        return "—"
    if x >= 1e6:
        return f"{x / 1e6:.2f} M"
    if x >= 1e4:
        return f"{x / 1e3:.0f} k"
    if x >= 1e3:
        return f"{x / 1e3:.1f} k"
    return f"{x:.1f}"


def _mem(b) -> str:
    if b is None:
        return "—"
    if b >= 1 << 20:
        return f"{b / (1 << 20):.1f} MiB"
    return f"{b / 1024:.1f} KiB"


def _ratio(x) -> str:
    return "—" if x is None else (f"{x:,.0f}×" if x >= 100 else f"{x:.1f}×")


def _find(rows, **key):
    for r in rows or ():
        if all(r.get(k) == v for k, v in key.items()) and "error" not in r and "skipped" not in r:
            return r
    return None


def targets(res: dict) -> list[dict]:
    """The project's performance targets checked against this run's figures: rows {target, measured, met}, with
    measured None (and met None) when this run did not measure it (``--quick``, skipped section, VMAS missing)."""
    rows = []

    def add(target, value, fmt, ok):
        rows.append(dict(target=target, measured=None if value is None else fmt.format(value),
                         met=None if value is None else bool(ok(value))))

    # issue 43 retired "full / comparison ≤ 3×" and "cold JIT ≤ 5 s" and set these (docs/performance.md)
    cmp10 = {b: _find(res.get("compare"), N=10, B=b) for b in (1, 1024)}
    for b, need in ((1024, 40), (1, 5000)):
        r = cmp10[b]
        add(f"comparison workload ≥ {need:,}× VMAS (N = 10, B = {b})", r.get("ratio_vmas") if r else None,
            "{:,.0f}×", lambda x, need=need: x >= need)
    r = cmp10[1024]
    add("comparison workload ≥ 15× plain NumPy (N = 10, B = 1024)", r["ratio_numpy"] if r else None, "{:.1f}×",
        lambda x: x >= 15)
    comp = {c["workload"]: c for c in res.get("compile") or () if "error" not in c["cold"] and "error" not in c["warm"]}
    fk = comp.get("finken")
    add("warm (cached) first call, full workload ≤ 1 s", fk["warm"]["first_call_s"] if fk else None, "{:.2f} s",
        lambda x: x <= 1)
    es = res.get("engine_scaling")
    add("full workload cost per copter-step flat within ±30 % from N = 10 to 10 000 (engine, fixed density)",
        es["spread"] * 100 if es else None, "±{:.0f} %", lambda x: x <= 30)
    env = _find(res.get("envs"), env="gymnasium vector", B=1024)
    add("Gymnasium vector env ≥ 100 k env-steps/s (N = 10, B = 1024, sensors on)",
        env["env_steps_per_s"] if env else None, "{:,.0f}", lambda x: x >= 1e5)
    return rows


def report(res: dict) -> str:
    L = []
    meta = res["meta"]
    L.append("# finkensim benchmark")
    L.append("")
    L.append(f"{meta['time']} · Python {meta['python']} · NumPy {meta['numpy']} · numba {meta['numba']} "
             f"({meta['numba_threads']} threads) · {meta['cpus']} CPUs · load average {meta['load_start']} → "
             f"{meta['load_end']}{' · QUICK' if meta['quick'] else ''}")
    L.append("")
    peers = res.get("peers")  # {"python": interpreter or None, "why": reason when None}
    L.append("## (a) Comparison workload: 4 walls, 4 sonar rays/copter (walls + copters), pairwise distances, "
             "kinematic update, no noise")
    L.append("")
    vrows = [r["vmas"] for r in res["compare"] if "vmas" in r]
    if vrows:
        L.append(f"VMAS {vrows[0].get('vmas', '?')} on torch {vrows[0].get('torch', '?')} (best of torch threads "
                 f"{'/'.join(map(str, meta['threads']))}), measured in this run right after finkensim on each row.")
    else:
        L.append(f"VMAS: not measured ({peers.get('why') if peers else 'skipped'}).")
    L.append("")
    L.append("| N | B | finkensim env-steps/s | finkensim copter-steps/s | NumPy env-steps/s | VMAS env-steps/s | "
             "finkensim / NumPy | finkensim / VMAS | threads finkensim / VMAS | mem/env finkensim | mem/env NumPy | "
             "mem/env VMAS |")
    L.append("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in res["compare"]:
        f, npy = r["finkensim"], r["numpy"]
        v = r.get("vmas")
        L.append(f"| {r['N']} | {r['B']} | {_rate(f['env_steps_per_s'])} | {_rate(f['copter_steps_per_s'])} | "
                 f"{_rate(npy['env_steps_per_s'])} | {_rate(v['env_steps_per_s']) if v else '—'} | "
                 f"{_ratio(r['ratio_numpy'])} | {_ratio(r.get('ratio_vmas'))} | "
                 f"{f['threads']} / {v.get('threads', '?') if v else '—'} | {_mem(f['peak_bytes_per_env'])} | "
                 f"{_mem(npy['peak_bytes_per_env'])} | {_mem(v['peak_bytes_per_env']) if v else '—'} |")
    L.append("")
    L.append("## (b) Full FINken workload: 16-plate bending walls, sonars with error model and cross-talk, "
             "2.5 m GMM ranging (K=100), IMU, attraction–repulsion")
    L.append("")
    fk = res.get("finken")
    if fk is None:
        L.append("skipped (--quick)")
    else:
        if fk["status"]:
            L.append(f"finkensim.swarm: n/a ({fk['status']}). Rows below: the stand-in "
                     "(World.rollout with the random-walk controller, then the batched sensors over the "
                     "trajectory; open loop).")
            L.append("")
        L.append("| N | B | env-steps/s | copter-steps/s | threads | mem/env | implementation |")
        L.append("|---:|---:|---:|---:|---:|---:|---|")
        for r in fk["rows"]:
            if "error" in r:
                L.append(f"| {r['N']} | {r['B']} | error | | | | {r['error']} |")
            else:
                L.append(f"| {r['N']} | {r['B']} | {_rate(r['env_steps_per_s'])} | {_rate(r['copter_steps_per_s'])} | "
                         f"{r['threads']} | {_mem(r['peak_bytes_per_env'])} | {r['impl']} |")
    L.append("")
    if res.get("breakdown"):
        from .breakdown import markdown

        by = (_find(res.get("compare"), N=10, B=res["breakdown"]["B"]) or {}).get("finkensim", {})
        one = by.get("steps_per_s_by_threads", {}).get("1")  # env-steps/s on one thread
        L.append(markdown(res["breakdown"], 1e6 / one if one else None))
    if res.get("envs"):
        from .envs_bench import markdown

        vmas = [r["vmas"] for r in res.get("compare", []) if r["N"] == 10 and "vmas" in r]
        L.append(markdown(res["envs"], vmas))
    L.append("## JIT compile time (subprocess; cold = fresh empty NUMBA_CACHE_DIR, warm = cache hit)")
    L.append("")
    if not res.get("compile"):
        L.append("skipped (--quick)" if meta["quick"] else "skipped (--no-compile)")
    else:
        L.append("| workload | import (s) | cold first call (s) | warm first call (s) | cold process (s) | warm process (s) |")
        L.append("|---|---:|---:|---:|---:|---:|")
        for r in res["compile"]:
            c, w = r["cold"], r["warm"]
            if "error" in c or "error" in w:
                L.append(f"| {r['workload']} | error: {c.get('error') or w.get('error')} | | | | |")
                continue
            L.append(f"| {r['workload']} | {w['import_s']:.2f} | {c['first_call_s']:.2f} | {w['first_call_s']:.2f} | "
                     f"{c['process_s']:.1f} | {w['process_s']:.1f} |")
        for r in res["compile"]:
            prof = r["cold"].get("profile")
            if not prof:
                continue
            L.append("")
            L.append(f"Where the cold compile of `{r['workload']}` goes (numba compile events, `finkensim.compiletime`; "
                     "own = minus the kernels it compiled in turn):")
            L.append("")
            L.append("| kernel | seconds | own seconds |")
            L.append("|---|---:|---:|")
            for k in prof:
                L.append(f"| {'&nbsp;&nbsp;' * k['depth']}{k['name']} | {k['seconds']:.2f} | {k['own_seconds']:.2f} |")
    L.append("")
    for section in ("scaling", "diagnosis"):
        if res.get(section):
            L.append(res[section]["markdown"])
    es = res.get("engine_scaling")
    if es:
        L.append("")
        L.append(es["markdown"])
    L.append("")
    L.append("## Targets (from this run)")
    L.append("")
    L.append("| target | measured | met |")
    L.append("|---|---:|---|")
    for t in targets(res):
        met = "not measured" if t["met"] is None else ("yes" if t["met"] else "**no**")
        L.append(f"| {t['target']} | {t['measured'] or '—'} | {met} |")
    L.append("")
    L.append("Methods: see `benchmarks/run.py` (timing: best of interleaved repeats; memory: tracemalloc peak "
             "over build + 1 step ÷ B, kernel-internal numba buffers not traced; VMAS memory: ru_maxrss delta).")
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="finkensim benchmarks (make bench)")
    ap.add_argument("--quick", action="store_true", help="tiny subset, a few seconds")
    ap.add_argument("--out", default="out/bench", help="output directory (bench.md, bench.json, scaling.png, engine_scaling.png)")
    ap.add_argument("--peers-python", default=None,
                    help="Python with torch and vmas (default: .venv-peers/bin/python, from `make bench-peers`)")
    ap.add_argument("--no-peers", action="store_true", help="skip VMAS")
    ap.add_argument("--seconds", type=float, default=None, help="target seconds per timed call")
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--no-compile", action="store_true", help="skip the cold/warm JIT probes")
    ap.add_argument("--no-scaling", action="store_true", help="skip benchmarks/scaling.py")
    ap.add_argument("--no-finken", action="store_true", help="skip workload (b)")
    ap.add_argument("--no-envs", action="store_true", help="skip (c), the RL environments")
    ap.add_argument("--no-engine-scaling", action="store_true", help="skip (d), the full workload against N")
    ap.add_argument("--no-diagnosis", action="store_true", help="skip (e), the diagnosis")
    a = ap.parse_args(argv)

    import numba

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    seconds = a.seconds or (0.05 if a.quick else 0.25)
    repeats = a.repeats or (2 if a.quick else 3)
    ns, bs = (QUICK_N, QUICK_B) if a.quick else (FULL_N, FULL_B)

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    meta = dict(time=time.strftime("%Y-%m-%d %H:%M:%S"), python=platform.python_version(), numpy=np.__version__,
                numba=numba.__version__, numba_threads=numba.get_num_threads(), cpus=os.cpu_count(),
                load_start=" ".join(f"{x:.2f}" for x in os.getloadavg()), quick=a.quick, seconds=seconds,
                repeats=repeats, numba_cache_dir=os.environ.get("NUMBA_CACHE_DIR", ""))
    res: dict = dict(meta=meta)
    max_threads = numba.get_num_threads()
    threads = tuple(sorted({1, max_threads}))
    meta["threads"] = list(threads)
    peers_py, why = (None, "--no-peers") if a.no_peers else peer_python(a.peers_python)
    res["peers"] = dict(python=peers_py, why=why)
    if peers_py is None:
        log(f"VMAS not measured: {why}")
    res["compare"] = bench_compare(ns, bs, seconds, repeats, log, threads, peers_py)
    if not a.quick and not a.no_finken:
        rows, status = bench_finken(ns, bs, seconds, repeats, log, threads)
        res["finken"] = dict(rows=rows, status=status)
        if not status:  # where its µs go, kernel by kernel (one thread)
            from . import breakdown

            res["breakdown"] = breakdown.run(10)
    if not a.quick and not a.no_envs:
        from . import envs_bench

        res["envs"] = envs_bench.run(seconds, repeats, log, threads)
    if not a.quick and not a.no_compile:
        probes = ["compare"] + ([] if a.no_finken else ["finken"])
        res["compile"] = compile_probes(probes, log)
    if not a.no_scaling:
        from . import scaling

        res["scaling"] = scaling.run(quick=a.quick, out_dir=out, log=log)
    if not a.quick and not a.no_engine_scaling:
        from . import engine_scaling

        numba.set_num_threads(1)
        res["engine_scaling"] = engine_scaling.run(log=log, out_dir=out)
    numba.set_num_threads(max_threads)
    if not a.quick and not a.no_diagnosis:
        from . import diagnosis
        res["diagnosis"] = diagnosis.run(log=log)
    meta["load_end"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    md = report(res)
    (out / "bench.md").write_text(md)
    (out / "bench.json").write_text(json.dumps(res, indent=1, default=str))
    print(md)
    print(f"saved {out / 'bench.md'} and {out / 'bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
