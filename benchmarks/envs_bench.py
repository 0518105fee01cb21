"""Throughput of the RL environments (``make bench``, section (c)): env-steps/s of the Gymnasium vector env
(``gymnasium.make_vec("finkensim/Swarm-v0", num_envs=B)``, one compiled call per step for the B swarms) and of
the PettingZoo ParallelEnv (one swarm per env; B > 1 = B envs stepped one after another in Python), N = 10
copters, default scenario sensors on (sonars with error model and cross-talk, GMM ranging, IMU), the
cohesion task's reward included. env-steps/s = B · steps / time; copter-steps/s = N times that.

    python -m benchmarks.envs_bench            # prints the table alone
"""
from __future__ import annotations

import sys

import numpy as np

ENV_N = 10
ENV_B = (1, 64, 1024)
PZ_MAX_B = 64   # PettingZoo rows beyond this take minutes of Python looping for nothing new


def _vector_runner(b: int):
    import gymnasium

    import finkensim.envs  # noqa: F401  (registers finkensim/Swarm-v0)

    env = gymnasium.make_vec("finkensim/Swarm-v0", num_envs=b, scenario={"copters": {"n": ENV_N}}, max_steps=10**9)
    env.reset(seed=0)
    act = np.random.default_rng(0).uniform(-0.5, 0.5, size=env.action_space.shape).astype(np.float32)

    def run(T):
        for _ in range(T):
            env.step(act)
    return run


def _pz_runner(b: int):
    import finkensim.envs as fe

    envs = [fe.parallel_env(scenario={"copters": {"n": ENV_N}}, max_steps=10**9) for _ in range(b)]
    for i, e in enumerate(envs):
        e.reset(seed=i)
    rng = np.random.default_rng(0)
    acts = {a: rng.uniform(-0.5, 0.5, size=2).astype(np.float32) for a in envs[0].possible_agents}

    def run(T):
        for _ in range(T):
            for e in envs:
                e.step(acts)
    return run


def run(seconds: float, repeats: int, log, threads=(1, 2), bs=ENV_B) -> list[dict]:
    """Rows {env, N, B, env_steps_per_s, copter_steps_per_s, threads} (or {…, error})."""
    from .run import best_of_threads, measure, thread_variants

    rows = []
    for kind, make in (("gymnasium vector", _vector_runner), ("pettingzoo parallel", _pz_runner)):
        for b in bs:
            if kind.startswith("pettingzoo") and b > PZ_MAX_B:
                rows.append(dict(env=kind, N=ENV_N, B=b, skipped=f"B > {PZ_MAX_B}: one swarm per env, looped in Python"))
                continue
            try:
                fn = make(b)
                fn(2)
            except Exception as e:  # noqa: BLE001 - e.g. the [rl] extra is missing
                rows.append(dict(env=kind, N=ENV_N, B=b, error=f"{type(e).__name__}: {e}"))
                log(f"(c) {kind} B={b}: {rows[-1]['error']}")
                continue
            s, k, _ = best_of_threads(measure(thread_variants("env", fn, threads), seconds, repeats), "env")
            rows.append(dict(env=kind, N=ENV_N, B=b, env_steps_per_s=b / s, copter_steps_per_s=ENV_N * b / s,
                             threads=k))
            log(f"(c) {kind:20s} N={ENV_N} B={b:5d}  {b / s:12.0f} env-steps/s  ({k} threads)")
    return rows


def markdown(rows: list[dict]) -> str:
    L = ["## (c) RL environments: N = 10, default sensors on, cohesion reward (benchmarks/envs_bench.py)", "",
         "| env | N | B | env-steps/s | copter-steps/s | threads |", "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "env_steps_per_s" in r:
            L.append(f"| {r['env']} | {r['N']} | {r['B']} | {r['env_steps_per_s']:,.0f} | "
                     f"{r['copter_steps_per_s']:,.0f} | {r['threads']} |")
        else:
            L.append(f"| {r['env']} | {r['N']} | {r['B']} | {r.get('error') or r.get('skipped')} | | |")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    import numba

    rows = run(0.5, 3, lambda m: print(m, file=sys.stderr, flush=True), tuple(sorted({1, numba.get_num_threads()})))
    print(markdown(rows))
