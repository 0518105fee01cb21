"""Sonars: raycast geometry, error models, cross-talk, reproducibility (fixed seeds)."""
from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numba import njit
from scipy import stats

from finkensim.arena import Arena
from finkensim.kernels.rng import STREAM_SONAR, counter_key
from finkensim.sensors.sonar_kernels import measured_reading
from finkensim.config import Config
from finkensim.kernels.rng import STREAM_SONAR_SCHEDULE, uniforms_array
from finkensim.sensors.sonar import (
    HIT_COPTER, HIT_NONE, HIT_WALL, SonarModel, cast_ray, cast_ray_culled, crosstalk_path, down_readings, fire_slots,
    ideal_sonar, plate_bands, rayleigh_std, sonar_from_trajectory, sonar_readings,
)
from finkensim.behaviours.open_loop import RandomWalk
from finkensim.testing import strategies as fst
from finkensim.world import World
from tests.naive.sonar import naive_down, naive_ideal, naive_readings
from tests.stats import assert_mean_within_se, assert_proportion_within_se, assert_std_within_se, se_std_normal

HYP = settings(derandomize=True, deadline=None, max_examples=40,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def setup(n=1, profile="default", **sonar):
    """(cfg, arena, params) for a 3 x 4 m arena with n copters and sonar.* overrides."""
    cfg = Config(profile).replace({"copters.n": n, **{f"sonar.{k}": v for k, v in sonar.items()}})
    return cfg, Arena.from_config(cfg.arena, cfg.walls), SonarModel.from_config(cfg)


def arrays(pos, yaw, arena, theta=None):
    pos = np.asarray(pos, dtype=float)
    if pos.ndim == 2:
        pos = pos[None]
    yaw = np.asarray(yaw, dtype=float).reshape(pos.shape[:2])
    theta = np.zeros((pos.shape[0], arena.n_plates)) if theta is None else np.asarray(theta, dtype=float)
    return pos, yaw, theta


# ------------------------------------------------------------------ raycast


def test_axis_aligned_distances():
    _, arena, sp = setup()
    pos, yaw, th = arrays([[1.0, 2.0]], [0.0], arena)
    dist, kind, hit = ideal_sonar(pos, yaw, th, arena, sp)
    np.testing.assert_allclose(dist[0, 0], [2.0, 2.0, 1.0, 2.0], atol=1e-12)  # front, left, back, right
    assert (kind == HIT_WALL).all()
    np.testing.assert_allclose(hit[0, 0], [[3, 2], [1, 4], [0, 2], [1, 0]], atol=1e-12)
    # facing +y: front sees y = 4, left x = 0, back y = 0, right x = 3
    pos, yaw, th = arrays([[1.0, 2.1]], [np.pi / 2], arena)
    dist, _, _ = ideal_sonar(pos, yaw, th, arena, sp)
    np.testing.assert_allclose(dist[0, 0], [1.9, 1.0, 2.1, 2.0], atol=1e-12)


def test_offset_measured_from_sonar():
    _, arena, sp = setup(offset=0.1)
    pos, yaw, th = arrays([[1.0, 2.0]], [0.0], arena)
    dist, _, _ = ideal_sonar(pos, yaw, th, arena, sp)
    np.testing.assert_allclose(dist[0, 0], [1.9, 1.9, 0.9, 1.9], atol=1e-12)


def test_copter_in_beam_is_hit_before_wall_and_own_body_is_ignored():
    _, arena, sp = setup(n=2)
    pos, yaw, th = arrays([[1.0, 2.0], [2.2, 2.0]], [0.0, 0.0], arena)
    dist, kind, hit = ideal_sonar(pos, yaw, th, arena, sp)
    assert dist[0, 0, 0] == pytest.approx(1.2 - 0.15, abs=1e-12) and kind[0, 0, 0] == HIT_COPTER
    np.testing.assert_allclose(hit[0, 0, 0], [2.05, 2.0], atol=1e-12)
    assert dist[0, 1, 2] == pytest.approx(1.05, abs=1e-12) and kind[0, 1, 2] == HIT_COPTER  # B's back sees A
    assert dist[0, 1, 0] == pytest.approx(0.8, abs=1e-12) and kind[0, 1, 0] == HIT_WALL  # not its own rim


def _east_plate_at(arena, y):
    for s in range(arena.n_plates):
        if arena.wall_index[s] == 1 and min(arena.plate_a[s, 1], arena.plate_b[s, 1]) < y < max(
                arena.plate_a[s, 1], arena.plate_b[s, 1]):
            return s
    raise AssertionError("no plate")


@pytest.mark.parametrize("angle", [0.1, 0.3, 0.7])
def test_bent_plate_shortens_by_displacement(angle):
    _, arena, sp = setup()
    s = _east_plate_at(arena, 2.1)
    th = np.zeros((1, arena.n_plates))
    th[0, s] = angle
    pos, yaw, _ = arrays([[1.0, 2.1]], [0.0], arena)
    flat, _, _ = ideal_sonar(pos, yaw, np.zeros_like(th), arena, sp)
    bent, kind, _ = ideal_sonar(pos, yaw, th, arena, sp)
    assert flat[0, 0, 0] - bent[0, 0, 0] == pytest.approx(arena.lever * math.sin(angle), abs=1e-12)
    assert kind[0, 0, 0] == HIT_WALL
    # a plate swung outward is behind the net: the net (backstop) still stops the ray
    th[0, s] = -angle
    out, kind, _ = ideal_sonar(pos, yaw, th, arena, sp)
    assert out[0, 0, 0] == pytest.approx(2.0, abs=1e-12) and kind[0, 0, 0] == HIT_WALL


def test_gap_between_plates_hits_net():
    _, arena, sp = setup()
    s = _east_plate_at(arena, 2.1)
    gap_y = max(arena.plate_a[s, 1], arena.plate_b[s, 1]) + 0.001  # just past the plate edge
    th = np.full((1, arena.n_plates), 0.5)
    pos, yaw, _ = arrays([[1.0, gap_y]], [0.0], arena)
    dist, kind, _ = ideal_sonar(pos, yaw, th, arena, sp)
    assert dist[0, 0, 0] == pytest.approx(2.0, abs=1e-12) and kind[0, 0, 0] == HIT_WALL


def scenes(n=3):
    """(pos (1, n, 2), yaw (1, n), theta (1, S)) of a default-arena world: the public world-state strategy
    (copters anywhere they can be, plates swinging up to ±1.5 rad)."""
    cfg = Config().replace({"copters.n": n})
    return fst.world_states(cfg, n_envs=1, moving=False).map(lambda s: (s.pos, s.yaw, s.theta))


@pytest.mark.parametrize("sonar", [{}, {"offset": 0.08}, {"beam": "cone", "beam_rays": 5},
                                   {"max_range": 1.2, "beam": "cone", "cone_half_angle_deg": 20.0}])
@HYP
@given(scene=scenes())
def test_ideal_matches_numpy_reference(sonar, scene):
    _, arena, sp = setup(n=3, **sonar)
    pos, yaw, th = scene
    d1, k1, h1 = ideal_sonar(pos, yaw, th, arena, sp)
    d2, k2, h2 = naive_ideal(pos, yaw, th, arena, sp)
    np.testing.assert_allclose(d1, d2, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(k1, k2)
    np.testing.assert_allclose(h1, h2, rtol=0, atol=1e-9)
    assert np.all(d1 <= sp.max_range) and np.all(d1 >= 0.0)


# ------------------------------------------------------------------ error models

MODELS = [
    {},  # default: rayleigh (sign -1) + geometric cross-talk, round robin
    {"error": "seed", "crosstalk": "constant"},
    {"error": "gaussian", "crosstalk": "off"},
    {"error": "none", "crosstalk": "geometric", "schedule": "simultaneous"},
    {"error": "rayleigh", "crosstalk": "geometric", "schedule": "random_offset", "n_slots": 2},
    {"error": "gaussian", "crosstalk": "constant", "sigma": 0.3, "beam": "cone"},
    {"error": "rayleigh", "rayleigh_sign": 1.0, "sigma": 1.0, "crosstalk": "geometric", "schedule": "simultaneous",
     "offset": 0.05},
]


@pytest.mark.parametrize("sonar", MODELS)
@HYP
@given(scene=scenes(n=4), seed=st.integers(0, 2**40), step=st.integers(0, 10**6))
def test_readings_match_numpy_reference(sonar, scene, seed, step):
    _, arena, sp = setup(n=4, **sonar)
    pos, yaw, th = scene
    pos, yaw, th = np.repeat(pos, 2, 0), np.repeat(yaw, 2, 0), np.repeat(th, 2, 0)
    yaw[1] += 0.3
    env_ids = np.array([3, 11])
    r1 = sonar_readings(pos, yaw, th, arena, sp, seed, env_ids, step)
    r2 = naive_readings(pos, yaw, th, arena, sp, seed, env_ids, step)
    np.testing.assert_allclose(r1, r2, rtol=0, atol=1e-9)
    alt = np.array([[0.6, 0.1, 2.0, 3.5], [0.6, 0.6, 0.6, 0.6]])
    d1 = down_readings(pos, sp, seed, env_ids, step, altitude=alt)
    np.testing.assert_allclose(d1, naive_down(alt, sp, seed, env_ids, step), rtol=0, atol=1e-9)


@pytest.mark.parametrize("sonar", MODELS + [{"error": "seed", "crosstalk": "constant", "sigma": 1.0}])
def test_every_reading_in_range(sonar):
    cfg, arena, sp = setup(n=6, **sonar)
    world = World(cfg)
    state = world.init(64, seed=5)
    state, _ = world.rollout(state, 30, RandomWalk(cfg), record=False)
    for step in range(3):
        r = sonar_readings(state.pos, state.yaw, state.theta, arena, sp, 5, state.env_ids, step)
        assert r.shape == (64, 6, 4) and np.all(r >= 0.2) and np.all(r <= 3.0)
        d = down_readings(state.pos, sp, 5, state.env_ids, step)
        assert d.shape == (64, 6) and np.all(d >= 0.2) and np.all(d <= 3.0)


@pytest.mark.parametrize("error", ["rayleigh", "seed", "gaussian", "none"])
@pytest.mark.parametrize("crosstalk", ["off", "geometric"])
def test_no_echo_reads_max_range(error, crosstalk):
    _, arena, sp = setup(n=1, max_range=1.0, error=error, crosstalk=crosstalk, sigma=0.3)
    pos, yaw, th = arrays(np.tile([[1.5, 2.0]], (50, 1, 1)), np.zeros((50, 1)), arena, np.zeros((50, 64)))
    r, dist, kind, _ = sonar_readings(pos, yaw, th, arena, sp, 1, np.arange(50), 0, return_ideal=True)
    assert (kind == HIT_NONE).all() and np.all(dist == 1.0)
    assert np.all(r == 1.0)
    d = down_readings(pos, sp, 1, np.arange(50), 0, altitude=1.5)
    assert np.all(d == 1.0)


def test_ideal_below_min_range_is_clamped_in_readings():
    _, arena, sp = setup(n=2, error="none", crosstalk="off")
    pos, yaw, th = arrays([[1.0, 2.0], [1.32, 2.0]], [0.0, 0.0], arena)
    r, dist, kind, _ = sonar_readings(pos, yaw, th, arena, sp, 0, [0], 0, return_ideal=True)
    assert dist[0, 0, 0] == pytest.approx(0.17, abs=1e-12) and kind[0, 0, 0] == HIT_COPTER
    assert r[0, 0, 0] == 0.2


def _seed_profile_sample(B=5000, sigma=None):
    extra = {} if sigma is None else {"sigma": sigma}
    _, arena, sp = setup(n=1, profile="seed", **extra)
    pos, yaw, th = arrays(np.tile([[1.5, 2.0]], (B, 1, 1)), np.zeros((B, 1)), arena, np.zeros((B, 64)))
    r = sonar_readings(pos, yaw, th, arena, sp, 2024, np.arange(B), 17)
    true = np.array([1.5, 2.0, 1.5, 2.0])
    return sp, r[:, 0, :], np.broadcast_to(true, (B, 4))


def test_seed_profile_crosstalk_rate_and_rayleigh_term():
    sp, r, true = _seed_profile_sample()
    assert sp.error == 3 and sp.crosstalk == 1 and sp.crosstalk_probability == 0.68
    halved = r == 0.5 * true
    assert np.all(halved | (r > 0.9 * true))  # either exactly d/2 or d + (R - s)
    # 20 000 readings: SE √(p(1−p)/n) = 0.0033, 5 SE = 0.016 (2.4 % of 0.68)
    assert_proportion_within_se(halved, 0.68, what="seed-profile cross-talk rate")
    R = r[~halved] - true[~halved] + rayleigh_std(sp.sigma)
    assert stats.kstest(R, stats.rayleigh(scale=sp.sigma).cdf).pvalue > 1e-3
    assert stats.kstest(R, stats.rayleigh(scale=1.3 * sp.sigma).cdf).pvalue < 1e-6  # the test has power


def test_default_rayleigh_runs_short():
    _, arena, sp = setup(n=1, crosstalk="off", sigma=0.1)
    B = 4000
    pos, yaw, th = arrays(np.tile([[1.5, 2.0]], (B, 1, 1)), np.zeros((B, 1)), arena, np.zeros((B, 64)))
    r = sonar_readings(pos, yaw, th, arena, sp, 9, np.arange(B), 0)[:, 0, :]
    R = -(r - np.array([1.5, 2.0, 1.5, 2.0])) + rayleigh_std(0.1)
    assert stats.kstest(R.ravel(), stats.rayleigh(scale=0.1).cdf).pvalue > 1e-3
    # short on average by (√(π/2) − 0.6551)·σ = 0.0598 m; 16 000 readings: SE (from the sample) ≈ 0.0005 m, 5 SE ≈
    # 4.4 % of the shortfall
    short = rayleigh_std(0.1) - math.sqrt(math.pi / 2) * 0.1
    assert short < 0
    assert_mean_within_se(r - [1.5, 2.0, 1.5, 2.0], short, what="mean Rayleigh reading error (runs short)")


def test_gaussian_moments():
    _, arena, sp = setup(n=1, error="gaussian", crosstalk="off", sigma=0.1)
    B = 4000
    pos, yaw, th = arrays(np.tile([[1.5, 2.0]], (B, 1, 1)), np.zeros((B, 1)), arena, np.zeros((B, 64)))
    e = (sonar_readings(pos, yaw, th, arena, sp, 3, np.arange(B), 0)[:, 0, :] - [1.5, 2.0, 1.5, 2.0]).ravel()
    assert stats.kstest(e, stats.norm(scale=0.1).cdf).pvalue > 1e-3


# ------------------------------------------------------------------ geometric cross-talk


def test_geometric_crosstalk_fires_when_facing_in_same_slot():
    _, arena, sp = setup(n=2, error="none", crosstalk_jitter=0.0, schedule="simultaneous")
    pos, yaw, th = arrays([[1.0, 2.0], [2.0, 2.0]], [0.0, np.pi], arena)
    r, dist, _, _ = sonar_readings(pos, yaw, th, arena, sp, 0, [0], 0, return_ideal=True)
    assert dist[0, 0, 0] == pytest.approx(0.85) and dist[0, 1, 0] == pytest.approx(0.85)
    assert r[0, 0, 0] == pytest.approx(0.5, abs=1e-12) and r[0, 1, 0] == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(r[0, :, 1:], dist[0, :, 1:], atol=1e-12)  # no emitter in the other cones
    # with jitter, the cross-talk reading is 0.5 + N(0, jitter^2): still the first arrival here
    _, _, spj = setup(n=2, error="rayleigh", crosstalk_jitter=0.02, schedule="simultaneous")
    B = 5000
    pos2, yaw2, th2 = arrays(np.tile(pos, (B, 1, 1)), np.tile(yaw, (B, 1)), arena, np.zeros((B, 64)))
    rj = sonar_readings(pos2, yaw2, th2, arena, spj, 0, np.arange(B), 0)
    x = rj[:, :, 0].ravel()
    # 10 000 readings: SE of the mean σ/√n = 0.0002 m (5 SE = 0.2 % of 0.5 m), of the std σ/√(2(n−1)) = 0.00014 m
    # (5 SE = 3.5 % of the 0.02 m jitter)
    assert_mean_within_se(x, 0.5, se=0.02 / np.sqrt(x.size), what="cross-talk reading mean with jitter")
    assert_std_within_se(x, 0.02, se=se_std_normal(0.02, x.size), what="cross-talk reading std (jitter)")


def test_round_robin_different_slots_never_crosstalk():
    pos = [[1.0, 2.0], [2.0, 2.0]]
    _, arena, sp = setup(n=2, error="none", crosstalk_jitter=0.0, schedule="round_robin", n_slots=2)
    p, y, th = arrays(pos, [0.0, np.pi], arena)
    r, dist, _, _ = sonar_readings(p, y, th, arena, sp, 0, [0], 0, return_ideal=True)
    np.testing.assert_allclose(r, np.clip(dist, 0.2, 3.0), atol=0)
    np.testing.assert_array_equal(fire_slots(sp, 0, [0], 0, 2), [[0, 1]])
    _, arena, sp1 = setup(n=2, error="none", crosstalk_jitter=0.0, schedule="round_robin", n_slots=1)
    r1 = sonar_readings(p, y, th, arena, sp1, 0, [0], 0)
    assert r1[0, 0, 0] == pytest.approx(0.5)


def test_random_offset_slots_from_schedule_stream():
    _, _, sp = setup(n=7, schedule="random_offset", n_slots=3)
    slots = fire_slots(sp, 42, [5, 9], 13, 7)
    for b, env in enumerate([5, 9]):
        for n in range(7):
            u = uniforms_array(42, env, 13, n, STREAM_SONAR_SCHEDULE, 1)[0]
            assert slots[b, n] == int(u * 3)
    assert set(np.unique(fire_slots(sp, 1, np.arange(50), 0, 7))) == {0, 1, 2}


def test_no_crosstalk_without_emitter_in_cone_constructed():
    # narrow cones: B at bearing 45 deg from A lies in none of A's cones
    _, arena, sp = setup(n=2, error="none", crosstalk_jitter=0.0, schedule="simultaneous", cone_half_angle_deg=20.0)
    p, y, th = arrays([[1.0, 2.0], [2.0, 3.0]], [0.0, -3 * np.pi / 4], arena)  # B's front points at A
    r, dist, _, _ = sonar_readings(p, y, th, arena, sp, 0, [0], 0, return_ideal=True)
    np.testing.assert_array_equal(r, np.clip(dist, 0.2, 3.0))
    # B in A's front cone but none of B's sonars points toward A (A at 45 deg off every B axis)
    p, y, th = arrays([[1.0, 2.0], [2.0, 2.0]], [0.0, np.pi / 4], arena)
    r, dist, _, _ = sonar_readings(p, y, th, arena, sp, 0, [0], 0, return_ideal=True)
    np.testing.assert_array_equal(r, np.clip(dist, 0.2, 3.0))
    # turn B to face A: now it fires
    p, y, th = arrays([[1.0, 2.0], [2.0, 2.0]], [0.0, np.pi], arena)
    r = sonar_readings(p, y, th, arena, sp, 0, [0], 0)
    assert r[0, 0, 0] == pytest.approx(0.5)


@HYP
@given(scene=scenes(n=3), half=st.floats(5.0, 89.0), seed=st.integers(0, 1000))
def test_geometric_crosstalk_needs_emitter_in_receiver_cone(scene, half, seed):
    _, arena, sp = setup(n=3, error="none", crosstalk_jitter=0.0, schedule="simultaneous", cone_half_angle_deg=half)
    pos, yaw, th = scene
    r, dist, _, _ = sonar_readings(pos, yaw, th, arena, sp, seed, [0], 0, return_ideal=True)
    h = math.radians(half)
    for n in range(3):
        for k in range(4):
            psi = yaw[0, n] + sp.mount_yaw[k]
            u = np.array([math.cos(psi), math.sin(psi)])
            seen = False
            for m in range(3):
                if m != n:
                    w = pos[0, m] - pos[0, n]
                    seen |= u @ w >= math.cos(h) * np.linalg.norm(w) - 1e-12
            if not seen:
                assert r[0, n, k] == np.clip(dist[0, n, k], 0.2, 3.0)
            else:
                assert r[0, n, k] <= np.clip(dist[0, n, k], 0.2, 3.0)  # cross-talk can only shorten


# ------------------------------------------------------------------ beam, reproducibility


def test_cone_beam_sees_off_axis_copter():
    b = (1.0 + math.cos(math.radians(30)), 2.0 + math.sin(math.radians(30)))
    _, arena, ray = setup(n=2)
    _, _, cone = setup(n=2, beam="cone", beam_rays=7)  # rays every 15 deg across +-45 deg
    p, y, th = arrays([[1.0, 2.0], b], [0.0, np.pi / 2], arena)
    d_ray, k_ray, _ = ideal_sonar(p, y, th, arena, ray)
    d_cone, k_cone, h_cone = ideal_sonar(p, y, th, arena, cone)
    assert k_ray[0, 0, 0] == HIT_WALL and d_ray[0, 0, 0] == pytest.approx(2.0)
    assert k_cone[0, 0, 0] == HIT_COPTER and d_cone[0, 0, 0] == pytest.approx(0.85, abs=1e-12)
    assert np.hypot(*(h_cone[0, 0, 0] - b)) == pytest.approx(0.15, abs=1e-12)


@pytest.mark.parametrize("profile,sonar", [("default", {"schedule": "random_offset"}), ("seed", {}),
                                           ("default", {"beam": "cone", "error": "gaussian",
                                                        "schedule": "simultaneous"})])
def test_same_seed_same_readings_any_batch_and_threads(profile, sonar):
    cfg, arena, sp = setup(n=6, profile=profile, **sonar)
    world = World(cfg)
    state, _ = world.rollout(world.init(64, seed=11), 20, RandomWalk(world.cfg), record=False)
    full = sonar_readings(state.pos, state.yaw, state.theta, arena, sp, 11, state.env_ids, 20)
    down = down_readings(state.pos, sp, 11, state.env_ids, 20)
    for k in (0, 17, 63):
        one = state.select([k])
        assert one.env_ids.tolist() == [k]
        r1 = sonar_readings(one.pos, one.yaw, one.theta, arena, sp, 11, one.env_ids, 20)
        np.testing.assert_array_equal(r1[0], full[k])
        np.testing.assert_array_equal(down_readings(one.pos, sp, 11, one.env_ids, 20)[0], down[k])
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        again = sonar_readings(state.pos, state.yaw, state.theta, arena, sp, 11, state.env_ids, 20)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(again, full)
    other = sonar_readings(state.pos, state.yaw, state.theta, arena, sp, 12, state.env_ids, 20)
    if sp.error != 0:
        assert not np.array_equal(other, full)


def test_trajectory_equals_per_step_readings():
    cfg, arena, sp = setup(n=4)
    world = World(cfg)
    state = world.init(3, seed=4)
    _, traj = world.rollout(state, 6, RandomWalk(world.cfg))
    out, dist, kind, hit = sonar_from_trajectory(traj, arena, sp, 4, state.env_ids, 0, return_ideal=True)
    assert out.shape == (6, 3, 4, 4) and hit.shape == (6, 3, 4, 4, 2)
    for t in range(6):
        r = sonar_readings(traj.pose[t, ..., :2], traj.pose[t, ..., 2], traj.theta[t], arena, sp, 4,
                                state.env_ids, t)
        np.testing.assert_array_equal(out[t], r)


def test_down_sonar():
    _, _, sp = setup(n=3, error="none")
    pos = np.zeros((2, 3, 2))
    np.testing.assert_array_equal(down_readings(pos, sp, 0, [0, 1], 0), np.full((2, 3), 0.6))
    _, _, sp = setup(n=3)
    d = down_readings(np.zeros((20_000, 3, 2)), sp, 0, np.arange(20_000), 0)
    assert np.all(d <= 0.6 + rayleigh_std(0.05))
    # default: d = 0.6 − (R − s), so 0.6 − d + s ~ Rayleigh(σ), mean 0.6 − 0.5982σ (runs short), std s
    assert stats.kstest(0.6 - d.ravel() + rayleigh_std(0.05), stats.rayleigh(scale=0.05).cdf).pvalue > 1e-3
    # SE s/√n = 0.00013 m for 60 000 readings; 5 SE = 0.00067 m, the mean's change for a 2.2 % error in σ
    se = rayleigh_std(0.05) / np.sqrt(d.size)
    assert_mean_within_se(d, 0.6 - (math.sqrt(math.pi / 2) * 0.05 - rayleigh_std(0.05)), se=se,
                          what="down-sonar reading mean")


# ------------------------------------------------------------------ culled raycast (fast path) vs full search


@njit(cache=True)
def _culled_vs_full(ox, oy, dx, dy, pos_b, radius, pa, pb, width, length):
    """Per ray: (t culled, kind culled, t full, kind full), plus whether the culling layout check passed."""
    bands = plate_bands(pa, pb, width, length)
    out = np.empty((ox.shape[0], 4))
    for i in range(ox.shape[0]):
        everyone = np.empty(0, dtype=np.int64)
        ray = (ox[i], oy[i], dx[i], dy[i])
        t1, k1 = cast_ray_culled(ray, 0, pos_b, radius, (pa, pb, width, length), bands, everyone, -1)
        t2, k2 = cast_ray(ray, 0, pos_b, radius, (pa, pb, width, length), everyone, -1)
        out[i, 0] = t1
        out[i, 1] = k1
        out[i, 2] = t2
        out[i, 3] = k2
    return out, bands[0]


_SPECIAL_THETAS = [0.0, -0.0, 0.5, -0.5, 0.5 * math.pi, -0.5 * math.pi, 1e-300, 0.3]


@st.composite
def ray_scenes(draw):
    """Arena (n_segments, size, plate width, lever), plate angles with repeated / extreme values, and rays
    from anywhere (inside, on and outside the rectangle, near walls and corners) aimed at random, along the
    axes, or at plate ends and pitch borders (± a few ulps / a small offset)."""
    n_seg = draw(st.sampled_from([1, 2, 3, 16, 40]))
    W = draw(st.sampled_from([3.0, 0.5, 7.3]))
    L = draw(st.sampled_from([4.0, 0.5, 11.1]))
    frac = draw(st.sampled_from([0.9, 1.0, 0.3]))
    hinge = draw(st.sampled_from([1.0, 2.5, 0.61]))
    cfg = Config().replace({"arena.width": W, "arena.length": L, "walls.n_segments": n_seg, "copters.n": 1,
                            "walls.plate_width_fraction": frac, "walls.hinge_height": hinge,
                            "walls.plate_length": min(1.0, hinge)})
    arena = Arena.from_config(cfg.arena, cfg.walls)
    S = arena.n_plates
    th = np.array(draw(st.lists(st.one_of(st.floats(-1.6, 1.6), st.sampled_from(_SPECIAL_THETAS)),
                                min_size=S, max_size=S)))
    pa, pb = arena.plate_surfaces(th[None])
    pa, pb = np.ascontiguousarray(pa[0]), np.ascontiguousarray(pb[0])
    R = 12
    ox, oy, dx, dy = np.empty(R), np.empty(R), np.empty(R), np.empty(R)
    for i in range(R):
        where = draw(st.sampled_from(["inside", "near_wall", "near_corner", "anywhere"]))
        if where == "inside":
            o = (draw(st.floats(0.0, W)), draw(st.floats(0.0, L)))
        elif where == "near_wall":
            s = draw(st.integers(0, S - 1))
            a = pa[s] + draw(st.floats(0.0, 1.0)) * (pb[s] - pa[s])
            o = tuple(a + arena.normal[s] * draw(st.sampled_from([0.0, 1e-12, -1e-12, 0.01, 0.2])))
        elif where == "near_corner":
            c = draw(st.sampled_from([(0.0, 0.0), (W, 0.0), (W, L), (0.0, L)]))
            o = (c[0] + draw(st.floats(-0.05, 0.05)) + (0.3 if c[0] == 0 else -0.3) * draw(st.floats(0.0, 1.0)),
                 c[1] + draw(st.floats(-0.05, 0.05)) + (0.3 if c[1] == 0 else -0.3) * draw(st.floats(0.0, 1.0)))
        else:
            o = (draw(st.floats(-1.0, W + 1.0)), draw(st.floats(-1.0, L + 1.0)))
        aim = draw(st.sampled_from(["random", "axis", "plate_end", "pitch_border", "corner"]))
        if aim == "random":
            a = draw(st.floats(-math.pi, math.pi))
            d = (math.cos(a), math.sin(a))
        elif aim == "axis":
            d = draw(st.sampled_from([(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (-0.0, 1.0)]))
        else:
            if aim == "plate_end":
                s = draw(st.integers(0, S - 1))
                p = (pa[s] if draw(st.booleans()) else pb[s]).copy()
            elif aim == "pitch_border":
                s = draw(st.integers(0, S - 1))
                p = arena.seg_a[s] + arena.normal[s] * arena.displacement(th[s])
            else:
                p = np.array(draw(st.sampled_from([(0.0, 0.0), (W, 0.0), (W, L), (0.0, L)])))
            p = p + np.array([draw(st.sampled_from([0.0, 1e-15, -1e-15, 1e-9, -1e-9, 1e-4])),
                              draw(st.sampled_from([0.0, 1e-15, -1e-15, 1e-9, -1e-9, 1e-4]))])
            v = p - np.array(o)
            nv = math.hypot(v[0], v[1])
            d = (v[0] / nv, v[1] / nv) if nv > 0.0 else (1.0, 0.0)
        ox[i], oy[i] = o
        dx[i], dy[i] = d
    pos = np.stack([np.array(draw(st.lists(st.floats(0.0, W), min_size=3, max_size=3))),
                    np.array(draw(st.lists(st.floats(0.0, L), min_size=3, max_size=3)))], -1)
    return arena, pa, pb, pos, ox, oy, dx, dy


@settings(derandomize=True, deadline=None, max_examples=100,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(scene=ray_scenes())
def test_culled_raycast_equals_full_search_bit_for_bit(scene):
    """The fast path tests only the plates in the bands the ray crosses before the net: same distance bits and
    kind as testing every plate, for displaced plates (both signs, at ±90°), rays at plate ends, pitch borders
    and corners, from inside, on and outside the rectangle."""
    arena, pa, pb, pos, ox, oy, dx, dy = scene
    out, ok = _culled_vs_full(ox, oy, dx, dy, pos, 0.15, pa, pb, arena.width, arena.length)
    assert ok  # the Arena layout always qualifies for culling
    np.testing.assert_array_equal(out[:, 0].view(np.int64), out[:, 2].view(np.int64))
    np.testing.assert_array_equal(out[:, 1], out[:, 3])


def test_culled_raycast_many_random_rays_and_border_rays():
    """Bulk check: 200 000 rays against bent plates (default arena), random and aimed at every plate end."""
    cfg = Config()
    arena = Arena.from_config(cfg.arena, cfg.walls)
    rng = np.random.default_rng(3)
    for _ in range(10):
        th = rng.uniform(-0.8, 1.4, arena.n_plates) * (rng.random(arena.n_plates) < 0.8)
        pa, pb = (np.ascontiguousarray(x[0]) for x in arena.plate_surfaces(th[None]))
        n = 10_000
        ox, oy = rng.uniform(0, 3, n), rng.uniform(0, 4, n)
        a = rng.uniform(-np.pi, np.pi, n)
        dx, dy = np.cos(a), np.sin(a)
        ends = np.concatenate([pa, pb])[rng.integers(0, 2 * arena.n_plates, n)] + rng.normal(0, 1e-6, (n, 2))
        v = ends - np.stack([ox, oy], -1)
        v /= np.hypot(v[:, 0], v[:, 1])[:, None]
        pos = np.stack([rng.uniform(0, 3, 4), rng.uniform(0, 4, 4)], -1)
        for ddx, ddy in ((dx, dy), (v[:, 0].copy(), v[:, 1].copy())):
            out, ok = _culled_vs_full(ox, oy, ddx, ddy, pos, 0.15, pa, pb, 3.0, 4.0)
            assert ok
            np.testing.assert_array_equal(out[:, 0].view(np.int64), out[:, 2].view(np.int64))
            np.testing.assert_array_equal(out[:, 1], out[:, 3])


def test_culled_raycast_falls_back_when_layout_differs():
    """Plates not in the Arena layout (shuffled) or NaN: no culling, the full search's answer."""
    cfg = Config()
    arena = Arena.from_config(cfg.arena, cfg.walls)
    rng = np.random.default_rng(0)
    th = rng.uniform(-0.5, 1.0, arena.n_plates)
    pa, pb = (np.ascontiguousarray(x[0]) for x in arena.plate_surfaces(th[None]))
    perm = rng.permutation(arena.n_plates)
    ox, oy = rng.uniform(0, 3, 500), rng.uniform(0, 4, 500)
    a = rng.uniform(-np.pi, np.pi, 500)
    pos = np.zeros((0, 2))
    for qa, qb in ((pa[perm].copy(), pb[perm].copy()), (np.where(np.arange(64)[:, None] == 5, np.nan, pa), pb)):
        out, ok = _culled_vs_full(ox, oy, np.cos(a), np.sin(a), pos, 0.15, qa, qb, 3.0, 4.0)
        assert not ok
        np.testing.assert_array_equal(out[:, 0], out[:, 2])
        np.testing.assert_array_equal(out[:, 1], out[:, 3])


@pytest.mark.parametrize("sonar", [{}, {"beam": "cone", "beam_rays": 5}, {"offset": 0.2}])
def test_ideal_readings_near_corners_and_bent_borders_match_reference(sonar):
    """Copters in the corners and along the walls, facing corners and plate borders, every plate bent either
    way: ideal readings (fast path) equal the NumPy reference."""
    _, arena, sp = setup(n=8, **sonar)
    r = 0.15
    pos = np.array([[r, r], [3 - r, r], [3 - r, 4 - r], [r, 4 - r], [1.5, r + 0.01], [3 - r - 1e-9, 2.0],
                    [3 * 5 / 16, 4 - r], [r, 4 * 9 / 16]])
    rng = np.random.default_rng(7)
    for _ in range(20):
        yaw = rng.choice([np.pi / 4, 3 * np.pi / 4, -np.pi / 4, -3 * np.pi / 4, 0.0, np.pi / 2], 8) \
            + rng.normal(0, 0.05, 8)
        th = rng.choice([0.0, 0.4, -0.4, 1.2, np.pi / 2], arena.n_plates)
        d1, k1, h1 = ideal_sonar(pos[None], yaw[None], th[None], arena, sp)
        d2, k2, h2 = naive_ideal(pos[None], yaw[None], th[None], arena, sp)
        np.testing.assert_allclose(d1, d2, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(k1, k2)
        np.testing.assert_allclose(h1, h2, rtol=0, atol=1e-12)


# ------------------------------------------------------------------ cross-talk: the kernel vs the plain loop


@njit(cache=True)
def _crosstalk_plain(n, k, sonar_buf, slot, sp):
    """The definition of crosstalk_path as a plain loop: every same-slot emitter, a sqrt each, then the comparisons."""
    rx = sonar_buf[n, k, 0]
    ry = sonar_buf[n, k, 1]
    ux = sonar_buf[n, k, 2]
    uy = sonar_buf[n, k, 3]
    lim = 2.0 * sp.max_range
    ch = sp.cos_half_angle
    best = np.inf
    for m in range(sonar_buf.shape[0]):
        if m == n or slot[m] != slot[n]:
            continue
        for j in range(4):
            wx = sonar_buf[m, j, 0] - rx
            wy = sonar_buf[m, j, 1] - ry
            L = np.sqrt(wx * wx + wy * wy)
            if L <= 0.0 or L > lim or L >= best:
                continue
            if ux * wx + uy * wy >= ch * L and -(sonar_buf[m, j, 2] * wx + sonar_buf[m, j, 3] * wy) >= ch * L:
                best = L
    return best


@njit(cache=True)
def _crosstalk_both(sonar_buf, slot, sp, spread=np.inf):
    N = sonar_buf.shape[0]
    out = np.empty((N, 4, 2))
    scratch = np.full(N, -1, dtype=np.int64)
    for n in range(N):
        for k in range(4):
            out[n, k, 0] = crosstalk_path(n, k, sonar_buf, slot, sp, np.empty(0, dtype=np.int64), -1, spread, scratch)
            out[n, k, 1] = _crosstalk_plain(n, k, sonar_buf, slot, sp)
    return out


# the cross-talk scene tests: many fixed examples (the edge cases are drawn, not listed)
crosstalk_scene_settings = settings(derandomize=True, deadline=None, max_examples=400,
                                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@st.composite
def crosstalk_scenes(draw):
    """Sonars on a coarse grid (exact alignments, equal lengths, coincident sonars, lengths exactly 2·max_range)
    or anywhere, headings at multiples of 45° (the default cone edge), aimed at another sonar turned by exactly
    ± the half angle (± ulps), or random; one or two slots."""
    N = draw(st.integers(2, 7))
    half = draw(st.sampled_from([45.0, 30.0, 90.0, 10.0, 89.999]))
    max_range = draw(st.sampled_from([3.0, 0.5, 0.25, 1.0]))
    _, _, sp = setup(n=N, cone_half_angle_deg=half, max_range=max_range, min_range=min(0.03, max_range))
    buf = np.empty((N, 4, 4))
    for n in range(N):
        for j in range(4):
            if draw(st.booleans()):
                buf[n, j, 0] = 0.25 * draw(st.integers(0, 12))
                buf[n, j, 1] = 0.25 * draw(st.integers(0, 16))
            else:
                buf[n, j, 0] = draw(st.floats(0.0, 3.0))
                buf[n, j, 1] = draw(st.floats(0.0, 4.0))
    for n in range(N):
        for j in range(4):
            how = draw(st.sampled_from(["grid", "random", "edge"]))
            if how == "grid":
                a = math.radians(45.0 * draw(st.integers(-4, 3)))
            elif how == "random":
                a = draw(st.floats(-math.pi, math.pi))
            else:
                m, i = draw(st.integers(0, N - 1)), draw(st.integers(0, 3))
                w = buf[m, i, :2] - buf[n, j, :2]
                a = math.atan2(w[1], w[0]) + draw(st.sampled_from([1.0, -1.0])) * sp.half_angle \
                    + draw(st.sampled_from([0.0, 1e-16, -1e-16, 1e-12, -1e-12]))
            buf[n, j, 2], buf[n, j, 3] = math.cos(a), math.sin(a)
    slot = np.array(draw(st.lists(st.integers(0, draw(st.integers(0, 1))), min_size=N, max_size=N)), dtype=np.int64)
    return buf, slot, sp


@crosstalk_scene_settings
@given(scene=crosstalk_scenes())
def test_crosstalk_path_equals_the_plain_loop_bit_for_bit(scene):
    buf, slot, sp = scene
    out = _crosstalk_both(buf, slot, sp)
    np.testing.assert_array_equal(out[..., 0].view(np.int64), out[..., 1].view(np.int64))


@st.composite
def copter_crosstalk_scenes(draw):
    """Copters as the engine places their sonars (:func:`sonar_poses_env`: origin + offset · heading, so any two
    sonars of a copter lie within sonar_spread = 2·|offset|): centres on a coarse grid or anywhere (some far from the
    origin), headings at multiples of 45°, random, or turning a sonar exactly (± ulps) onto the cone edge toward
    another copter's sonar 0 — the cases where the copter-level rejection decides near its margin."""
    from finkensim.sensors.sonar_kernels import sonar_poses_env

    N = draw(st.integers(2, 7))
    half = draw(st.sampled_from([45.0, 30.0, 90.0, 10.0, 89.999, 0.5, 0.57]))
    max_range = draw(st.sampled_from([3.0, 0.5, 1.0]))
    offset = draw(st.sampled_from([0.0, 0.05, 0.1, 0.12]))
    _, _, sp = setup(n=N, cone_half_angle_deg=half, max_range=max_range, min_range=min(0.03, max_range), offset=offset)
    far = draw(st.sampled_from([0.0, 0.0, 100.0, 1e4]))
    pos = np.empty((N, 2))
    for n in range(N):
        if draw(st.booleans()):
            pos[n] = far + 0.25 * draw(st.integers(0, 12)), far + 0.25 * draw(st.integers(0, 16))
        else:
            pos[n] = far + draw(st.floats(0.0, 3.0)), far + draw(st.floats(0.0, 4.0))
    yaw = np.empty(N)
    for n in range(N):
        how = draw(st.sampled_from(["grid", "random", "edge"]))
        if how == "grid":
            yaw[n] = math.radians(45.0 * draw(st.integers(-4, 3)))
        elif how == "random":
            yaw[n] = draw(st.floats(-math.pi, math.pi))
        else:
            m, j = draw(st.integers(0, N - 1)), draw(st.integers(0, 3))
            w = pos[m] - pos[n]
            yaw[n] = math.atan2(w[1], w[0]) - sp.mount_yaw[j] + draw(st.sampled_from([1.0, -1.0])) * sp.half_angle \
                + draw(st.sampled_from([0.0, 1e-16, -1e-16, 1e-12, -1e-12, 1e-8, -1e-8]))
    buf = np.empty((N, 4, 4))
    sonar_poses_env(pos, yaw, sp, buf)
    slot = np.array(draw(st.lists(st.integers(0, draw(st.integers(0, 1))), min_size=N, max_size=N)), dtype=np.int64)
    return buf, slot, sp


@crosstalk_scene_settings
@given(scene=copter_crosstalk_scenes())
def test_crosstalk_copter_level_rejection_bit_identical(scene):
    """With sonar_spread, copters whose sonars all lie outside the receiver's cone are passed over with one test:
    every path is the plain loop's, bit for bit."""
    from finkensim.sensors.sonar_kernels import sonar_spread

    buf, slot, sp = scene
    out = _crosstalk_both(buf, slot, sp, sonar_spread(sp))
    np.testing.assert_array_equal(out[..., 0].view(np.int64), out[..., 1].view(np.int64))


def test_crosstalk_path_bulk_random():
    rng = np.random.default_rng(11)
    _, _, sp = setup(n=10)
    hits = 0
    for _ in range(300):
        buf = np.empty((10, 4, 4))
        buf[..., 0] = rng.uniform(0, 3, (10, 4))
        buf[..., 1] = rng.uniform(0, 4, (10, 4))
        a = rng.uniform(-np.pi, np.pi, (10, 4))
        buf[..., 2], buf[..., 3] = np.cos(a), np.sin(a)
        slot = rng.integers(0, 2, 10)
        out = _crosstalk_both(buf, slot, sp)
        np.testing.assert_array_equal(out[..., 0].view(np.int64), out[..., 1].view(np.int64))
        hits += int(np.isfinite(out[..., 0]).sum())
    assert hits > 1000  # many emitters actually heard


def test_crosstalk_copter_level_rejection_bulk_random():
    """Sonar buffers as the engine builds them, 10 copters anywhere in the arena, offsets 0–0.12 m: the copter-level
    rejection changes no path (and many are heard)."""
    from finkensim.sensors.sonar_kernels import sonar_poses_env, sonar_spread

    rng = np.random.default_rng(12)
    hits = 0
    for i in range(300):
        _, _, sp = setup(n=10, offset=float(rng.choice([0.0, 0.05, 0.12])))
        pos = np.column_stack([rng.uniform(0, 3, 10), rng.uniform(0, 4, 10)])
        buf = np.empty((10, 4, 4))
        sonar_poses_env(pos, rng.uniform(-np.pi, np.pi, 10), sp, buf)
        out = _crosstalk_both(buf, rng.integers(0, 2, 10), sp, sonar_spread(sp))
        np.testing.assert_array_equal(out[..., 0].view(np.int64), out[..., 1].view(np.int64))
        hits += int(np.isfinite(out[..., 0]).sum())
    assert hits > 300  # emitters actually heard


def test_sonar_scalars_are_the_models_scalar_fields():
    """sonar_scalars (compiled) keeps every scalar field of the SonarModel under its name and drops the arrays."""
    from finkensim.sensors.sonar_model import SonarScalars, sonar_scalars
    _, _, sp = setup(beam="cone", beam_rays=5)
    sp = sp._replace(bias=0.07, range_scale=1.03, crosstalk_hear_probability=0.5)
    sc = sonar_scalars(sp)
    assert isinstance(sc, SonarScalars)
    assert set(SonarScalars._fields) == set(SonarModel._fields) - {"mount_yaw", "ray_angles", "correction"}
    for f in SonarScalars._fields:
        assert getattr(sc, f) == getattr(sp, f), f


@settings(max_examples=200, deadline=None)
@given(yaws=st.lists(st.one_of(st.floats(-4.0, 4.0), st.floats(-1e4, 1e4)), min_size=1, max_size=6),
       mounts=st.lists(st.floats(-7.0, 7.0), min_size=4, max_size=4), offset=st.floats(0.0, 0.2))
def test_sonar_headings_within_the_stated_bound_of_cos_sin_of_the_sum(yaws, mounts, offset):
    """sonar_poses_env rotates each copter's (cos, sin) of its yaw by the mounts' (one sine and cosine per copter and
    per mount): within 1e-15 + 2.3e-16·|yaw + mount| of (cos, sin) of the float sum, a unit vector to 1e-15, and the
    origins offset along it."""
    from finkensim.sensors.sonar_kernels import sonar_poses_env

    _, _, sp = setup(n=len(yaws), offset=offset)
    sp = sp._replace(mount_yaw=np.array(mounts))
    yaw = np.array(yaws)
    pos = np.random.default_rng(len(yaws)).uniform(0, 3, (yaw.size, 2))
    buf = np.empty((yaw.size, 4, 4))
    sonar_poses_env(pos, yaw, sp, buf)
    psi = yaw[:, None] + np.array(mounts)[None, :]
    bound = 1e-15 + 2.3e-16 * np.abs(psi)
    assert np.all(np.abs(buf[..., 2] - np.cos(psi)) <= bound)
    assert np.all(np.abs(buf[..., 3] - np.sin(psi)) <= bound)
    assert np.all(np.abs(np.hypot(buf[..., 2], buf[..., 3]) - 1.0) <= 1e-15)
    np.testing.assert_array_equal(buf[..., 0], pos[:, None, 0] + sp.offset * buf[..., 2])
    np.testing.assert_array_equal(buf[..., 1], pos[:, None, 1] + sp.offset * buf[..., 3])


@njit(cache=True)
def _measured(d, echo, path, seed, k, sp):
    return measured_reading(d, echo, path, counter_key(seed, 0, 0, 0, STREAM_SONAR), k, sp)


@pytest.mark.parametrize("mode", ["constant", "geometric"])
def test_crosstalk_readings_carry_the_range_scale_and_the_bias(mode):
    """A cross-talk reading is an echo time converted like any other: range_scale · (d/2 or path/2) + bias, before
    the clamp. Constant cross-talk with probability 1 always halves; geometric without jitter reads path/2."""
    from finkensim.sensors.sonar_model import sonar_scalars

    _, _, sp = setup(error="none", crosstalk=mode, crosstalk_probability=1.0, crosstalk_jitter=0.0)
    d, path = 2.4, 1.6
    for scale, bias in ((1.0, 0.0), (1.05, -0.08), (0.97, 0.12)):
        sc = sonar_scalars(sp._replace(range_scale=scale, bias=bias))
        got = _measured(d, True, path if mode == "geometric" else np.inf, 3, 1, sc)
        half = 0.5 * (d if mode == "constant" else path)
        assert got == min(sp.max_range, max(sp.min_range, half * scale + bias))
        if scale == 1.0 and bias == 0.0:
            assert got == half  # the configured model: exactly d/2 (path/2)
