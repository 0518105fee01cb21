"""The cell grid inside the engine: with ``simulation.grid_min_copters`` reached, copter-copter queries run on
the grid (finkensim/kernels/cellgrid.py) and give the brute force's results bit for bit.

References: the brute-force branch of the same kernel (gp.on = False) and a plain-NumPy overlap test written from
the definition (two copters touch when their centres are closer than 2·radius).
"""
from __future__ import annotations

import copy
import pickle

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from finkensim.config import Config
from finkensim.copters import update_contacts_env
from finkensim.kernels.cellgrid import GridParams, engine_grid, env_grid, grid_params
from finkensim.sensors.ranging import RangingModel
from finkensim.swarm.sense import ranging_outlined
from finkensim.swarm import SwarmSim
from finkensim.swarm.state import concat_records
from finkensim.world import World


@njit(cache=True)
def _contacts(pos, radius, g, in_collision, collisions):
    """update_contacts_env over a batch pos (B, N, 2) (no wall gaps: every copter far from the walls)."""
    B, N, _ = pos.shape
    gap = np.full(N, 1.0)
    in_wall = np.zeros(N, dtype=np.bool_)
    wall_contacts = np.zeros(N, dtype=np.int64)
    for b in range(B):
        update_contacts_env(pos[b], radius, gap, in_wall, wall_contacts, in_collision[b], collisions[b], g,
                            env_grid(g, b))


def _overlaps_reference(pos_b, radius):
    diff = pos_b[:, None, :] - pos_b[None, :, :]
    d2 = diff[..., 0] * diff[..., 0] + diff[..., 1] * diff[..., 1]
    np.fill_diagonal(d2, np.inf)
    return (d2 < (2.0 * radius) ** 2).any(axis=1)


def _run_contacts(pos, radius, gp):
    B, N, _ = pos.shape
    in_collision = np.zeros((B, N), dtype=np.bool_)
    collisions = np.zeros((B, N), dtype=np.int64)
    _contacts(pos, radius, engine_grid(gp, B, N), in_collision, collisions)
    return in_collision, collisions


OFF = GridParams(False, 0.0, 0.0, 1.0, 1.0, 1, 1)


@st.composite
def swarms(draw):
    """Positions in a width × length arena, some outside it, some on a lattice of spacing exactly 2·radius (exact
    ties of the strict test), some clustered."""
    n = draw(st.integers(2, 60))
    width, length = draw(st.floats(0.5, 20.0)), draw(st.floats(0.5, 20.0))
    radius = draw(st.sampled_from([0.05, 0.1, 0.125, 0.3]))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    pos = rng.uniform([-1.0, -1.0], [width + 1.0, length + 1.0], size=(2, n, 2))
    k = draw(st.integers(0, n))
    lattice = 2.0 * radius * rng.integers(0, 4, size=(2, k, 2))
    pos[:, :k] = lattice + pos[:, :1]  # lattice points relative to one copter: exact distances 2r·integer
    if draw(st.booleans()):
        pos[:, k:] = pos[:, k:] * 0.05 + width / 2  # a tight cluster
    return pos, width, length, radius, draw(st.floats(0.01, 3.0))


@settings(max_examples=150, deadline=None)
@given(swarms())
def test_contacts_on_the_grid_equal_the_brute_force(scene):
    pos, width, length, radius, query = scene
    on = grid_params(pos.shape[1], width, length, query, min_copters=0)
    assert on.on
    got = _run_contacts(pos, radius, on)
    want = _run_contacts(pos, radius, OFF)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    for b in range(pos.shape[0]):
        np.testing.assert_array_equal(want[0][b], _overlaps_reference(pos[b], radius))


@njit(cache=True)
def _ranging(pos, beacons, p, g, out):
    # the engine's compiled ranging_grid_env (its outlined copy, with the argument types swarm_env passes): the code under
    # test, compiled once for the engine and this test (inlining it here cost ≈ 25 s of cold compile)
    for b in range(pos.shape[0]):
        ranging_outlined(pos[b], np.zeros(pos.shape[1]), beacons, (np.int64(7), np.int64(b), np.int64(3)), p, out[b], g,
                     env_grid(g, b), True)


@pytest.fixture(scope="module")
def ranging_models():
    return {mode: RangingModel(mode) for mode in ("mixture", "gaussian", "seed")}


@settings(max_examples=60, deadline=None)
@given(swarms(), st.sampled_from(["mixture", "gaussian", "seed"]), st.booleans())
def test_ranging_on_the_grid_equals_the_brute_force(ranging_models, scene, mode, on_the_range):
    """Every reading bit for bit, including copters exactly max_range apart (placed on the range circle)."""
    pos, width, length, _, query = scene
    p = ranging_models[mode].params
    if on_the_range:  # copter 1 at exactly max_range from copter 0 along an axis (an exact tie of the rule)
        pos[:, 1] = pos[:, 0] + np.array([p.max_range, 0.0])
    B, N, _ = pos.shape
    beacons = np.array([[0.5, 0.5], [width, length]])
    out = [np.full((B, N, N + 2), np.nan) for _ in range(2)]
    _ranging(pos, beacons, p, engine_grid(grid_params(N, width, length, query, min_copters=0), B, N), out[0])
    _ranging(pos, beacons, p, engine_grid(OFF, B, N), out[1])
    np.testing.assert_array_equal(out[0], out[1])


def test_grid_params_switch_and_cell_size():
    assert not grid_params(10, 3.0, 4.0, 0.2, min_copters=64).on
    gp = grid_params(10_000, 100.0, 120.0, 0.2, min_copters=256)
    assert gp.on and gp.cell == pytest.approx(np.sqrt(100.0 * 120.0 / 10_000))  # cells ≤ copters
    assert gp.nx * gp.ny <= 10_000 * 1.1
    assert grid_params(300, 3.0, 4.0, 2.5, min_copters=256).cell == 2.5  # the query range when larger
    off = engine_grid(OFF, 64, 10)
    assert [a.shape for a in off[7:]] == [(1, 1), (1, 0), (1, 0, 2), (1, 0), (1, 0), (1, 0)]


# crowded (many contacts) and large enough that many pairs are beyond the ranging range
CROWDED = {"copters.n": 40, "copters.min_separation": 0.05, "arena.width": 4.5, "arena.length": 6.0}


GEOMETRIC = {"sonar.crosstalk": "geometric", "sonar.beam": "cone", "sonar.beam_rays": 5, "sonar.offset": 0.05,
             "sonar.max_range": 2.0}


@pytest.mark.parametrize("behaviour,sonar", [("random_walk", {}), ("attraction_repulsion", {}),
                                             ("attraction_repulsion", {**GEOMETRIC, "behaviour.wall_check": "sequence"}),
                                             # slots drawn at random at each step (13 000 of 57 600 readings are
                                             # cross-talk in this flight)
                                             ("random_walk", {**GEOMETRIC, "sonar.schedule": "random_offset",
                                                              "sonar.n_slots": 3}),
                                             ("attraction_repulsion", {"behaviour.wall_check": "per_reading"})])
def test_a_closed_loop_flight_is_bit_identical_with_and_without_the_grid(behaviour, sonar):
    """40 copters in a 4.5 m × 6 m arena (contacts, copters beyond the sonar and ranging ranges), every sensor on,
    also with geometric cross-talk and a 5-ray cone from sonars off the centre: records and counters match
    exactly."""
    cfg = Config().replace({**CROWDED, "behaviour.kind": behaviour, **sonar})
    grid = SwarmSim(cfg.replace({"simulation.grid_min_copters": 0}))
    brute = SwarmSim(cfg)
    assert grid.world.grid.on and not brute.world.grid.on
    runs = [sim.rollout(sim.init(n_envs=3, seed=11), 120) for sim in (grid, brute)]
    (s_g, r_g), (s_b, r_b) = runs
    assert r_b.counters["collisions"].sum() > 0  # the test exercises contacts
    for name in ("collisions", "wall_contacts", "wall_onsets", "wall_readings"):
        np.testing.assert_array_equal(r_g.counters[name], r_b.counters[name])
    np.testing.assert_array_equal(r_g.pose, r_b.pose)
    np.testing.assert_array_equal(r_g.sonar, r_b.sonar)
    np.testing.assert_array_equal(r_g.ranging, r_b.ranging)
    np.testing.assert_array_equal(r_g.sonar_ideal, r_b.sonar_ideal)
    np.testing.assert_array_equal(r_g.sonar_hit, r_b.sonar_hit)
    if r_b.wall is not None:
        np.testing.assert_array_equal(r_g.wall, r_b.wall)
    if "wall_check" in str(sonar):
        assert r_b.counters["wall_readings"].sum() > 0  # the check judged readings
    assert (r_b.sonar_hit == 2).any()  # copter echoes happen
    np.testing.assert_array_equal(s_g.world.in_collision, s_b.world.in_collision)


@pytest.mark.parametrize("check", ["per_reading", "sequence"])
def test_without_recorded_ranging_the_grid_leaves_out_of_range_columns_and_nothing_changes(check):
    """With the grid on and the ranging not recorded, the wall check reads only the ranging columns in range, so
    the engine does not fill the others with max_range at every step (10⁸ writes per step at N = 10 000): the
    flight — poses, sonar, wall flags and every counter — is the brute force's (which fills and reads every column),
    bit for bit. The rows are the sim's buffer, kept between rollouts: poisoned with NaN beforehand and reused by
    three consecutive rollouts, they still give the brute force's flight (no entry is read before it is written)."""
    cfg = Config().replace({**CROWDED, "behaviour.kind": "attraction_repulsion", "behaviour.wall_check": check})
    grid = SwarmSim(cfg.replace({"simulation.grid_min_copters": 0}))
    brute = SwarmSim(cfg)
    names = ["pose", "sonar", "wall"]
    s_b, r_b = brute.rollout(brute.init(n_envs=2, seed=5), 120, record=names)
    rows = grid._ranging_rows(2, 40, 40)
    rows[:] = np.nan
    s_g, parts = grid.init(n_envs=2, seed=5), []
    for _ in range(3):
        s_g, r = grid.rollout(s_g, 40, record=names)
        parts.append(r)
    assert grid._ranging_rows(2, 40, 40) is rows and np.isnan(rows).any()  # reused; columns out of range untouched
    r_g = concat_records(parts)
    assert r_g.ranging is None or r_g.ranging.size == 0
    assert r_b.counters["wall_readings"].sum() > 0  # the check judged readings
    for name in r_b.counters:
        np.testing.assert_array_equal(r_g.counters[name], r_b.counters[name])
    for name in names:
        np.testing.assert_array_equal(getattr(r_g, name), getattr(r_b, name))
    np.testing.assert_array_equal(s_g.world.pos, s_b.world.pos)


def test_a_pickled_or_copied_sim_flies_the_same_and_leaves_the_kept_rows_behind():
    """Process pools and Dask ship a sim by pickle: the copy (pickled or deep-copied) starts without the
    original's kept ranging rows and flies the original's flight bit for bit."""
    cfg = Config().replace({**CROWDED, "behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "sequence",
                            "simulation.grid_min_copters": 0})
    sim = SwarmSim(cfg)
    _, r_0 = sim.rollout(sim.init(n_envs=2, seed=3), 30, record=["pose", "sonar"])
    kept = sim._ranging_rows(2, 40, 40)
    for copy_of in (lambda s: pickle.loads(pickle.dumps(s)), copy.deepcopy):
        clone = copy_of(sim)
        assert clone.cfg == cfg and getattr(clone._work, "ranging_rows", None) is None
        # the same numba types as the original's (read-only model tables), so the copy's flight compiles nothing new
        assert numba.typeof(clone.ranging.params) == numba.typeof(sim.ranging.params)
        assert numba.typeof(clone.ranging.ideal_params) == numba.typeof(sim.ranging.ideal_params)
        _, r = clone.rollout(clone.init(n_envs=2, seed=3), 30, record=["pose", "sonar"])
        np.testing.assert_array_equal(r.pose, r_0.pose)
        np.testing.assert_array_equal(r.sonar, r_0.sonar)
        assert clone._ranging_rows(2, 40, 40) is not kept


def test_world_step_and_vector_env_step_use_the_grid_identically():
    cfg = Config().replace(CROWDED)
    worlds = [World(cfg.replace({"simulation.grid_min_copters": m})) for m in (0, 10**6)]
    states = [w.init(n_envs=4, seed=2) for w in worlds]
    rng = np.random.default_rng(0)
    for _ in range(60):
        cmd = rng.normal(0.0, 0.5, size=(4, 40, 2))
        states = [w.step(s, cmd) for w, s in zip(worlds, states)]
    assert states[1].collisions.sum() > 0
    np.testing.assert_array_equal(states[0].collisions, states[1].collisions)
    np.testing.assert_array_equal(states[0].pos, states[1].pos)

    from finkensim.swarm.control import Controlled
    sims = [SwarmSim(cfg.replace({"simulation.grid_min_copters": m})) for m in (0, 10**6)]
    ctls = [Controlled(s) for s in sims]
    sts = [s.init(n_envs=4, seed=5) for s in sims]
    for _ in range(40):
        cmd = rng.normal(0.0, 0.5, size=(4, 40, 2))
        out = [c.step(s, cmd) for c, s in zip(ctls, sts)]
        sts = [o[0] for o in out]
        np.testing.assert_array_equal(out[0][1].sonar, out[1][1].sonar)
        np.testing.assert_array_equal(out[0][1].ranging, out[1][1].ranging)
    np.testing.assert_array_equal(sts[0].world.collisions, sts[1].world.collisions)
    assert sts[1].world.collisions.sum() > 0
