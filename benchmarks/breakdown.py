"""Where the time of the full FINken step goes: ``python -m benchmarks.breakdown [--n 10 100]``.

Times each per-environment kernel of the closed loop on its own, single-threaded (a plain loop over
B environments, ``time.thread_time``, best of 5; compiled with ``error_model="numpy"`` like the engine's outlined copies of the
kernels, see :mod:`finkensim.swarm.kernel`), on states taken from a real run (the swarm after
100 steps, so plates swing and copters are spread). Reports µs per env-step and the share of the sum (markdown);
``make bench`` puts the N = 10 table in its report, beside the comparison workload's cost on one thread.

B defaults to 10 240 / N distinct environments (1024 at N = 10; at least 64), each timed only a few times: the ray casts branch on each environment's
geometry, and with few environments timed many times (B = 64, 20 repetitions) the CPU's branch predictor learns
them by heart — the sonar then measured 5.6 instead of 7.4–8.3 µs per env-step on the same states (the same 64 states
tiled 16 times over B = 1024 ran as fast as B = 64).
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from numba import njit

from finkensim.arena import walls_step_env
from finkensim.kernels.geometry import nearest_body_distance_within_env
from finkensim.sensors.imu import imu_env
from finkensim.sensors.sonar import N_SONARS, displaced_plates_env, down_env, ideal_env, sonar_env
from finkensim.swarm import ranging_env
from finkensim.kernels.cellgrid import engine_grid, env_grid
from finkensim.world import step_env


@njit(cache=True, error_model="numpy")
def t_world(w, cp, hp, geo, dt, grid, reps):
    B, N, _ = w.pos.shape
    dist_buf = np.empty(geo.seg_a.shape[0])
    gap = np.empty(N)
    cmd_v = np.zeros((N, 2))
    cmd_w = np.zeros(N)
    for _ in range(reps):
        for b in range(B):
            for n in range(N):
                cmd_v[n, 0] = 0.2 * np.cos(w.yaw[b, n])
                cmd_v[n, 1] = 0.2 * np.sin(w.yaw[b, n])
            step_env(w, b, cmd_v, cmd_w, (cp, hp, geo), dt, (dist_buf, gap), grid, env_grid(grid, b))


@njit(cache=True, error_model="numpy")
def t_nearest(pos, seg_a, seg_b, radius, cutoff, reps):
    out = np.empty(seg_a.shape[0])
    for _ in range(reps):
        for b in range(pos.shape[0]):
            nearest_body_distance_within_env(seg_a, seg_b, pos[b], radius, cutoff, out)


@njit(cache=True, error_model="numpy")
def t_hinges(theta, omega, integ, dist, hp, lever, dt, reps):
    th = theta.copy()
    om = omega.copy()
    ig = integ.copy()
    for _ in range(reps):
        for b in range(theta.shape[0]):
            for s in range(theta.shape[1]):  # restart from the recorded state each rep
                th[b, s] = theta[b, s]
                om[b, s] = omega[b, s]
                ig[b, s] = integ[b, s]
            walls_step_env(th[b], om[b], ig[b], dist[b], hp, lever, dt)


@njit(cache=True, error_model="numpy")
def t_sonar(pos, yaw, theta, plate_a, plate_b, normal, lever, width, length, sp, g, seed, reps, ideal_only):
    B, N, _ = pos.shape
    S = plate_a.shape[0]
    pa = np.empty((S, 2))
    pb = np.empty((S, 2))
    buf = np.empty((N, N_SONARS, 4))
    dist = np.empty((N, N_SONARS))
    kind = np.empty((N, N_SONARS), dtype=np.int64)
    hit = np.empty((N, N_SONARS, 2))
    slot = np.zeros(N, dtype=np.int64)
    out = np.empty((N, N_SONARS))
    for r in range(reps):
        for b in range(B):
            displaced_plates_env(theta[b], plate_a, plate_b, normal, lever, pa, pb)
            if ideal_only:
                ideal_env(pos[b], yaw[b], (pa, pb, width, length), sp, (buf, dist, kind, hit), g, env_grid(g, 0))
            else:
                sonar_env(pos[b], yaw[b], (pa, pb, width, length), sp, (seed, b, r), (buf, dist, kind, hit, slot),
                               out, g, env_grid(g, 0))


@njit(cache=True, error_model="numpy")
def t_down(B, N, sp, seed, reps):
    alt = np.full(N, sp.altitude)
    out = np.empty(N)
    for r in range(reps):
        for b in range(B):
            down_env(alt, sp, seed, b, r, out)


@njit(cache=True, error_model="numpy")
def t_ranging(pos, seed, p, reps):
    B, n, _ = pos.shape
    out = np.empty((n, n))
    beacons = np.empty((0, 2))
    for r in range(reps):
        for b in range(B):
            ranging_env(pos[b], np.zeros(n), beacons, seed, b, r, p, out)


@njit(cache=True, error_model="numpy")
def t_imu(acc, yaw, yaw_rate, bias, ip, seed, reps):
    B, N, _ = acc.shape
    oa = np.empty((N, 2))
    og = np.empty(N)
    for r in range(reps):
        for b in range(B):
            imu_env(acc[b], yaw[b], yaw_rate[b], bias[b], ip, seed, b, r, oa, og)


def _best(fn, args, reps, B, repeats=5):
    fn(*args, 1)  # compile / warm
    best = np.inf
    for _ in range(repeats):
        t0 = time.thread_time()
        fn(*args, reps)
        best = min(best, time.thread_time() - t0)
    return best / (reps * B) * 1e6  # µs per env-step


def breakdown(n: int, b: int = 1024, reps: int = 20, warm_steps: int = 100) -> dict:
    from finkensim.swarm import SwarmSim

    from .workloads import finken_config

    cfg = finken_config(n, b)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        sim = SwarmSim(cfg)
        st, _ = sim.rollout(sim.init(n_envs=b, seed=1), warm_steps, record=False)
        ws, world, sp, rp, ip = st.world, sim.world, sim.sonar, sim.ranging, sim.imu
    a = world.arena
    s = ws.copy()
    dist = np.empty((b, a.seg_a.shape[0]))
    cutoff = max(world.hinge_params.threshold, a.lever)  # as world.step_env
    for k in range(b):
        nearest_body_distance_within_env(a.seg_a, a.seg_b, s.pos[k], world.copter_params.radius, cutoff, dist[k])
    geo = (ws.pos, ws.yaw, ws.theta, a.plate_a, a.plate_b, a.normal, a.lever, a.width, a.length, sp,
           engine_grid(world.grid, 1, n), 1)
    rows = {
        "world step (move, contacts, plate distances, hinges)": _best(
            t_world, (s.arrays(), world.copter_params, world.hinge_params, world.geometry, world.dt,
                      engine_grid(world.grid, b, n)), reps, b),
        "  of which plate distances (segments near each copter)": _best(
            t_nearest, (ws.pos, a.seg_a, a.seg_b, world.copter_params.radius, cutoff), reps, b),
        "  of which hinge dynamics (S plates × substeps)": _best(
            t_hinges, (ws.theta, ws.omega, ws.integ, dist, world.hinge_params, a.lever, world.dt), reps, b),
        "sonar: displaced plates + raycast + error + cross-talk": _best(
            lambda *x: t_sonar(*x, False), geo, reps, b),
        "  of which ideal raycast (plates, net, circles)": _best(lambda *x: t_sonar(*x, True), geo, reps, b),
        "down sonar": _best(t_down, (b, n, sp, 1), reps, b),
        "ranging (N×N, mixture)": _best(t_ranging, (ws.pos, 1, rp.params), reps, b),
        "IMU": _best(t_imu, (ws.acc, ws.yaw, ws.yaw_rate, np.zeros((b, n, 3)), ip, 1), reps, b),
    }
    at_rest = float(np.mean((ws.theta == 0.0) & (ws.omega == 0.0)))
    return dict(N=n, B=b, us_per_env_step=rows, plates_at_rest=at_rest,
                plates_active=float(np.mean(dist < world.hinge_params.threshold)))


def markdown(r: dict, compare_us: float | None = None) -> str:
    """A :func:`breakdown` result as a markdown table (µs per env-step and share of each kernel, their sum); with
    ``compare_us`` (the comparison workload's µs per env-step on one thread, same N and B) also the ratio of the sum
    to it and the sum that 3× would allow."""
    us = r["us_per_env_step"]
    total = sum(v for k, v in us.items() if not k.startswith("  "))
    L = [f"Where the full workload's time goes (`python -m benchmarks.breakdown`; N = {r['N']}, B = {r['B']}, one "
         f"thread, each kernel timed alone on a settled swarm; plates within the hinge threshold "
         f"{100 * r['plates_active']:.0f} %, exactly at rest {100 * r['plates_at_rest']:.0f} %):", "",
         "| kernel | µs per env-step | share |", "|---|---:|---:|"]
    for k, v in us.items():
        sub = k.startswith("  ")
        L.append(f"| {'&nbsp;&nbsp;' * sub}{k.strip()} | {v:.2f} | {'' if sub else f'{100 * v / total:.1f} %'} |")
    L.append(f"| sum | {total:.2f} | {1e3 * total / r['N']:.0f} ns per copter-step |")
    if compare_us:
        L += ["", f"The comparison workload takes {compare_us:.2f} µs per env-step on one thread in this run: the sum "
              f"above is {total / compare_us:.1f}× that; 3× would allow {3 * compare_us:.2f} µs."]
    return "\n".join(L) + "\n"


def run(n: int = 10, b: int | None = None) -> dict:
    """:func:`breakdown` with the command line's defaults: B = 10 240 / N (at least 64), few repetitions."""
    b = b if b is not None else max(64, 10240 // n)
    return breakdown(n, b, reps=max(1, 2000 // (n * b) + 2))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[10, 100])
    ap.add_argument("--b", type=int, default=None, help="environments (default: 10240 // N, at least 64)")
    a = ap.parse_args(argv)
    for n in a.n:
        print(markdown(run(n, a.b)))


if __name__ == "__main__":
    main()
