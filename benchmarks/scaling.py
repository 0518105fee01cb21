"""Scaling: cost per copter-step of range-limited work at fixed density, brute force vs cell grid.

``python -m benchmarks.scaling [--quick]`` (also part of ``make bench``). One environment, one
thread (no ``prange``: the figure is the thread's CPU time per copter-step, ``time.thread_time``), N = 10 … 10 000 copters at a fixed
density — the arena grows with N, ``AREA_PER_COPTER`` = 2 m² per copter, aspect 3 : 4 like the
SwarmLab (N = 10: 3.9 m × 5.2 m; N = 10 000: 122 m × 163 m). Copters start uniformly at random and
drift (constant velocity, reflected at the walls), so every step rebuilds the grid. Two tasks, each
timed including everything it needs per step (move + grid build for the grid variants):

- **pairs within 2.5 m** (the ranging range): for each copter, the number of copters within 2.5 m
  and the sum of their distances (what a range-limited sensor or a repulsion term consumes).
  Brute force: all N − 1 others. Grid: cells of 2.5 m, neighbour query (3 rows, each trimmed to the disc's chord).
- **sonar raycasts**: 4 rays per copter (0°, 90°, 180°, 270° from its heading), nearest of the
  arena boundary and the other copters' circles (radius 0.15 m), no echo beyond 3 m. Brute force:
  every other copter per ray. Grid: the same grid; the copters within 3 m + radius of the sonar
  are scanned once per copter and tested against its 4 rays (``raycast_fan_env``).

Both variants give identical results (checked on every run). The goal: grid cost per copter-step
flat within ±30 % from N = 10 to N = 10 000 (the spread is reported); brute force grows ∝ N.
Writes the log-log figure ``scaling.png`` into the output directory.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from numba import njit

from finkensim.kernels.cellgrid import GridSpec, build_env, grid_spec, query_env, raycast_fan_env
from finkensim.kernels.cellgrid_batch import neighbour_counts
from finkensim.kernels.geometry import ray_circle
from finkensim.kernels.raycast import box_exit
from benchmarks.plotting import loglog_figure

AREA_PER_COPTER = 2.0  # m² per copter
RANGE = 2.5  # m, ranging range
CELL = 2.5  # m, grid cell side = the query range (measured fastest here among 0.83, 1.25 and 2.5 m)
SONAR_RANGE = 3.0  # m
RADIUS = 0.15  # m
SPEED = 0.3  # m/s drift
DT = 0.05  # s
FULL_N = (10, 32, 100, 316, 1000, 3162, 10000)
QUICK_N = (10, 100)


def arena_for(n: int) -> tuple[float, float]:
    area = AREA_PER_COPTER * n
    return math.sqrt(area * 3.0 / 4.0), math.sqrt(area * 4.0 / 3.0)


@njit(cache=True, inline="always")
def _move(pos, vel, width, length):
    for i in range(pos.shape[0]):
        x = pos[i, 0] + vel[i, 0] * DT
        if x < 0.0 or x > width:
            vel[i, 0] = -vel[i, 0]
            x = -x if x < 0.0 else 2.0 * width - x
        y = pos[i, 1] + vel[i, 1] * DT
        if y < 0.0 or y > length:
            vel[i, 1] = -vel[i, 1]
            y = -y if y < 0.0 else 2.0 * length - y
        pos[i, 0] = x
        pos[i, 1] = y


@njit(cache=True, inline="always")
def _ray_dirs(yaw, dirs):
    c = np.cos(yaw)
    s = np.sin(yaw)
    dirs[0, 0], dirs[0, 1] = c, s
    dirs[1, 0], dirs[1, 1] = -s, c
    dirs[2, 0], dirs[2, 1] = -c, -s
    dirs[3, 0], dirs[3, 1] = s, -c


@njit(cache=True)
def pairs_brute(pos, vel, width, length, r, n_steps, count, acc):
    N = pos.shape[0]
    r2 = r * r
    for _ in range(n_steps):
        _move(pos, vel, width, length)
        for i in range(N):
            c = 0
            a = 0.0
            qx = pos[i, 0]
            qy = pos[i, 1]
            for j in range(N):
                dx = pos[j, 0] - qx
                dy = pos[j, 1] - qy
                d2 = dx * dx + dy * dy
                if d2 <= r2 and j != i:
                    c += 1
                    a += np.sqrt(d2)
            count[i] = c
            acc[i] = a


@njit(cache=True)
def pairs_grid(pos, vel, width, length, r, n_steps, x0, y0, inv_cell, nx, ny, count, acc):
    N = pos.shape[0]
    cell_start = np.empty(nx * ny + 1, dtype=np.int64)
    order = np.empty(N, dtype=np.int64)
    spos = np.empty((N, 2))
    cell_of = np.empty(N, dtype=np.int64)
    idx = np.empty(N, dtype=np.int64)
    d2 = np.empty(N)
    for _ in range(n_steps):
        _move(pos, vel, width, length)
        build_env(pos, (x0, y0, inv_cell, nx, ny), cell_start, order, spos, cell_of)
        for s in range(N):  # queries in cell order: neighbouring queries share cells (cache)
            i = order[s]
            n = query_env(spos[s, 0], spos[s, 1], r, i, (x0, y0, inv_cell, nx, ny), cell_start, order, spos, idx, d2)
            a = 0.0
            for k in range(n):
                a += np.sqrt(d2[k])
            count[i] = n
            acc[i] = a


@njit(cache=True)
def sonar_brute(pos, vel, yaw, width, length, n_steps, out):
    N = pos.shape[0]
    dirs = np.empty((4, 2))
    for _ in range(n_steps):
        _move(pos, vel, width, length)
        for i in range(N):
            _ray_dirs(yaw[i], dirs)
            ox = pos[i, 0]
            oy = pos[i, 1]
            for k in range(4):
                best = box_exit(ox, oy, dirs[k, 0], dirs[k, 1], width, length)
                for j in range(N):
                    if j != i:
                        t = ray_circle(ox, oy, dirs[k, 0], dirs[k, 1], pos[j, 0], pos[j, 1], RADIUS, False)
                        if t < best:
                            best = t
                out[i, k] = min(best, SONAR_RANGE)


@njit(cache=True)
def sonar_grid(pos, vel, yaw, width, length, n_steps, x0, y0, inv_cell, nx, ny, out):
    N = pos.shape[0]
    cell_start = np.empty(nx * ny + 1, dtype=np.int64)
    order = np.empty(N, dtype=np.int64)
    spos = np.empty((N, 2))
    cell_of = np.empty(N, dtype=np.int64)
    dirs = np.empty((4, 2))
    ts = np.empty(4)
    js = np.empty(4, dtype=np.int64)
    spec = GridSpec(x0, y0, 1.0 / inv_cell, inv_cell, nx, ny)
    for _ in range(n_steps):
        _move(pos, vel, width, length)
        build_env(pos, (x0, y0, inv_cell, nx, ny), cell_start, order, spos, cell_of)
        for s in range(N):
            i = order[s]
            _ray_dirs(yaw[i], dirs)
            ox = spos[s, 0]
            oy = spos[s, 1]
            raycast_fan_env(ox, oy, dirs, SONAR_RANGE, RADIUS, i, spec, (cell_start, order, spos), ts, js)
            for k in range(4):
                out[i, k] = min(min(box_exit(ox, oy, dirs[k, 0], dirs[k, 1], width, length), ts[k]), SONAR_RANGE)


def _scene(n: int, seed: int = 0):
    w, length = arena_for(n)
    rng = np.random.default_rng(seed)
    pos = np.stack([rng.uniform(0, w, n), rng.uniform(0, length, n)], -1)
    ang = rng.uniform(-np.pi, np.pi, n)
    vel = SPEED * np.stack([np.cos(ang), np.sin(ang)], -1)
    yaw = rng.uniform(-np.pi, np.pi, n)
    return w, length, pos, vel, yaw


def _timed(fn, args_of, seconds: float, repeats: int) -> tuple[float, int]:
    """Best CPU seconds per step of ``fn(*args_of(T))`` with T calibrated to ≈ seconds per call.

    CPU time of this thread (``time.thread_time``; the kernels are single-threaded), so time spent
    waiting for a core while other jobs run is not counted."""
    T = 1
    while True:
        t0 = time.thread_time()
        fn(*args_of(T))
        el = time.thread_time() - t0
        if el >= seconds / 4 or T >= 1 << 20:
            break
        T *= 4
    T = max(1, int(T * seconds / max(el, 1e-9)))
    best = math.inf
    for _ in range(repeats):
        t0 = time.thread_time()
        fn(*args_of(T))
        best = min(best, (time.thread_time() - t0) / T)
    return best, T


def run(quick: bool = False, out_dir: str | Path = "out/bench", log=print, seconds: float | None = None,
        repeats: int | None = None) -> dict:
    """Measure every N; returns rows, the grid's spread and a markdown table; writes scaling.png."""
    ns = QUICK_N if quick else FULL_N
    seconds = seconds or (0.01 if quick else 0.05)
    repeats = repeats or (1 if quick else 7)
    rows = []
    for n in ns:
        w, length, pos0, vel0, yaw = _scene(n)
        spec = grid_spec(w, length, CELL)
        g = (spec.x0, spec.y0, spec.inv_cell, spec.nx, spec.ny)
        # correctness on the same scene: grid == brute force
        cb, ab = np.empty(n, dtype=np.int64), np.empty(n)
        cg, ag = np.empty(n, dtype=np.int64), np.empty(n)
        pairs_brute(pos0.copy(), vel0.copy(), w, length, RANGE, 1, cb, ab)
        pairs_grid(pos0.copy(), vel0.copy(), w, length, RANGE, 1, *g, cg, ag)
        sb, sg = np.empty((n, 4)), np.empty((n, 4))
        sonar_brute(pos0.copy(), vel0.copy(), yaw, w, length, 1, sb)
        sonar_grid(pos0.copy(), vel0.copy(), yaw, w, length, 1, *g, sg)
        if not (np.array_equal(cb, cg) and np.allclose(ab, ag, rtol=1e-12) and np.array_equal(sb, sg)):
            raise AssertionError(f"cell grid disagrees with brute force at N={n}")
        in_sonar_range = neighbour_counts(pos0[None], SONAR_RANGE + RADIUS, spec)[0]
        row = dict(N=n, width=w, length=length, cells=spec.n_cells, neighbours_per_copter=float(cb.mean()),
                   sonar_candidates_per_copter=float(in_sonar_range.mean()),
                   sonar_echo_fraction=float((sb < SONAR_RANGE).mean()))
        pos, vel = pos0.copy(), vel0.copy()
        cnt, acc, so = np.empty(n, dtype=np.int64), np.empty(n), np.empty((n, 4))
        variants = {
            "pairs_brute": (pairs_brute, lambda T: (pos, vel, w, length, RANGE, T, cnt, acc)),
            "pairs_grid": (pairs_grid, lambda T: (pos, vel, w, length, RANGE, T, *g, cnt, acc)),
            "sonar_brute": (sonar_brute, lambda T: (pos, vel, yaw, w, length, T, so)),
            "sonar_grid": (sonar_grid, lambda T: (pos, vel, yaw, w, length, T, *g, so)),
        }
        for name, (fn, args_of) in variants.items():
            # brute force at large N: a step costs ~N² work; one short call is enough
            sec = seconds if not (name.endswith("brute") and n >= 3000) else min(seconds, 0.05)
            s, T = _timed(fn, args_of, sec, repeats if sec == seconds else 1)
            row[name + "_ns"] = s / n * 1e9  # ns per copter-step
            row[name + "_steps"] = T
        rows.append(row)
        log(f"scaling N={n:6d}: pairs brute {row['pairs_brute_ns']:9.1f} grid {row['pairs_grid_ns']:7.1f} | "
            f"sonar brute {row['sonar_brute_ns']:9.1f} grid {row['sonar_grid_ns']:7.1f} ns/copter-step "
            f"({row['neighbours_per_copter']:.1f} neighbours within {RANGE} m)")
    spread = {}
    for task, work in (("pairs_grid", "neighbours_per_copter"), ("sonar_grid", "sonar_candidates_per_copter")):
        v = np.array([r[task + "_ns"] for r in rows])
        per = v / np.array([1.0 + r[work] for r in rows])  # per copter and object in range (itself + others)
        spread[task] = dict(min=float(v.min()), max=float(v.max()), mean=float(v.mean()),
                            max_over_min=float(v.max() / v.min()),
                            max_dev_from_mean=float(np.max(np.abs(v / v.mean() - 1.0))),
                            per_object_max_dev_from_mean=float(np.max(np.abs(per / per.mean() - 1.0))),
                            from_100_max_dev_from_mean=float(np.max(np.abs(v[[r["N"] >= 100 for r in rows]]
                                                                           / v[[r["N"] >= 100 for r in rows]].mean() - 1.0)))
                            if any(r["N"] >= 100 for r in rows) else None)
    out_dir = Path(out_dir)
    fig_path = _figure(rows, out_dir / "scaling.png")
    md = _markdown(rows, spread, fig_path)
    return dict(rows=rows, spread=spread, figure=str(fig_path) if fig_path else None, markdown=md,
                area_per_copter=AREA_PER_COPTER, range=RANGE, sonar_range=SONAR_RANGE)


def _markdown(rows, spread, fig_path) -> str:
    L = [f"## Scaling at fixed density ({AREA_PER_COPTER:g} m² per copter), one thread, ns per copter-step",
         "",
         f"Pairs within {RANGE} m (count + sum of distances) and 4 sonar rays per copter (boundary + copter circles, "
         f"{SONAR_RANGE} m range); brute force vs cell grid (cell {CELL} m, build included). Grid and brute force "
         "give identical results (checked).",
         "",
         "| N | arena (m) | cells | copters ≤ 2.5 m | copters ≤ 3.15 m | pairs brute | pairs grid | sonar brute | "
         "sonar grid | grid speed-up pairs / sonar |",
         "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        L.append(f"| {r['N']} | {r['width']:.1f} × {r['length']:.1f} | {r['cells']} | {r['neighbours_per_copter']:.1f} | "
                 f"{r['sonar_candidates_per_copter']:.1f} | {r['pairs_brute_ns']:.0f} | {r['pairs_grid_ns']:.0f} | "
                 f"{r['sonar_brute_ns']:.0f} | {r['sonar_grid_ns']:.0f} | "
                 f"{r['pairs_brute_ns'] / r['pairs_grid_ns']:.1f}× / {r['sonar_brute_ns'] / r['sonar_grid_ns']:.1f}× |")
    L.append("")
    for task, s in spread.items():
        extra = (f"; from N = 100 on ±{100 * s['from_100_max_dev_from_mean']:.0f} %"
                 if s.get("from_100_max_dev_from_mean") is not None else "")
        L.append(f"- {task}: {s['min']:.0f}–{s['max']:.0f} ns/copter-step over N = {rows[0]['N']} … {rows[-1]['N']}: "
                 f"±{100 * s['max_dev_from_mean']:.0f} % around the mean (max/min {s['max_over_min']:.2f}){extra}; "
                 f"per copter and object in range (1 + copters within the range) ±"
                 f"{100 * s['per_object_max_dev_from_mean']:.0f} %")
    L.append("- the work itself is not constant at small N: the range disc of a copter in a small arena lies "
             "partly outside it, so fewer copters are in range (columns 4–5); brute force grows ∝ N.")
    if fig_path:
        L.append(f"- figure: `{fig_path}`")
    return "\n".join(L)


def _figure(rows, path: Path):
    n = [r["N"] for r in rows]

    def draw(ax):
        for key, label, style in (("pairs_brute", f"pairs ≤ {RANGE} m, brute force", "o--"),
                                  ("pairs_grid", f"pairs ≤ {RANGE} m, cell grid", "o-"),
                                  ("sonar_brute", "4 sonar rays, brute force", "s--"),
                                  ("sonar_grid", "4 sonar rays, cell grid", "s-")):
            ax.plot(n, [r[key + "_ns"] for r in rows], style, label=label)

    return loglog_figure(path, draw, "copters N (arena grows: 2 m² per copter)", "ns per copter-step (one thread)",
                         "Cost per copter-step at fixed density")


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="out/bench")
    a = ap.parse_args()
    res = run(quick=a.quick, out_dir=a.out)
    print(res["markdown"])
