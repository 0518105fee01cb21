"""Uniform cell grid for range-limited neighbour queries and short raycasts (numba).

Why: every copter-to-copter loop in a step (ranging within 2.5 m, sonar echoes within 3 m,
contacts, repulsion) is O(N) per copter when done by brute force, so a step costs O(N²). At a
fixed density (copters per m²) only a constant number of copters lies within a fixed range, so a
grid makes the cost per copter-step constant: build O(N + C), each query O(copters in the scanned
cells).

**Layout.** Cells of side ``cell`` (m) tile the rectangle [x0, x0 + nx·cell) × [y0, y0 + ny·cell),
row-major: cell id = cy·nx + cx. A point outside the rectangle goes to the nearest edge cell (the
cell index is clamped), so every finite point is stored and every query stays exact; the grid just
gets slower when many points lie outside. Build is a stable counting sort of the N copters by cell:

- ``cell_start`` (C + 1,) int64: copters of cell c are sorted slots cell_start[c] … cell_start[c+1]−1;
- ``order`` (N,) int64: copter index of each sorted slot (ascending within a cell);
- ``spos`` (N, 2) float64: positions in sorted order (a copy, so a query reads contiguous memory —
  the cells cx0…cx1 of one grid row are one contiguous slot range);
- ``cell_of`` (N,) int64: work buffer (cell of each copter).

**Queries** scan the grid rows cy0…cy1 of the query box [q − r, q + r] and, in each row, only the
cells that the disc of radius r reaches at that row's nearest edge (the chord), as one contiguous
slot range (:func:`row_slots`). Cell coordinates are clamped and monotone in the coordinate, and the
box is widened by a relative 1e-9 against rounding, so any point within r of q is scanned, for any
cell size; membership is then decided by the exact squared-distance test. The hit/miss decision is
branch-free (always write, advance the count on a hit), since a data-dependent branch there is
mispredicted about half the time. Iterating the queries in sorted-slot order (copter ``order[k]``,
centre ``spos[k]``) keeps consecutive queries on the same cells. Measured (benchmarks/scaling.py):
cell side = query range was fastest (vs r/2 and r/3).

**Raycasts.** :func:`raycast_fan_env` casts R rays from one origin against the copter circles and
returns the nearest hit of each ray within ``max_range``. It does not walk cells along each ray: it
scans the copters within max_range + radius of the origin once and tests every ray of the fan
against each of them. That prefilter is exact: a hit at distance t ≤ max_range is a point of the
circle t from the origin, so the circle's centre is at most t + radius ≤ max_range + radius away.
It is also enough for a flat cost: the candidates are the copters in a disc of fixed radius, a
constant number at fixed density, and one scan serves all rays of a copter's sonars (4 here). A
per-ray cell walk (DDA) would test fewer circles per ray — those in a band of width ~2·(radius +
cell) along the ray instead of the whole disc — which is a constant factor, not a different
scaling, and it would walk the 3 × 3 neighbourhoods of every cell the ray crosses for each ray
separately. Hits beyond ``max_range`` are not reported (t = inf), which is what a sonar needs (no
echo within range reads max_range).

**In the engine.** :class:`GridParams` (built by :func:`grid_params`) is the record the simulator's
kernels take: ``on`` says whether this run's environments are large enough for the grid to pay
(``simulation.grid_min_copters``), and the geometry. Kernels with a copter-copter loop take it with
the per-environment buffers and run the grid query when ``on``, the brute force otherwise; both
decide membership by the same exact test, so the results are identical (``tests/test_cellgrid.py``).
Users: copter contacts (:func:`~finkensim.copters.update_contacts_env`, :func:`any_within_env`), virtual ranging
(:func:`~finkensim.sensors.ranging_kernels.ranging_grid_env`), sonar rays and cross-talk, and the wall check
(:func:`query_env`).

**Kernels.** ``*_env`` functions are per-environment kernels (arrays and numbers only) for compiled rollouts. The
four the engine calls (:func:`build_env`, :func:`query_env`, :func:`count_env`, :func:`any_within_env`) are compiled
functions, not inlined: inlined into the sonar, ranging, contact and wall-check kernels they made the cold compile of
the full workload 6.5 s longer (``benchmarks.compile_probe finken``: 48.5 → 42.0 s), while as calls they cost nothing
measurable at 10 copters (the grid is off there) and ≈ 3 % at 1 024. Allocate the grid buffers once per environment
(:func:`grid_buffers`), call :func:`build_env` each step, then query. The batched wrappers
(:func:`build_grid`, :func:`neighbour_counts`, :func:`neighbours_within`, :func:`raycast_fan`) loop
over the leading environment axis with ``prange`` (:mod:`finkensim.kernels.cellgrid_batch`). NumPy references
are in the tests.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit


__all__ = [
    "GridSpec", "grid_spec", "grid_buffers", "GridParams", "NO_GRID", "grid_params", "EngineGrid", "engine_grid", "env_grid", "no_grid_buffers",
    "grid_layout", "cell_coord", "build_env", "row_slots", "query_env", "count_env", "any_within_env", "raycast_fan_env",
]


class GridSpec(NamedTuple):
    """Grid geometry: origin x0, y0 (m), cell side (m), inv_cell (1/m), nx, ny cells (C = nx·ny)."""

    x0: float
    y0: float
    cell: float
    inv_cell: float
    nx: int
    ny: int

    @property
    def n_cells(self) -> int:
        return self.nx * self.ny


def grid_spec(width: float, length: float, cell: float, x0: float = 0.0, y0: float = 0.0,
              max_cells: int = 1 << 24) -> GridSpec:
    """A grid covering [x0, x0 + width] × [y0, y0 + length] with cells of side ``cell`` m.

    Use the query range as the cell side (a query then scans ≤ 3 × 3 cells). The number of cells is
    capped at ``max_cells`` by enlarging the cell (a very small cell in a huge arena would make the
    build O(C) dominate).
    """
    if not (cell > 0.0 and math.isfinite(cell)):
        raise ValueError(f"cell = {cell!r}: expected a finite cell side > 0 m")
    if not (width > 0.0 and length > 0.0 and math.isfinite(width) and math.isfinite(length)):
        raise ValueError(f"width, length = {width!r}, {length!r}: expected finite extents > 0 m")
    cell = float(cell)
    while True:
        nx = max(1, int(math.ceil(width / cell)))
        ny = max(1, int(math.ceil(length / cell)))
        if nx * ny <= max_cells:
            break
        cell *= 2.0
    return GridSpec(float(x0), float(y0), cell, 1.0 / cell, nx, ny)


def grid_buffers(n: int, spec: GridSpec):
    """Work buffers of one environment: (cell_start (C+1,), order (N,), spos (N, 2), cell_of (N,))."""
    return (np.zeros(spec.n_cells + 1, dtype=np.int64), np.zeros(n, dtype=np.int64), np.zeros((n, 2)),
            np.zeros(n, dtype=np.int64))


class GridParams(NamedTuple):
    """The engine's grid as one numba record: ``on`` (use it; else the kernels run their brute force),
    origin x0, y0 (m), cell side and its inverse (m, 1/m), nx, ny cells."""

    on: bool
    x0: float
    y0: float
    cell: float
    inv_cell: float
    nx: int
    ny: int


#: a grid that is off (the kernels run their brute force); with empty buffers wherever a kernel wants some
NO_GRID = GridParams(False, 0.0, 0.0, 1.0, 1.0, 1, 1)


def grid_params(n_copters: int, width: float, length: float, query_range: float, min_copters: int) -> GridParams:
    """The grid of an arena of width × length m for ``n_copters`` per environment: on when n_copters ≥
    ``min_copters``, cells of side max(query_range, sqrt(area / n_copters)) — the query range makes a query scan
    ≤ 3 × 3 cells; the second term keeps the number of cells (the build's O(C) part) at most the number of copters.
    Off: a 1 × 1 grid that no kernel reads."""
    n = max(1, int(n_copters))
    if int(n_copters) < int(min_copters):
        return NO_GRID
    spec = grid_spec(width, length, max(float(query_range), math.sqrt(width * length / n)))
    return GridParams(True, spec.x0, spec.y0, spec.cell, spec.inv_cell, spec.nx, spec.ny)


class EngineGrid(NamedTuple):
    """:class:`GridParams` and the buffers of B environments as one flat numba record (a nested tuple of a record
    and arrays does not pass through ``prange``): cell_start (B, C+1), order (B, N), spos (B, N, 2),
    cell_of (B, N) of :func:`build_env`, and query outputs found_idx (B, N), found_d2 (B, N) of
    :func:`query_env` — one environment's worth of empty buffers when the grid is off."""

    on: bool
    x0: float
    y0: float
    cell: float
    inv_cell: float
    nx: int
    ny: int
    cell_start: np.ndarray
    order: np.ndarray
    spos: np.ndarray
    cell_of: np.ndarray
    found_idx: np.ndarray
    found_d2: np.ndarray


def engine_grid(gp: GridParams, n_envs: int, n_copters: int) -> EngineGrid:
    """The engine's grid record for B = ``n_envs`` environments of N = ``n_copters`` (buffers allocated once;
    when the grid is off, empty ones with the same dtypes and ranks). Environment b's part is :func:`env_grid`."""
    B, N, C = (n_envs, n_copters, gp.nx * gp.ny) if gp.on else (1, 0, 0)
    return EngineGrid(*gp, np.zeros((B, C + 1), dtype=np.int64), np.zeros((B, N), dtype=np.int64),
                      np.zeros((B, N, 2)), np.zeros((B, N), dtype=np.int64), np.zeros((B, N), dtype=np.int64),
                      np.zeros((B, N)))


@njit(cache=True, inline="always")
def env_grid(g, b):
    """Environment b's grid buffers (cell_start, order, spos, cell_of, found_idx, found_d2) of an
    :class:`EngineGrid` (the one empty set when the grid is off)."""
    i = np.int64(b) if g.on else np.int64(0)  # a prange index may be typed uint64
    return g.cell_start[i], g.order[i], g.spos[i], g.cell_of[i], g.found_idx[i], g.found_d2[i]


@njit(cache=True, inline="always")
def no_grid_buffers():
    """One environment's buffers for a grid that is off (empty; what :func:`env_grid` gives for :data:`NO_GRID`):
    for the batched APIs that call the engine's kernels without a grid."""
    return (np.empty(1, dtype=np.int64), np.empty(0, dtype=np.int64), np.empty((0, 2)), np.empty(0, dtype=np.int64),
            np.empty(0, dtype=np.int64), np.empty(0))


@njit(cache=True, inline="always")
def grid_layout(g):
    """The grid's layout as the kernels take it: the tuple (x0 m, y0 m, inv_cell 1/m, nx, ny) of any record with those
    fields (:class:`GridSpec`, :class:`GridParams`, :class:`EngineGrid`)."""
    return g.x0, g.y0, g.inv_cell, g.nx, g.ny


# The query box is widened by this relative amount so that rounding of q ± r can never drop a cell
# holding a point whose computed squared distance is ≤ r² (the exact test decides membership).
BOX_PAD = 1e-9


# ---------------------------------------------------------------------------------------------
# per-environment kernels


@njit(cache=True, inline="always")
def cell_coord(v, v0, inv_cell, n):
    """Cell coordinate (0 … n−1) of coordinate v (m), clamped to the grid (monotone in v)."""
    f = (v - v0) * inv_cell
    if f < 0.0:  # also handles -inf
        return 0
    if f >= n:  # also handles +inf and huge values before the int conversion
        return n - 1
    return int(f)


@njit(cache=True)
def build_env(pos_b, layout, cell_start, order, spos, cell_of):
    """Counting sort of one environment's copters pos_b (N, 2) into cells; fills the grid buffers.

    layout: :func:`grid_layout`. Stable: copters of one cell keep ascending index order. O(N + C).
    """
    x0, y0, inv_cell, nx, ny = layout
    N = pos_b.shape[0]
    C = nx * ny
    for c in range(C + 1):
        cell_start[c] = 0
    for i in range(N):
        c = cell_coord(pos_b[i, 1], y0, inv_cell, ny) * nx + cell_coord(pos_b[i, 0], x0, inv_cell, nx)
        cell_of[i] = c
        cell_start[c] += 1
    # exclusive prefix sum: cell_start[c] = first slot of cell c
    acc = 0
    for c in range(C):
        k = cell_start[c]
        cell_start[c] = acc
        acc += k
    cell_start[C] = acc
    # scatter (cell_start[c] advances to the end of cell c = start of c + 1) ...
    for i in range(N):
        c = cell_of[i]
        k = cell_start[c]
        order[k] = i
        spos[k, 0] = pos_b[i, 0]
        spos[k, 1] = pos_b[i, 1]
        cell_start[c] = k + 1
    # ... so shift back by one cell
    for c in range(C, 0, -1):
        cell_start[c] = cell_start[c - 1]
    cell_start[0] = 0


@njit(cache=True, inline="always")
def row_slots(cy, qx, qy, rb, pad, layout, cell, cell_start):
    """Sorted-slot range (k0, k1) of grid row cy that can hold points within rb of (qx, qy); layout:
    :func:`grid_layout`, cell m its cell side.

    The row's cells are trimmed to the chord of the disc at the row's nearest edge (so a query scans
    about the disc plus a band one cell wide, not its bounding square). Edge rows extend to ±inf
    (they hold the clamped points); ``pad`` (m) widens the band against rounding. (0, 0) if none.
    """
    x0, y0, inv_cell, nx, ny = layout
    dy = 0.0
    if cy > 0:
        lo = y0 + cy * cell
        if qy < lo:
            dy = lo - qy
    if cy < ny - 1:
        hi = y0 + (cy + 1) * cell
        if qy > hi:
            dy = qy - hi
    dy -= pad
    if dy < 0.0:
        dy = 0.0
    if dy > rb:
        return 0, 0
    half = np.sqrt(rb * rb - dy * dy) + pad
    row = cy * nx
    return cell_start[row + cell_coord(qx - half, x0, inv_cell, nx)], \
        cell_start[row + cell_coord(qx + half, x0, inv_cell, nx) + 1]


@njit(cache=True, inline="always")
def query_rows(qx, qy, r, y0, inv_cell, ny):
    """The grid rows a query of radius r around (qx, qy) scans: (pad, r + pad, cell side, first row, last row);
    pad (m) widens the box against rounding (see ``BOX_PAD``)."""
    pad = BOX_PAD * (r + abs(qx) + abs(qy))
    rb = r + pad
    return pad, rb, 1.0 / inv_cell, cell_coord(qy - rb, y0, inv_cell, ny), cell_coord(qy + rb, y0, inv_cell, ny)


@njit(cache=True)
def query_env(qx, qy, r, skip, layout, cell_start, order, spos, out_idx, out_d2):
    """Copters within r (squared distance ≤ r²) of point (qx, qy), except copter ``skip`` (−1: none).

    Writes their indices into out_idx and squared distances into out_d2 (in grid order, not sorted;
    both need room for every copter that can be within r — N in the worst case) and returns how
    many. Needs the buffers of :func:`build_env` (layout: :func:`grid_layout`). Querying the copters in sorted-slot order
    (``order[k]`` for k = 0 … N−1) keeps consecutive queries in the same cells (cache friendly).
    """
    pad, rb, cell, cy0, cy1 = query_rows(qx, qy, r, layout[1], layout[2], layout[4])
    r2 = r * r
    n = 0
    for cy in range(cy0, cy1 + 1):
        k0, k1 = row_slots(cy, qx, qy, rb, pad, layout, cell, cell_start)
        for k in range(k0, k1):
            dx = spos[k, 0] - qx
            dy = spos[k, 1] - qy
            d2 = dx * dx + dy * dy
            j = order[k]
            # branch-free compaction: always write, advance only on a hit (a hit/miss branch would be
            # mispredicted about half the time). n ≤ candidates seen so far < N, so the write fits.
            out_idx[n] = j
            out_d2[n] = d2
            n += (d2 <= r2) & (j != skip)
    return n


@njit(cache=True)
def count_env(qx, qy, r, skip, layout, cell_start, order, spos):
    """Number of copters within r of (qx, qy), except ``skip`` (as :func:`query_env`, no output)."""
    pad, rb, cell, cy0, cy1 = query_rows(qx, qy, r, layout[1], layout[2], layout[4])
    r2 = r * r
    n = 0
    for cy in range(cy0, cy1 + 1):
        k0, k1 = row_slots(cy, qx, qy, rb, pad, layout, cell, cell_start)
        for k in range(k0, k1):
            dx = spos[k, 0] - qx
            dy = spos[k, 1] - qy
            n += (dx * dx + dy * dy <= r2) & (order[k] != skip)
    return n


@njit(cache=True)
def any_within_env(qx, qy, r, skip, layout, cell_start, order, spos):
    """Whether some copter other than ``skip`` is strictly closer than r to (qx, qy): squared distance
    (q − p)·(q − p) < r², the brute force's test (the sign of a difference does not change its square)."""
    pad, rb, cell, cy0, cy1 = query_rows(qx, qy, r, layout[1], layout[2], layout[4])
    r2 = r * r
    for cy in range(cy0, cy1 + 1):
        k0, k1 = row_slots(cy, qx, qy, rb, pad, layout, cell, cell_start)
        for k in range(k0, k1):
            dx = qx - spos[k, 0]
            dy = qy - spos[k, 1]
            if dx * dx + dy * dy < r2 and order[k] != skip:
                return True
    return False


@njit(cache=True, inline="always")
def raycast_fan_env(ox, oy, dirs, max_range, radius, skip, spec, cells, out_t, out_j):
    """Nearest copter-circle hit of each ray of a fan, within max_range.

    Rays O + t·dirs[k] (dirs (R, 2) unit vectors) against the circles (centre, ``radius``) of every
    copter except ``skip``, on the grid ``spec`` (:class:`GridSpec`) built into ``cells`` = (cell_start, order,
    spos) (:func:`build_env`). Writes out_t (R,) m (``inf`` if no hit at t ≤ max_range) and out_j (R,)
    the copter hit (−1 if none); a tie keeps the lower copter index. Scans only the copters within
    max_range + radius of O (exact; see the module docstring).
    """
    layout = grid_layout(spec)
    cell_start, order, spos = cells
    R = dirs.shape[0]
    for k in range(R):
        out_t[k] = np.inf
        out_j[k] = -1
    pad, lim, cell, cy0, cy1 = query_rows(ox, oy, max_range + radius, layout[1], layout[2], layout[4])
    lim2 = lim * lim
    r2 = radius * radius
    for cy in range(cy0, cy1 + 1):
        k0, k1 = row_slots(cy, ox, oy, lim, pad, layout, cell, cell_start)
        for s in range(k0, k1):
            cx = spos[s, 0]
            cyy = spos[s, 1]
            fx = ox - cx
            fy = oy - cyy
            f2 = fx * fx + fy * fy
            if f2 > lim2:
                continue
            j = order[s]
            if j == skip:
                continue
            # ray_circle with its per-circle terms hoisted out of the ray loop (same operations, same
            # results): b = (O − C)·D, c = |O − C|² − r², first root ahead of the origin
            c = f2 - r2
            for k in range(R):
                b = fx * dirs[k, 0] + fy * dirs[k, 1]
                disc = b * b - c
                if disc < 0.0:
                    continue
                sq = np.sqrt(disc)
                t = -b - sq
                if t < 0.0:
                    t = -b + sq
                    if t < 0.0:
                        continue
                if t <= max_range and (t < out_t[k] or (t == out_t[k] and j < out_j[k])):
                    out_t[k] = t
                    out_j[k] = j
