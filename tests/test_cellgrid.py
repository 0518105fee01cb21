"""Cell grid (finkensim/kernels/cellgrid.py): neighbour queries and raycasts == brute force.

The brute-force references are plain NumPy written from the definitions: a copter j is a neighbour
of i when (x_j − x_i)² + (y_j − y_i)² ≤ r² (the same formula and operand order as the kernel, so
exact ties agree), and a ray's nearest copter hit is the minimum over all other copters of the
ray–circle quadratic (tests/naive/geometry.py), kept when t ≤ max_range.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.kernels import cellgrid as cg
from finkensim.kernels import cellgrid_batch as cgb
from tests.naive import geometry as naive


# --------------------------------------------------------------------------- references

def brute_neighbours(pos_b, r, exclude_self=True):
    """Per copter i: the sorted list of j with squared distance ≤ r² (and those squared distances)."""
    diff = pos_b[None, :, :] - pos_b[:, None, :]  # diff[i, j] = p_j − p_i
    d2 = diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1]
    inside = d2 <= r * r
    if exclude_self:
        np.fill_diagonal(inside, False)
    return [np.flatnonzero(inside[i]) for i in range(pos_b.shape[0])], d2


def brute_raycast(pos_b, yaw_b, ray_yaw, max_range, radius):
    N, R = pos_b.shape[0], len(ray_yaw)
    t_out = np.full((N, R), np.inf)
    for i in range(N):
        for k in range(R):
            a = yaw_b[i] + ray_yaw[k]
            d = (math.cos(a), math.sin(a))
            for j in range(N):
                if j == i:
                    continue
                t = naive.ray_circle(pos_b[i], d, pos_b[j], radius)
                if t <= max_range and t < t_out[i, k]:
                    t_out[i, k] = t
    return t_out


def check_neighbours(pos, r, spec, exclude_self=True):
    counts, idx, d2 = cgb.neighbours_within(pos, r, spec, exclude_self=exclude_self)
    assert counts.max(initial=0) <= idx.shape[2]
    n_counts = cgb.neighbour_counts(pos, r, spec, exclude_self=exclude_self)
    np.testing.assert_array_equal(counts, n_counts)
    for b in range(pos.shape[0]):
        ref, ref_d2 = brute_neighbours(pos[b], r, exclude_self)
        for i in range(pos.shape[1]):
            got = idx[b, i, :counts[b, i]]
            np.testing.assert_array_equal(np.sort(got), ref[i], err_msg=f"env {b} copter {i}")
            np.testing.assert_array_equal(d2[b, i, :counts[b, i]], ref_d2[i, got])
            assert np.all(idx[b, i, counts[b, i]:] == -1)


# --------------------------------------------------------------------------- strategies

@st.composite
def scenes(draw, max_n=40, outside=True):
    """(pos (B, N, 2), width, length, cell) with copters in (or a bit outside) the arena."""
    width = draw(st.floats(0.5, 40.0))
    length = draw(st.floats(0.5, 40.0))
    cell = draw(st.floats(0.05, 12.0))
    B = draw(st.integers(1, 3))
    N = draw(st.integers(1, max_n))
    margin = 1.0 if outside else 0.0
    xs = st.floats(-margin, width + margin, allow_nan=False)
    ys = st.floats(-margin, length + margin, allow_nan=False)
    flat = draw(st.lists(st.tuples(xs, ys), min_size=B * N, max_size=B * N))
    pos = np.array(flat, dtype=float).reshape(B, N, 2)
    if draw(st.booleans()):  # snap some copters onto cell borders and corners
        snap = draw(st.lists(st.booleans(), min_size=B * N, max_size=B * N))
        grid_pos = np.round(pos / cell) * cell
        pos = np.where(np.array(snap).reshape(B, N, 1), grid_pos, pos)
    return pos, width, length, cell


# --------------------------------------------------------------------------- neighbour queries

@settings(max_examples=200, deadline=None)
@given(scenes(), st.floats(0.0, 15.0), st.booleans())
def test_neighbours_match_brute_force(scene, r, exclude_self):
    pos, width, length, cell = scene
    spec = cg.grid_spec(width, length, cell)
    check_neighbours(pos, r, spec, exclude_self)


@settings(max_examples=100, deadline=None)
@given(scenes(), st.sampled_from([0.5, 1.0, 2.0]))
def test_radius_equal_to_cell_and_multiples(scene, factor):
    """The intended use: cell side = query range (and coarser/finer cells)."""
    pos, width, length, cell = scene
    check_neighbours(pos, cell * factor, cg.grid_spec(width, length, cell))


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 6), st.integers(1, 6), st.floats(0.1, 3.0), st.integers(0, 3))
def test_copters_on_cell_borders_and_corners(nx, ny, cell, r_cells):
    """Every copter exactly on a cell corner; radius an exact multiple of the cell side (ties at r)."""
    xs, ys = np.meshgrid(np.arange(nx + 1) * cell, np.arange(ny + 1) * cell, indexing="ij")
    pos = np.stack([xs.ravel(), ys.ravel()], axis=-1)[None]
    spec = cg.grid_spec(nx * cell, ny * cell, cell)
    check_neighbours(pos, r_cells * cell, spec)


def test_one_copter_has_no_neighbours():
    pos = np.array([[[1.0, 1.0]]])
    spec = cg.grid_spec(3.0, 4.0, 2.5)
    counts, idx, _ = cgb.neighbours_within(pos, 2.5, spec)
    assert counts.tolist() == [[0]] and idx.shape == (1, 1, 0)
    counts, idx, d2 = cgb.neighbours_within(pos, 2.5, spec, exclude_self=False)
    assert counts.tolist() == [[1]] and idx[0, 0, 0] == 0 and d2[0, 0, 0] == 0.0


def test_empty_cells_and_all_in_one_cell():
    # 100 cells, every copter in one corner cell: all other cells empty
    rng = np.random.default_rng(0)
    pos = rng.uniform(0.0, 0.3, size=(2, 25, 2))
    spec = cg.grid_spec(10.0, 10.0, 1.0)
    check_neighbours(pos, 0.2, spec)
    check_neighbours(pos, 5.0, spec)
    cell_start, order, spos = cgb.build_grid(pos, spec)
    assert cell_start[:, 1].tolist() == [25, 25] and np.all(cell_start[:, -1] == 25)
    np.testing.assert_array_equal(order, np.tile(np.arange(25), (2, 1)))  # stable sort


def test_build_is_a_stable_counting_sort():
    rng = np.random.default_rng(1)
    pos = rng.uniform(-0.5, 5.5, size=(3, 200, 2))  # some outside the grid: clamped to edge cells
    spec = cg.grid_spec(5.0, 5.0, 0.7)
    cell_start, order, spos = cgb.build_grid(pos, spec)
    cx = np.clip(np.floor((pos[..., 0] - spec.x0) / spec.cell), 0, spec.nx - 1).astype(int)
    cy = np.clip(np.floor((pos[..., 1] - spec.y0) / spec.cell), 0, spec.ny - 1).astype(int)
    cell = cy * spec.nx + cx
    for b in range(3):
        ref = np.argsort(cell[b], kind="stable")
        np.testing.assert_array_equal(order[b], ref)
        np.testing.assert_array_equal(spos[b], pos[b, ref])
        np.testing.assert_array_equal(cell_start[b], np.concatenate([[0], np.cumsum(np.bincount(cell[b], minlength=spec.n_cells))]))


def test_truncated_lists_report_true_counts():
    pos = np.zeros((1, 5, 2))
    counts, idx, _ = cgb.neighbours_within(pos, 1.0, cg.grid_spec(2.0, 2.0, 1.0), max_neighbours=2)
    assert counts.tolist() == [[4] * 5] and idx.shape == (1, 5, 2) and np.all(idx >= 0)


def test_grid_spec_validation_and_cap():
    with pytest.raises(ValueError, match="cell"):
        cg.grid_spec(3.0, 4.0, 0.0)
    with pytest.raises(ValueError, match="width"):
        cg.grid_spec(-1.0, 4.0, 1.0)
    spec = cg.grid_spec(1000.0, 1000.0, 0.001, max_cells=10_000)
    assert spec.n_cells <= 10_000 and spec.nx * spec.cell >= 1000.0
    with pytest.raises(ValueError, match="finite"):
        cgb.neighbours_within(np.array([[[np.nan, 0.0]]]), 1.0, spec)


# --------------------------------------------------------------------------- raycasts

@settings(max_examples=100, deadline=None)
@given(scenes(max_n=25), st.floats(0.05, 1.0), st.floats(0.1, 6.0), st.integers(1, 5), st.floats(-math.pi, math.pi))
def test_raycast_fan_matches_brute_force(scene, radius, max_range, n_rays, yaw0):
    pos, width, length, cell = scene
    B, N, _ = pos.shape
    ray_yaw = yaw0 + np.arange(n_rays) * (2 * np.pi / n_rays)
    yaw = np.linspace(-3.0, 3.0, B * N).reshape(B, N)
    spec = cg.grid_spec(width, length, cell)
    t, j = cgb.raycast_fan(pos, yaw, ray_yaw, max_range, radius, spec)
    for b in range(B):
        ref = brute_raycast(pos[b], yaw[b], ray_yaw, max_range, radius)
        np.testing.assert_allclose(t[b], ref, rtol=1e-12, atol=1e-12)
        hit = np.isfinite(t[b])
        assert np.all((j[b] >= 0) == hit)
        # the reported copter is one whose circle the ray meets at t
        for i, k in zip(*np.nonzero(hit)):
            a = yaw[b, i] + ray_yaw[k]
            tt = naive.ray_circle(pos[b, i], (math.cos(a), math.sin(a)), pos[b, j[b, i, k]], radius)
            assert abs(tt - t[b, i, k]) <= 1e-12 * max(1.0, tt)
            assert j[b, i, k] != i


def test_raycast_analytic():
    # copter 0 at the origin looking along +x; copter 1 at 2 m, copter 2 at 5 m (beyond 3 m range)
    pos = np.array([[[0.5, 0.5], [2.5, 0.5], [5.5, 0.5]]])
    spec = cg.grid_spec(6.0, 1.0, 1.0)
    t, j = cgb.raycast_fan(pos, np.zeros((1, 3)), [0.0, np.pi / 2, np.pi], 3.0, 0.15, spec)
    assert t[0, 0, 0] == pytest.approx(1.85) and j[0, 0, 0] == 1
    assert np.isinf(t[0, 0, 1]) and j[0, 0, 1] == -1
    assert np.isinf(t[0, 0, 2])
    assert t[0, 1, 0] == pytest.approx(2.85) and j[0, 1, 0] == 2  # 1 sees 2 at 2.85 m
    assert t[0, 1, 2] == pytest.approx(1.85) and j[0, 1, 2] == 0
    assert t[0, 2, 2] == pytest.approx(2.85) and j[0, 2, 2] == 1


def test_per_environment_kernels_compose_in_a_compiled_loop():
    """The inline kernels work from a user's njit loop with one set of buffers reused across steps."""
    from numba import njit

    @njit
    def loop(pos_steps, r, x0, y0, inv_cell, nx, ny):
        T, N, _ = pos_steps.shape
        cell_start = np.empty(nx * ny + 1, dtype=np.int64)
        order = np.empty(N, dtype=np.int64)
        spos = np.empty((N, 2))
        cell_of = np.empty(N, dtype=np.int64)
        idx = np.empty(N, dtype=np.int64)
        d2 = np.empty(N)
        out = np.zeros((T, N), dtype=np.int64)
        for t in range(T):
            cg.build_env(pos_steps[t], (x0, y0, inv_cell, nx, ny), cell_start, order, spos, cell_of)
            for i in range(N):
                out[t, i] = cg.query_env(pos_steps[t, i, 0], pos_steps[t, i, 1], r, i, (x0, y0, inv_cell, nx, ny),
                                         cell_start, order, spos, idx, d2)
        return out

    rng = np.random.default_rng(3)
    pos = rng.uniform(0, 10, size=(4, 60, 2))
    spec = cg.grid_spec(10.0, 10.0, 2.5)
    got = loop(pos, 2.5, spec.x0, spec.y0, spec.inv_cell, spec.nx, spec.ny)
    np.testing.assert_array_equal(got, cgb.neighbour_counts(pos, 2.5, spec))
    for t in range(4):
        ref, _ = brute_neighbours(pos[t], 2.5)
        assert got[t].tolist() == [len(x) for x in ref]
