"""Batched wrappers of the cell grid (:mod:`finkensim.kernels.cellgrid`): B environments in one ``prange`` call.

For notebooks, tests and benchmarks; the engine calls the per-environment kernels directly.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from .cellgrid import GridSpec, build_env, count_env, grid_layout, query_env, raycast_fan_env

__all__ = ["build_grid", "neighbour_counts", "neighbours_within", "raycast_fan"]




def _check_pos(pos) -> np.ndarray:
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ValueError(f"pos has shape {pos.shape}: expected (B, N, 2) m")
    if not np.all(np.isfinite(pos)):
        raise ValueError("pos: coordinates must be finite")
    return pos


@njit(cache=True, parallel=True)
def _build_batch(pos, spec, cell_start, order, spos):
    B, N, _ = pos.shape
    layout = grid_layout(spec)
    for b in prange(B):
        cell_of = np.empty(N, dtype=np.int64)
        build_env(pos[b], layout, cell_start[b], order[b], spos[b], cell_of)


@njit(cache=True, parallel=True)
def _counts_batch(pos, r, exclude_self, spec, out):
    B, N, _ = pos.shape
    layout = grid_layout(spec)
    nx, ny = spec.nx, spec.ny
    for b in prange(B):
        cell_start = np.empty(nx * ny + 1, dtype=np.int64)
        order = np.empty(N, dtype=np.int64)
        spos = np.empty((N, 2))
        cell_of = np.empty(N, dtype=np.int64)
        build_env(pos[b], layout, cell_start, order, spos, cell_of)
        for s in range(N):  # in cell order (cache friendly)
            i = order[s]
            skip = i if exclude_self else -1
            out[b, i] = count_env(pos[b, i, 0], pos[b, i, 1], r, skip, layout, cell_start, order, spos)


@njit(cache=True, parallel=True)
def _neighbours_batch(pos, r, exclude_self, spec, counts, idx, d2):
    B, N, _ = pos.shape
    K = idx.shape[2]
    layout = grid_layout(spec)
    nx, ny = spec.nx, spec.ny
    for b in prange(B):
        cell_start = np.empty(nx * ny + 1, dtype=np.int64)
        order = np.empty(N, dtype=np.int64)
        spos = np.empty((N, 2))
        cell_of = np.empty(N, dtype=np.int64)
        tmp_i = np.empty(N, dtype=np.int64)
        tmp_d = np.empty(N)
        build_env(pos[b], layout, cell_start, order, spos, cell_of)
        for s in range(N):  # in cell order (cache friendly)
            i = order[s]
            skip = i if exclude_self else -1
            n = query_env(pos[b, i, 0], pos[b, i, 1], r, skip, layout, cell_start, order, spos, tmp_i, tmp_d)
            counts[b, i] = n
            for k in range(min(n, K)):
                idx[b, i, k] = tmp_i[k]
                d2[b, i, k] = tmp_d[k]
            for k in range(min(n, K), K):
                idx[b, i, k] = -1
                d2[b, i, k] = np.inf


@njit(cache=True, parallel=True)
def _raycast_batch(pos, yaw, ray_yaw, max_range, radius, spec, out_t, out_j):
    B, N, _ = pos.shape
    layout = grid_layout(spec)
    nx, ny = spec.nx, spec.ny
    R = ray_yaw.shape[0]
    for b in prange(B):
        cell_start = np.empty(nx * ny + 1, dtype=np.int64)
        order = np.empty(N, dtype=np.int64)
        spos = np.empty((N, 2))
        cell_of = np.empty(N, dtype=np.int64)
        dirs = np.empty((R, 2))
        build_env(pos[b], layout, cell_start, order, spos, cell_of)
        for s in range(N):  # in cell order (cache friendly)
            i = order[s]
            for k in range(R):
                dirs[k, 0] = np.cos(yaw[b, i] + ray_yaw[k])
                dirs[k, 1] = np.sin(yaw[b, i] + ray_yaw[k])
            raycast_fan_env(pos[b, i, 0], pos[b, i, 1], dirs, max_range, radius, i, spec, (cell_start, order, spos),
                            out_t[b, i], out_j[b, i])


def build_grid(pos, spec: GridSpec):
    """Grids of B environments: pos (B, N, 2) m → (cell_start (B, C+1), order (B, N), spos (B, N, 2))."""
    pos = _check_pos(pos)
    B, N, _ = pos.shape
    cell_start = np.empty((B, spec.n_cells + 1), dtype=np.int64)
    order = np.empty((B, N), dtype=np.int64)
    spos = np.empty((B, N, 2))
    _build_batch(pos, spec, cell_start, order, spos)
    return cell_start, order, spos


def neighbour_counts(pos, r: float, spec: GridSpec, exclude_self: bool = True) -> np.ndarray:
    """Number of copters within r (m) of each copter: (B, N) int64 (itself excluded by default)."""
    pos = _check_pos(pos)
    out = np.empty(pos.shape[:2], dtype=np.int64)
    _counts_batch(pos, float(r), bool(exclude_self), spec, out)
    return out


def neighbours_within(pos, r: float, spec: GridSpec, max_neighbours: int | None = None,
                      exclude_self: bool = True):
    """Fixed-capacity neighbour lists of every copter: copters within r (m).

    Returns (counts (B, N) int64, idx (B, N, K) int64, d2 (B, N, K) m²): the first min(count, K)
    entries of row (b, i) are its neighbours (grid order, not sorted) and their squared distances;
    the rest are −1 / inf. ``counts`` is the true number even when it exceeds K (the list is then
    truncated: check ``counts.max() <= K``). K = ``max_neighbours``, by default the largest count
    (one extra counting pass).
    """
    pos = _check_pos(pos)
    B, N, _ = pos.shape
    if max_neighbours is None:
        c = neighbour_counts(pos, r, spec, exclude_self)
        max_neighbours = int(c.max()) if c.size else 0
    K = int(max_neighbours)
    counts = np.empty((B, N), dtype=np.int64)
    idx = np.empty((B, N, K), dtype=np.int64)
    d2 = np.empty((B, N, K))
    _neighbours_batch(pos, float(r), bool(exclude_self), spec, counts, idx, d2)
    return counts, idx, d2


def raycast_fan(pos, yaw, ray_yaw, max_range: float, radius: float, spec: GridSpec):
    """Rays from every copter centre, at headings yaw (B, N) + ray_yaw (R,) rad, against the other copters'
    circles (``radius`` m): (t (B, N, R) m, inf if no hit within max_range; j (B, N, R) copter hit or −1)."""
    pos = _check_pos(pos)
    B, N, _ = pos.shape
    yaw = np.ascontiguousarray(np.broadcast_to(np.asarray(yaw, dtype=np.float64), (B, N)))
    ray_yaw = np.ascontiguousarray(np.asarray(ray_yaw, dtype=np.float64).reshape(-1))
    R = ray_yaw.shape[0]
    out_t = np.empty((B, N, R))
    out_j = np.empty((B, N, R), dtype=np.int64)
    _raycast_batch(pos, yaw, ray_yaw, float(max_range), float(radius), spec, out_t, out_j)
    return out_t, out_j
