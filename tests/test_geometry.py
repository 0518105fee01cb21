"""Geometry kernels: numba == NumPy reference (hypothesis), metric properties, analytic ray cases."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from finkensim.kernels import geometry as g
from tests.naive import geometry as naive

COORD = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
POINT = st.tuples(COORD, COORD)
ANGLE = st.floats(-np.pi, np.pi, allow_nan=False)
RADIUS = st.floats(0.0, 3.0, allow_nan=False)


def _unit(angle):
    return np.cos(angle), np.sin(angle)


def _same(a, b, tol=1e-12):
    """Both infinite, or both finite and equal to a relative/absolute tolerance."""
    if np.isinf(a) or np.isinf(b):
        return np.isinf(a) and np.isinf(b)
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


# --------------------------------------------------------------------------- point-segment

@settings(max_examples=300, deadline=None)
@given(POINT, POINT, POINT)
def test_point_segment_matches_naive(p, a, b):
    d = g.point_segment_distance(*p, *a, *b)
    assert _same(d, naive.point_segment_distance(p, a, b))
    # a distance to the closest point: never more than to either end, never negative
    assert 0.0 <= d <= min(np.hypot(p[0] - a[0], p[1] - a[1]), np.hypot(p[0] - b[0], p[1] - b[1])) + 1e-12


@settings(max_examples=100, deadline=None)
@given(POINT, POINT)
def test_point_segment_degenerate_is_point_distance(p, a):
    assert _same(g.point_segment_distance(*p, *a, *a), np.hypot(p[0] - a[0], p[1] - a[1]))


def test_point_segment_analytic():
    assert g.point_segment_distance(0.5, 2.0, 0.0, 0.0, 1.0, 0.0) == 2.0  # above the interior
    assert g.point_segment_distance(-3.0, 4.0, 0.0, 0.0, 1.0, 0.0) == 5.0  # beyond end A
    assert g.point_segment_distance(4.0, -4.0, 0.0, 0.0, 1.0, 0.0) == 5.0  # beyond end B
    assert g.point_segment_distance(0.3, 0.0, 0.0, 0.0, 1.0, 0.0) == 0.0  # on it


# --------------------------------------------------------------------------- rays

@settings(max_examples=300, deadline=None)
@given(POINT, ANGLE, POINT, POINT)
@example(o=(0.5, 0.0), angle=0.0, a=(0.0, 0.0), b=(0.0, 5e-324))  # a subnormal segment: once a false hit at t = -0
def test_ray_segment_matches_naive(o, angle, a, b):
    d = _unit(angle)
    t = g.ray_segment(*o, *d, *a, *b)
    assert _same(t, naive.ray_segment(o, d, a, b))
    assert _same(g.ray_segment(*o, *d, *a, *b, False), t)  # the branching machine code: the same result
    if np.isfinite(t):
        hit = (o[0] + t * d[0], o[1] + t * d[1])
        assert t >= 0.0
        assert naive.point_segment_distance(hit, a, b) < 1e-6 * max(1.0, t)


@settings(max_examples=300, deadline=None)
@given(POINT, ANGLE, POINT, RADIUS)
def test_ray_circle_matches_naive(o, angle, c, r):
    d = _unit(angle)
    t = g.ray_circle(*o, *d, *c, r)
    assert _same(t, naive.ray_circle(o, d, c, r))
    assert _same(g.ray_circle(*o, *d, *c, r, False), t)  # the branching machine code: the same result
    if np.isfinite(t):
        hit = np.array([o[0] + t * d[0], o[1] + t * d[1]])
        assert t >= 0.0
        assert abs(np.hypot(*(hit - np.array(c))) - r) < 1e-6 * max(1.0, t, r)


@pytest.mark.parametrize("args", [
    (0.0, 0.0, 1.0, 0.0, 1.0, -1.0, 1.0, 1.0),      # hits at t = 1
    (0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 2.0, 1.0),       # parallel: den = 0
    (0.0, 0.0, 1.0, 0.0, -1.0, -1.0, -1.0, 1.0),    # behind the origin
    (0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0),       # grazing the end A
    (0.0, 0.0, np.nan, 0.0, 1.0, -1.0, 1.0, 1.0),
    (0.0, 0.0, 1.0, 0.0, np.inf, -1.0, np.inf, 1.0),
])
def test_ray_segment_edge_cases_agree_between_selects_and_branches(args):
    with np.errstate(invalid="ignore"):  # the naive reference's numpy arithmetic on infinities
        want = naive.ray_segment(args[0:2], args[2:4], args[4:6], args[6:8])
    assert _same(g.ray_segment(*args), want) and _same(g.ray_segment(*args, False), want)


@pytest.mark.parametrize("args", [
    (0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.5),    # hits at 1.5
    (2.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.5),    # origin inside: the exit distance
    (0.0, 0.0, 1.0, 0.0, 2.0, 0.5, 0.5),    # tangent: disc = 0
    (0.0, 0.0, 1.0, 0.0, 2.0, 0.6, 0.5),    # misses: disc < 0
    (0.0, 0.0, -1.0, 0.0, 2.0, 0.0, 0.5),   # behind
    (0.0, 0.0, 1.0, 0.0, np.nan, 0.0, 0.5),
    (0.0, 0.0, 1.0, 0.0, np.inf, 0.0, 0.5),
])
def test_ray_circle_edge_cases_agree_between_selects_and_branches(args):
    with np.errstate(invalid="ignore"):
        want = naive.ray_circle(args[0:2], args[2:4], args[4:6], args[6])
    assert _same(g.ray_circle(*args), want) and _same(g.ray_circle(*args, False), want)


@settings(max_examples=200, deadline=None)
@given(POINT, ANGLE, st.floats(0.05, 3.0), st.floats(0.01, 5.0))
def test_ray_through_circle_centre_gives_distance_minus_radius(o, angle, r, gap):
    d = _unit(angle)
    dist = r + gap
    c = (o[0] + dist * d[0], o[1] + dist * d[1])
    assert g.ray_circle(*o, *d, *c, r) == pytest.approx(dist - r, rel=1e-9, abs=1e-9)
    # the opposite direction misses
    assert g.ray_circle(*o, -d[0], -d[1], *c, r) == np.inf


@pytest.mark.parametrize(
    "o, d, a, b, expected",
    [
        ((1.5, 2.0), (1.0, 0.0), (3.0, 0.0), (3.0, 4.0), 1.5),  # east wall of a 3 x 4 arena
        ((1.5, 2.0), (-1.0, 0.0), (0.0, 4.0), (0.0, 0.0), 1.5),  # west wall
        ((1.5, 2.0), (0.0, 1.0), (3.0, 4.0), (0.0, 4.0), 2.0),  # north wall
        ((1.5, 2.0), (0.0, -1.0), (0.0, 0.0), (3.0, 0.0), 2.0),  # south wall
        ((1.5, 2.0), (1.0, 0.0), (0.0, 4.0), (0.0, 0.0), np.inf),  # wall behind the ray
        ((1.5, 2.0), (1.0, 0.0), (3.0, 2.5), (3.0, 4.0), np.inf),  # segment beside the ray
        ((1.5, 2.0), (1.0, 0.0), (0.0, 0.0), (3.0, 0.0), np.inf),  # parallel
        ((1.5, 0.0), (1.0, 0.0), (0.0, 0.0), (3.0, 0.0), np.inf),  # collinear counts as parallel
        ((1.5, 2.0), (1.0, 0.0), (3.0, 2.0), (3.0, 4.0), 1.5),  # hits end A exactly
    ],
)
def test_ray_segment_analytic(o, d, a, b, expected):
    assert g.ray_segment(*o, *d, *a, *b) == expected
    assert naive.ray_segment(o, d, a, b) == expected


def test_ray_circle_analytic():
    assert g.ray_circle(0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.5) == 1.5  # through the centre: d - r
    assert g.ray_circle(0.0, 0.0, 1.0, 0.0, 2.0, 1.0, 0.5) == np.inf  # passes beside
    assert g.ray_circle(0.0, 0.0, -1.0, 0.0, 2.0, 0.0, 0.5) == np.inf  # circle behind
    assert g.ray_circle(0.0, 0.0, 1.0, 0.0, 2.0, 0.5, 0.5) == 2.0  # tangent
    assert g.ray_circle(2.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.5) == 0.5  # from inside: the exit


# --------------------------------------------------------------------------- pairwise / batched

POS = hnp.arrays(np.float64, st.tuples(st.integers(1, 3), st.integers(0, 6), st.just(2)), elements=COORD)


@settings(max_examples=100, deadline=None)
@given(POS)
def test_pairwise_distances_matches_naive_and_is_a_metric(pos):
    d = g.pairwise_distances(pos)
    np.testing.assert_allclose(d, naive.pairwise_distances(pos), rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(d, np.swapaxes(d, 1, 2))  # exactly symmetric
    assert np.all(np.diagonal(d, axis1=1, axis2=2) == 0.0)
    assert np.all(d >= 0.0)
    # triangle inequality d(i, k) <= d(i, j) + d(j, k)
    assert np.all(d[:, :, None, :] <= d[:, :, :, None] + d[:, None, :, :] + 1e-9)


@settings(max_examples=100, deadline=None)
@given(
    hnp.arrays(np.float64, st.tuples(st.integers(1, 5), st.just(2)), elements=COORD),
    hnp.arrays(np.float64, st.tuples(st.integers(1, 5), st.just(2)), elements=COORD),
    POS,
    RADIUS,
)
def test_segment_copter_distances_matches_naive(seg_a, seg_b_raw, pos, radius):
    S = min(seg_a.shape[0], seg_b_raw.shape[0])
    seg_a, seg_b = np.ascontiguousarray(seg_a[:S]), np.ascontiguousarray(seg_b_raw[:S])
    d = g.segment_copter_distances(seg_a, seg_b, pos, radius)
    assert d.shape == (pos.shape[0], S)
    np.testing.assert_allclose(d, naive.segment_copter_distances(seg_a, seg_b, pos, radius), rtol=1e-12, atol=1e-12)
    assert np.all(d >= 0.0)


def test_segment_copter_distances_arena_case():
    """Copter at (1, 0.45), radius 0.15, against the south wall y = 0 split into three segments."""
    seg_a = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    seg_b = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    pos = np.array([[[1.0, 0.45], [2.5, 3.5]]])
    d = g.segment_copter_distances(seg_a, seg_b, pos, 0.15)
    np.testing.assert_allclose(d, [[0.3, 0.3, np.hypot(1.0, 0.45) - 0.15]], rtol=1e-12)
    # a copter overlapping a segment is at distance 0, not negative
    assert g.segment_copter_distances(seg_a, seg_b, np.array([[[0.5, 0.05]]]), 0.15)[0, 0] == 0.0


# --------------------------------------------------------------------------- plate distances within a cut-off


def _within_expected(seg_a, seg_b, pos, radius, cutoff):
    brute = g.segment_copter_distances(seg_a, seg_b, pos, radius)
    return np.where(brute < cutoff, brute, np.inf)


def _bits(x):
    return np.ascontiguousarray(x).view(np.int64)


@st.composite
def arena_scenes(draw):
    """Arena walls (size, plates per wall) and copters inside, on and outside the walls, on pitch borders
    and wall lines, in the corners; radius and cut-off from 0 to beyond the arena."""
    from finkensim.arena import Arena
    from finkensim.config import Config

    W = draw(st.sampled_from([3.0, 0.5, 7.3, 40.0]))
    L = draw(st.sampled_from([4.0, 0.5, 11.1]))
    n = draw(st.sampled_from([1, 2, 3, 16, 50]))
    cfg = Config().replace({"arena.width": W, "arena.length": L, "walls.n_segments": n, "copters.n": 1})
    arena = Arena.from_config(cfg.arena, cfg.walls)
    B, N = draw(st.integers(1, 3)), draw(st.integers(0, 12))
    pos = np.empty((B, N, 2))
    for b in range(B):
        for i in range(N):
            kind = draw(st.sampled_from(["inside", "border", "corner", "outside", "line"]))
            if kind == "inside":
                p = (draw(st.floats(0.0, W)), draw(st.floats(0.0, L)))
            elif kind == "border":  # on a pitch border, a little inside
                s = draw(st.integers(0, arena.n_plates - 1))
                q = arena.seg_a[s] + arena.normal[s] * draw(st.sampled_from([0.0, 1e-12, 0.15, 0.5, 0.999, 1.0, 1.15]))
                p = (q[0] + draw(st.sampled_from([0.0, 1e-15, -1e-15])), q[1])
            elif kind == "corner":
                c = draw(st.sampled_from([(0.0, 0.0), (W, 0.0), (W, L), (0.0, L)]))
                p = (c[0] + draw(st.floats(-1.5, 1.5)), c[1] + draw(st.floats(-1.5, 1.5)))
            elif kind == "outside":
                p = (draw(st.floats(-5.0, W + 5.0)), draw(st.floats(-5.0, L + 5.0)))
            else:  # exactly on a wall line
                p = draw(st.sampled_from([(draw(st.floats(-1.0, W + 1.0)), 0.0), (W, draw(st.floats(-1.0, L + 1.0))),
                                          (0.0, draw(st.floats(0.0, L)))]))
            pos[b, i] = p
    radius = draw(st.sampled_from([0.15, 0.0, 0.5, 2.0]))
    cutoff = draw(st.sampled_from([1.0, 0.4, 0.0, 0.25, 3.0, 100.0]))
    return arena, pos, radius, cutoff


@settings(max_examples=400, deadline=None, derandomize=True)
@given(arena_scenes())
def test_plate_distances_within_cutoff_equal_brute_force(scene):
    """Exact (bit for bit) where the brute force is below the cut-off, inf elsewhere."""
    arena, pos, radius, cutoff = scene
    d = g.segment_copter_distances_within(arena.seg_a, arena.seg_b, pos, radius, cutoff)
    np.testing.assert_array_equal(_bits(d), _bits(_within_expected(arena.seg_a, arena.seg_b, pos, radius, cutoff)))


def test_plate_distances_within_bulk_and_step_cutoff():
    """Many random swarms in the default arena at the cut-off the world step uses."""
    from finkensim.world import World

    world = World()
    a, hp = world.arena, world.hinge_params
    cutoff = max(hp.threshold, a.lever)
    rng = np.random.default_rng(2)
    pos = np.stack([rng.uniform(-0.2, 3.2, (2000, 10)), rng.uniform(-0.2, 4.2, (2000, 10))], -1)
    d = g.segment_copter_distances_within(a.seg_a, a.seg_b, pos, 0.15, cutoff)
    expected = _within_expected(a.seg_a, a.seg_b, pos, 0.15, cutoff)
    np.testing.assert_array_equal(_bits(d), _bits(expected))
    assert 0.2 < np.isfinite(d).mean() < 0.9  # both cases well represented


def test_plate_distances_within_other_layouts_and_non_finite():
    """Segments not in the Arena layout (shuffled, slanted) run the brute force; NaN / inf copters and a NaN
    cut-off follow the same contract."""
    from finkensim.world import World

    a = World().arena
    rng = np.random.default_rng(4)
    pos = np.stack([rng.uniform(0, 3, (50, 6)), rng.uniform(0, 4, (50, 6))], -1)
    pos[3, 2] = np.nan
    pos[4, 0] = (np.inf, 1.0)
    perm = rng.permutation(a.n_plates)
    slanted_b = a.seg_b.copy()
    slanted_b[5, 1] += 0.01
    for sa, sb in ((a.seg_a[perm].copy(), a.seg_b[perm].copy()), (a.seg_a, slanted_b), (a.seg_a, a.seg_b)):
        for cutoff in (1.0, np.nan, np.inf):
            d = g.segment_copter_distances_within(sa, sb, pos, 0.15, cutoff)
            np.testing.assert_array_equal(_bits(d), _bits(_within_expected(sa, sb, pos, 0.15, cutoff)))
