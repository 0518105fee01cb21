"""Throughput of the RL environments (``make bench``, section (c)): env-steps/s of the Gymnasium vector env
(``gymnasium.make_vec("finkensim/Swarm-v0", num_envs=B)``, one compiled call per step for the B swarms) and of
the PettingZoo ParallelEnv (one swarm per env; B > 1 = B envs stepped one after another in Python), N = 10
copters, default scenario sensors on (sonars with error model and cross-talk, GMM ranging, IMU), the
cohesion task's reward included. env-steps/s = B · steps / time; copter-steps/s = N times that.

    python -m benchmarks.envs_bench            # prints the table alone
    python -m benchmarks.envs_bench --split    # where one vector-env step's time goes (B = 1024)
    python -m benchmarks.envs_bench --sensors  # its compiled step, one thread, with each sensor switched on in turn
"""
from __future__ import annotations

import sys

import numpy as np

ENV_N = 10
ENV_B = (1, 64, 1024)
PZ_MAX_B = 64   # PettingZoo rows beyond this take minutes of Python looping for nothing new


def _vector_env(b: int):
    """(vector env of B swarms, reset with seed 0; one fixed random action for every step)."""
    import gymnasium

    import finkensim.envs  # noqa: F401  (registers finkensim/Swarm-v0)

    env = gymnasium.make_vec("finkensim/Swarm-v0", num_envs=b, scenario={"copters": {"n": ENV_N}}, max_steps=10**9)
    env.reset(seed=0)
    return env, np.random.default_rng(0).uniform(-0.5, 0.5, size=env.action_space.shape).astype(np.float32)


def _vector_runner(b: int):
    env, act = _vector_env(b)

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


def markdown(rows: list[dict], vmas_rows: list[dict] = ()) -> str:
    """The (c) table; ``vmas_rows``: section (a)'s VMAS measurements at N = 10 of the same run (VMAS's own vectorized
    env on the comparison scenario: 4 rays per copter, no sensor errors, no reward task), shown next to the envs."""
    L = ["## (c) RL environments: N = 10, default sensors on, cohesion reward (benchmarks/envs_bench.py)", "",
         "| env | N | B | env-steps/s | copter-steps/s | threads |", "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "env_steps_per_s" in r:
            L.append(f"| {r['env']} | {r['N']} | {r['B']} | {r['env_steps_per_s']:,.0f} | "
                     f"{r['copter_steps_per_s']:,.0f} | {r['threads']} |")
        else:
            L.append(f"| {r['env']} | {r['N']} | {r['B']} | {r.get('error') or r.get('skipped')} | | |")
    for v in vmas_rows:
        L.append(f"| VMAS {v.get('vmas', '?')} env, comparison scenario (section (a)) | {v['N']} | {v['B']} | "
                 f"{v['env_steps_per_s']:,.0f} | {v['copter_steps_per_s']:,.0f} | {v.get('threads', '?')} |")
    if not vmas_rows:
        L.append("\nVMAS's own env: not measured in this run (`make bench-peers` installs it; section (a) runs it).")
    return "\n".join(L) + "\n"


def step_split(b: int = 1024, steps: int = 200) -> dict:
    """ms per vector-env step (wall clock, all threads) and the parts of it: the compiled world + sensor step
    (``Controlled.step``), the reward and the observation assembly; the rest is action clipping and Python."""
    import time

    env, act = _vector_env(b)
    for _ in range(20):  # compile; the copters reach the walls as in the throughput rows
        env.step(act)
    core = env.unwrapped.core
    spent = {"compiled step": 0.0, "reward": 0.0, "observation": 0.0}

    def timed(name, fn):
        def wrapped(*args, **kwargs):
            t0 = time.perf_counter()
            out = fn(*args, **kwargs)
            spent[name] += time.perf_counter() - t0
            return out
        return wrapped

    core.ctl.step = timed("compiled step", core.ctl.step)
    core.task.reward = timed("reward", core.task.reward)
    core.observe = timed("observation", core.observe)
    t0 = time.perf_counter()
    for _ in range(steps):
        env.step(act)
    total = time.perf_counter() - t0
    out = {"B": b, "env_steps_per_s": b * steps / total, "step_ms": 1e3 * total / steps}
    out.update({f"{k}_ms": 1e3 * v / steps for k, v in spent.items()})
    return out


SENSOR_SETS = (("world step alone", ()), ("+ sonar", ("sonar",)), ("+ ranging", ("ranging",)), ("+ IMU", ("imu",)),
               ("every sensor", ("sonar", "ranging", "imu")))


def sensor_split(b: int = 1024, steps: int = 20, warm: int = 100) -> dict[str, float]:
    """µs per env-step of the vector env's compiled step (``Controlled.step``, one thread, thread CPU time, best of 3)
    with the world step alone and with each sensor switched on (scenario ``enabled`` flags), N = 10, the benchmark's
    fixed random actions after ``warm`` steps (the copters then sit at the walls, as in the throughput rows)."""
    import time

    import numba

    from finkensim.envs.core import SwarmCore

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    out = {}
    try:
        for label, on in SENSOR_SETS:
            sc = {"copters": {"n": ENV_N}, **{k: {"enabled": k in on} for k in ("sonar", "ranging", "imu")}}
            core = SwarmCore(sc, n_envs=b, max_steps=10**9, pose=not on)
            core.set_seeds(0, None)
            core.reset()
            act = np.random.default_rng(0).uniform(-0.5, 0.5, size=(b, ENV_N, 2))
            buf = core.ctl.readings(b, ENV_N)  # as the env: one set of readings arrays, rewritten every step
            for _ in range(warm):
                core.state, _ = core.ctl.step(core.state, act, buf)
            best = np.inf
            for _ in range(3):
                t0 = time.thread_time()
                for _ in range(steps):
                    core.state, _ = core.ctl.step(core.state, act, buf)
                best = min(best, (time.thread_time() - t0) / (steps * b) * 1e6)
            out[label] = best
    finally:
        numba.set_num_threads(before)
    return out


if __name__ == "__main__":
    import numba

    if "--sensors" in sys.argv[1:]:
        r = sensor_split()
        base = r["world step alone"]
        for label, us in r.items():
            extra = f"  ({us - base:+.2f})" if label.startswith("+") else ""
            print(f"{label:18s} {us:6.2f} µs per env-step{extra}   (compiled step, one thread, N = {ENV_N}, B = 1024)")
    elif "--split" in sys.argv[1:]:
        r = step_split()
        print(f"vector env, N = {ENV_N}, B = {r['B']}: {r['env_steps_per_s']:,.0f} env-steps/s, {r['step_ms']:.2f} ms per "
              f"step: compiled step {r['compiled step_ms']:.2f}, reward {r['reward_ms']:.2f}, observation "
              f"{r['observation_ms']:.2f} ms (the rest: action clipping, Python)")
    else:
        rows = run(0.5, 3, lambda m: print(m, file=sys.stderr, flush=True), tuple(sorted({1, numba.get_num_threads()})))
        print(markdown(rows))
