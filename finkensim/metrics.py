"""Swarm-behaviour metrics of an episode, from its recorded poses; batched over environments::

    from finkensim.metrics import episode_metrics, METRICS
    final, rec = sim.rollout(state0, n_steps, record=("pose",))      # sim = finkensim.swarm.SwarmSim(cfg)
    m = episode_metrics(rec.pose, (cfg.arena.width, cfg.arena.length), cfg.copters.radius,
                        final_pos=final.world.pos)
    m["cohesion"]            # (B,) m, one value per environment

Input: ``pose`` (T, B, N, 3) (x, y, yaw; only x, y are used; (T, B, N, 2) works too), sampled
every step as :meth:`SwarmSim.rollout <finkensim.swarm.SwarmSim.rollout>` and
:meth:`World.rollout <finkensim.world.World.rollout>` record it (the state before each step). Every value is a NumPy array shaped (B,), float64. The metrics (name, unit, meaning):

``cohesion`` (m)
    Distance of a copter centre from the swarm centroid (mean of the N centres), averaged over
    copters and samples. 0 for a single copter.
``nearest_neighbour`` (m)
    Centre distance from each copter to its nearest other copter, averaged over copters and
    samples. NaN for a single copter.
``wall_sticking`` (fraction, 0–1)
    Fraction of copter-samples whose **body** is within ``wall_distance`` (0.3 m) of a wall:
    ``min(x, W − x, y, L − y) − radius <= wall_distance``, i.e. the gap between the copter's disc
    (``copters.radius``) and the arena rectangle. The body is used, not the centre, because the
    kinematic model never lets the centre come closer than one radius to a wall; measured from
    the body the 0.3 m band means the same for any copter size. The walls are taken at their
    rest position (the net), not the deflected plates.
``collisions`` (count)
    Copter–copter collision onsets per episode, counted **per pair**: pair (i, j) starts a
    collision at sample k when the centres are closer than 2·radius (the bodies overlap) at k
    and were not at k − 1 (an overlap at the first sample counts as an onset). This is the
    number of distinct bump events; ``WorldState.collisions`` counts onsets per copter instead
    (copter i enters "overlapping someone"), whose sum over copters is not twice this number
    when three or more copters touch at once.
``wall_contacts`` (count)
    Wall-contact onsets summed over copters, with the rule of the copter model
    (:func:`finkensim.copters.update_contacts_env`): a contact begins when the body touches a wall
    (gap 0) and ends only once the gap exceeds ``WALL_RELEASE_GAP`` (2 cm). For a rollout from
    :meth:`World.init` with ``final_pos`` given this equals ``final.wall_contacts.sum(-1)``.
``fragmentation`` (components, 1–N)
    Number of connected components of the graph linking copters whose centres are closer than
    ``link_range`` (2.5 m, the virtual-ranging range), averaged over samples. 1 = one swarm.
``coverage`` (fraction, 0–1)
    Fraction of the cells of a ``cell`` (0.25 m) square grid over the arena that some copter
    centre visited at any sample. The grid has ceil(W / cell) × ceil(L / cell) cells (12 × 16 in
    the 3 m × 4 m arena); a centre on a cell border belongs to the cell above it.

``collisions`` and ``wall_contacts`` are counted over the samples plus ``final_pos`` (the state
after the last step) when it is given, so they cover every step of the rollout; the other
metrics are averages over the T samples (equal weight per sample). Pairwise quantities are
computed in blocks of samples, so memory stays bounded for long or wide batches.
"""
from __future__ import annotations

from typing import Iterable, NamedTuple, Sequence

import numpy as np
from numba import njit

from .usertext import suggest
from .copters import WALL_RELEASE_GAP

__all__ = [
    "METRICS", "WALL_DISTANCE", "LINK_RANGE", "COVERAGE_CELL", "episode_metrics", "cohesion",
    "nearest_neighbour", "wall_sticking", "collision_onsets", "wall_contact_onsets", "fragmentation",
    "coverage", "coverage_cells", "check_metric_names", "centroid_distances", "near_wall",
]

WALL_DISTANCE = 0.3   # m, body-to-wall gap counted as "at the wall" by wall_sticking
LINK_RANGE = 2.5      # m, centre distance below which two copters are linked (fragmentation)
COVERAGE_CELL = 0.25  # m, side of a coverage grid cell
WALL_TOUCH_TOL = 1e-9  # m, a body gap at or below this is "touching" (positions clamped to the wall)
_BLOCK_ELEMENTS = 2_000_000  # pairwise entries (samples x B x N x N) handled at once


class MetricInfo(NamedTuple):
    unit: str
    doc: str


METRICS: dict[str, MetricInfo] = {
    "cohesion": MetricInfo("m", "mean distance of a copter from the swarm centroid"),
    "nearest_neighbour": MetricInfo("m", "mean distance of a copter to its nearest neighbour"),
    "wall_sticking": MetricInfo("fraction", f"fraction of copter-time with the body within {WALL_DISTANCE} m of a wall"),
    "collisions": MetricInfo("count", "copter-copter collision onsets, per pair"),
    "wall_contacts": MetricInfo("count", "wall contact onsets, summed over copters"),
    "fragmentation": MetricInfo("components", f"mean number of groups (links < {LINK_RANGE} m)"),
    "coverage": MetricInfo("fraction", f"fraction of {COVERAGE_CELL} m grid cells visited"),
}
"""Every episode metric by name, with its unit and what it measures (:class:`MetricInfo`)."""


def check_metric_names(names: Iterable[str] | None) -> tuple[str, ...]:
    """The metric names in canonical order; unknown names raise ``ValueError`` with a suggestion."""
    if names is None:
        return tuple(METRICS)
    names = list(names)
    for n in names:
        if n not in METRICS:
            raise ValueError(f"unknown metric {n!r}{suggest(n, METRICS)}; expected some of {', '.join(METRICS)}")
    return tuple(m for m in METRICS if m in names)


def _positions(pose) -> np.ndarray:
    pose = np.asarray(pose, dtype=np.float64)
    if pose.ndim != 4 or pose.shape[-1] not in (2, 3):
        raise ValueError(f"pose has shape {pose.shape}: expected (T, B, N, 3) (x, y, yaw) or (T, B, N, 2)")
    if pose.shape[0] < 1 or pose.shape[2] < 1:
        raise ValueError(f"pose has shape {pose.shape}: expected at least one sample and one copter")
    return pose[..., :2]


def _with_final(pos, final_pos) -> np.ndarray:
    if final_pos is None:
        return pos
    final_pos = np.asarray(final_pos, dtype=np.float64)
    if final_pos.shape != pos.shape[1:]:
        raise ValueError(f"final_pos has shape {final_pos.shape}: expected (B, N, 2) = {pos.shape[1:]}")
    return np.concatenate([pos, final_pos[None]], axis=0)


def _blocks(pos) -> Iterable[slice]:
    T, B, N, _ = pos.shape
    step = max(1, _BLOCK_ELEMENTS // max(1, B * N * N))
    for k in range(0, T, step):
        yield slice(k, min(T, k + step))


def _pair_distances(p) -> np.ndarray:
    """(t, B, N, N) centre distances of positions p (t, B, N, 2)."""
    d = p[:, :, :, None, :] - p[:, :, None, :, :]
    return np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2)


@njit(cache=True, inline="always")
def _min_nan(a, b):
    """min(a, b), NaN if either is NaN (as ``np.minimum``)."""
    m = a if a < b else b
    return a if a != a else m


@njit(cache=True, inline="always")
def _body_gap(x, y, width, length, radius):
    """Body-to-wall gap (m) of a copter centre (x, y) m: min(x, W − x, y, L − y) − radius (NaN for a NaN coordinate)."""
    return _min_nan(_min_nan(x, width - x), _min_nan(y, length - y)) - radius


@njit(cache=True)
def _wall_gaps(pos, width, length, radius) -> np.ndarray:
    """(T, B, N) m: :func:`_body_gap` of every centre of pos (T, B, N, ≥ 2) m."""
    T, B, N = pos.shape[0], pos.shape[1], pos.shape[2]
    out = np.empty((T, B, N))
    for t in range(T):
        for b in range(B):
            for n in range(N):
                out[t, b, n] = _body_gap(pos[t, b, n, 0], pos[t, b, n, 1], width, length, radius)
    return out


# ------------------------------------------------------------------------------------------ metrics

@njit(cache=True)
def centroid_distances(pos) -> np.ndarray:
    """(T, B, N) m: distance of each copter centre from its environment's centroid, per sample; pos (T, B, N, ≥ 2) m.

    The centroid sums the copters in index order (the order numpy's ``mean(axis=2)`` takes on a C-ordered pose:
    the same result bit for bit). Compiled: the cohesion task computes it at every step of B environments."""
    T, B, N = pos.shape[0], pos.shape[1], pos.shape[2]
    out = np.empty((T, B, N))
    for t in range(T):
        for b in range(B):
            sx = pos[t, b, 0, 0]
            sy = pos[t, b, 0, 1]
            for n in range(1, N):
                sx += pos[t, b, n, 0]
                sy += pos[t, b, n, 1]
            cx = sx / N
            cy = sy / N
            for n in range(N):
                dx = pos[t, b, n, 0] - cx
                dy = pos[t, b, n, 1] - cy
                out[t, b, n] = np.sqrt(dx * dx + dy * dy)
    return out


def cohesion(pose) -> np.ndarray:
    """(B,) m: mean distance of a copter centre from the centroid of its environment's swarm
    (:func:`centroid_distances` averaged over samples and copters)."""
    return centroid_distances(_positions(pose)).mean(axis=(0, 2))


def nearest_neighbour(pose) -> np.ndarray:
    """(B,) m: mean centre distance to the nearest other copter; NaN when N = 1."""
    pos = _positions(pose)
    T, B, N, _ = pos.shape
    if N < 2:
        return np.full(B, np.nan)
    total = np.zeros(B)
    eye = np.eye(N, dtype=bool)
    for blk in _blocks(pos):
        d = _pair_distances(pos[blk])
        d[..., eye] = np.inf
        total += d.min(axis=-1).sum(axis=(0, 2))
    return total / (T * N)


@njit(cache=True)
def near_wall(pos, width, length, radius, wall_distance) -> np.ndarray:
    """(T, B, N) bool: the body gap min(x, W − x, y, L − y) − radius of each copter centre pos (T, B, N, ≥ 2) m is at
    most ``wall_distance`` m (arena width × length m; the gap of ``wall_contact_onsets``, compared as ``wall_sticking``
    does; a bool array rather than :func:`_wall_gaps` and a comparison: the cohesion task calls it at every step)."""
    T, B, N = pos.shape[0], pos.shape[1], pos.shape[2]
    out = np.empty((T, B, N), dtype=np.bool_)
    for t in range(T):
        for b in range(B):
            for n in range(N):
                out[t, b, n] = _body_gap(pos[t, b, n, 0], pos[t, b, n, 1], width, length, radius) <= wall_distance
    return out


def wall_sticking(pose, arena, radius, wall_distance: float = WALL_DISTANCE) -> np.ndarray:
    """(B,) fraction of copter-samples whose body is within ``wall_distance`` m of a wall.

    ``arena`` = (width, length) m; ``radius`` m (body disc). Body gap = min(x, W−x, y, L−y) − radius
    (:func:`near_wall`).
    """
    pos = _positions(pose)
    return near_wall(pos, float(arena[0]), float(arena[1]), float(radius), float(wall_distance)).mean(axis=(0, 2))


def collision_onsets(pose, radius, final_pos=None) -> np.ndarray:
    """(B,) count of pair collision onsets: pair (i < j) closer than 2·radius now and not at the previous
    sample (an overlap at the first sample counts). ``final_pos`` (B, N, 2) is appended as a last sample."""
    pos = _with_final(_positions(pose), final_pos)
    T, B, N, _ = pos.shape
    counts = np.zeros(B, dtype=np.int64)
    if N < 2:
        return counts.astype(np.float64)
    upper = np.triu(np.ones((N, N), dtype=bool), k=1)
    prev = np.zeros((B, N, N), dtype=bool)
    lim = 2.0 * float(radius)
    for blk in _blocks(pos):
        over = (_pair_distances(pos[blk]) < lim) & upper
        before = np.concatenate([prev[None], over[:-1]], axis=0)
        counts += (over & ~before).sum(axis=(0, 2, 3))
        prev = over[-1]
    return counts.astype(np.float64)


def wall_contact_onsets(pose, arena, radius, final_pos=None) -> np.ndarray:
    """(B,) wall-contact onsets summed over copters, with the copter model's hysteresis: a contact
    begins at body gap 0 (within 1e-9 m) and ends once the gap exceeds ``WALL_RELEASE_GAP``."""
    pos = _with_final(_positions(pose), final_pos)
    gap = _wall_gaps(pos, float(arena[0]), float(arena[1]), float(radius))  # (T, B, N)
    in_wall = np.zeros(gap.shape[1:], dtype=bool)
    counts = np.zeros(gap.shape[1], dtype=np.int64)
    for g in gap:
        touching = g <= WALL_TOUCH_TOL
        counts += (touching & ~in_wall).sum(axis=-1)
        in_wall = touching | (in_wall & (g <= WALL_RELEASE_GAP))
    return counts.astype(np.float64)


def _components(adj) -> np.ndarray:
    """Connected components of boolean adjacency matrices adj (..., N, N) with a true diagonal."""
    N = adj.shape[-1]
    labels = np.broadcast_to(np.arange(N), adj.shape[:-1]).copy()
    while True:  # every node takes the smallest label among its neighbours until nothing changes
        new = np.where(adj, labels[..., None, :], N).min(axis=-1)
        if np.array_equal(new, labels):
            break
        labels = new
    return (labels == np.arange(N)).sum(axis=-1)


def fragmentation(pose, link_range: float = LINK_RANGE) -> np.ndarray:
    """(B,) mean over samples of the number of connected components of the graph linking copters whose
    centres are closer than ``link_range`` m."""
    pos = _positions(pose)
    T, B, N, _ = pos.shape
    total = np.zeros(B)
    for blk in _blocks(pos):
        adj = _pair_distances(pos[blk]) < link_range
        adj[..., np.arange(N), np.arange(N)] = True
        total += _components(adj).sum(axis=0)
    return total / T


def coverage(pose, arena, cell: float = COVERAGE_CELL) -> np.ndarray:
    """(B,) fraction of the ceil(W/cell) × ceil(L/cell) grid cells visited by some copter centre."""
    pos = _positions(pose)
    T, B, N, _ = pos.shape
    cells, n_cells = coverage_cells(pos, arena, cell)
    visited = np.zeros((B, n_cells), dtype=bool)
    env = np.broadcast_to(np.arange(B)[None, :, None], cells.shape)
    visited[env.ravel(), cells.ravel()] = True
    return visited.sum(axis=1) / n_cells


def coverage_cells(pos, arena, cell: float = COVERAGE_CELL) -> tuple[np.ndarray, int]:
    """The coverage grid of :func:`coverage`: (flat cell index of each centre in ``pos`` (..., 2) m, shaped
    ``pos.shape[:-1]``, int64; the number of cells ceil(W/cell) · ceil(L/cell))."""
    pos = np.asarray(pos, dtype=np.float64)
    nx = max(1, int(np.ceil(float(arena[0]) / cell - 1e-9)))
    ny = max(1, int(np.ceil(float(arena[1]) / cell - 1e-9)))
    ix = np.clip(np.floor(pos[..., 0] / cell).astype(np.int64), 0, nx - 1)
    iy = np.clip(np.floor(pos[..., 1] / cell).astype(np.int64), 0, ny - 1)
    return ix * ny + iy, nx * ny


def episode_metrics(pose, arena: Sequence[float], radius: float, final_pos=None, names: Iterable[str] | None = None,
                    *, wall_distance: float = WALL_DISTANCE, link_range: float = LINK_RANGE,
                    cell: float = COVERAGE_CELL) -> dict[str, np.ndarray]:
    """The metrics ``names`` (default: all of :data:`METRICS`) of B episodes, each a (B,) float64 array.

    Args:
        pose: (T, B, N, 3) or (T, B, N, 2) recorded poses, m (yaw unused).
        arena: (width, length) of the arena, m.
        radius: copter body radius, m.
        final_pos: optional (B, N, 2) positions after the last step (counted by the contact metrics).
    """
    names = check_metric_names(names)
    funcs = {
        "cohesion": lambda: cohesion(pose),
        "nearest_neighbour": lambda: nearest_neighbour(pose),
        "wall_sticking": lambda: wall_sticking(pose, arena, radius, wall_distance),
        "collisions": lambda: collision_onsets(pose, radius, final_pos),
        "wall_contacts": lambda: wall_contact_onsets(pose, arena, radius, final_pos),
        "fragmentation": lambda: fragmentation(pose, link_range),
        "coverage": lambda: coverage(pose, arena, cell),
    }
    return {n: np.asarray(funcs[n](), dtype=np.float64) for n in names}
