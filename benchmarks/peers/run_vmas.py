"""VMAS on the comparison workload: env-steps/s and peak memory per environment, as JSON.

``python -m benchmarks.peers.run_vmas [--quick] --out out/bench/peers.json`` (``make bench-peers``).
Needs torch and vmas (``.venv-peers``), not finkensim. Each (N, B) configuration runs in a fresh
subprocess so that its peak memory is measurable: peak bytes = ru_maxrss at the end − RSS just
before the environment is built (resource.getrusage / /proc/self/statm; torch allocations are
invisible to tracemalloc), divided by B. Timing: 3 warm-up steps, then steps are repeated until
``--seconds`` have passed (at least 2); one step = controller(obs) → env.step(actions). Each
configuration runs with torch.set_num_threads(1) and (2) and the faster counts: on a machine
shared with other jobs torch's spinning worker threads can make 2 threads 3× slower than 1.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

FULL_N = (4, 10, 32, 100)
FULL_B = (1, 64, 1024)


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def run_one(n: int, b: int, seconds: float, threads: int | None = None) -> dict:
    import torch
    import vmas
    from vmas import make_env

    from .vmas_scenario import Scenario, controller

    if threads:
        torch.set_num_threads(threads)
    rss0 = _rss_bytes()
    env = make_env(Scenario(), num_envs=b, device="cpu", continuous_actions=True, clamp_actions=True, seed=0,
                   n_agents=n)
    obs = env.reset()
    with torch.no_grad():
        for _ in range(3):
            obs, _, _, _ = env.step(controller(obs, n))
        steps = 0
        t0 = time.perf_counter()
        while True:
            obs, _, _, _ = env.step(controller(obs, n))
            steps += 1
            el = time.perf_counter() - t0
            if steps >= 2 and el >= seconds:
                break
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - rss0
    return dict(N=n, B=b, steps=steps, seconds=el, env_steps_per_s=steps * b / el,
                copter_steps_per_s=steps * b * n / el, peak_bytes_per_env=max(peak, 0) / b,
                torch=torch.__version__, vmas=getattr(vmas, "__version__", "?"), threads=torch.get_num_threads())


def measure_config(python: str, n: int, b: int, seconds: float, threads=(1, 2), cwd: str | None = None) -> dict:
    """VMAS on (N, B) with each torch thread count in ``threads``, each in a fresh subprocess of the interpreter
    ``python`` (one that has torch and vmas): the fastest result (with ``by_threads``), or a dict with ``error``."""
    tries = []
    for th in threads:
        cmd = [python, "-m", "benchmarks.peers.run_vmas", "--one", str(n), str(b), "--seconds", str(seconds),
               "--threads", str(th)]
        p = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
        if p.returncode != 0:
            print(f"vmas N={n} B={b} threads={th}: failed\n{p.stderr[-2000:]}", file=sys.stderr)
            tries.append(dict(N=n, B=b, threads=th,
                              error=p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "failed"))
            continue
        tries.append(json.loads(p.stdout.strip().splitlines()[-1]))
    ok = [r for r in tries if "error" not in r]
    if not ok:
        return tries[-1]
    r = dict(max(ok, key=lambda r: r["env_steps_per_s"]))
    r["by_threads"] = {str(t["threads"]): t["env_steps_per_s"] for t in ok}
    return r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N=10, B in {1, 64}, 0.3 s each")
    ap.add_argument("--out", default="out/bench/peers.json")
    ap.add_argument("--seconds", type=float, default=None, help="timed seconds per configuration")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2],
                    help="torch thread counts to try per configuration; the fastest is reported")
    ap.add_argument("--one", nargs=2, type=int, metavar=("N", "B"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.one:
        print(json.dumps(run_one(a.one[0], a.one[1], a.seconds or 2.0, a.threads[0])))
        return 0
    configs = [(10, 1), (10, 64)] if a.quick else [(n, b) for n in FULL_N for b in FULL_B]
    seconds = a.seconds or (0.3 if a.quick else 2.0)
    results = []
    for n, b in configs:
        r = measure_config(sys.executable, n, b, seconds, a.threads)
        results.append(r)
        if "error" not in r:
            print(f"vmas N={n:4d} B={b:5d}: {r['env_steps_per_s']:12.1f} env-steps/s  "
                  f"{r['peak_bytes_per_env'] / 1024:10.1f} KiB/env  (best of torch threads {r['by_threads']})",
                  flush=True)
    meta = dict(peer="vmas", python=platform.python_version(), machine=platform.machine(), cpus=os.cpu_count(),
                time=time.strftime("%Y-%m-%dT%H:%M:%S"), quick=a.quick)
    ok = [r for r in results if "error" not in r]
    if ok:
        meta.update(torch=ok[0]["torch"], vmas=ok[0]["vmas"], threads="best of " + "/".join(map(str, a.threads)))
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    with open(a.out, "w") as f:
        json.dump(dict(meta=meta, results=results), f, indent=1)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
