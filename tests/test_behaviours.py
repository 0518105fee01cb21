"""Swarm behaviours: attraction–repulsion and the wall plausibility checks, against the NumPy reference
and on hand-made cases (equilibrium, no echo, wall readings repel only, flag / release of the sequence check)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from finkensim.behaviours.attraction import AttractionParams, attraction_repulsion, body_to_world, \
    settle_distance, settle_reading
from finkensim.behaviours.wall_check import BehaviourState, WallCheckParams, dead_reckon, per_reading_check, \
    wall_check
from finkensim.config import Config, ConfigError
from finkensim.swarm import SwarmSim
from tests.naive import behaviours as naive

# ------------------------------------------------------------------------------ attraction–repulsion


def _ar_cfg(**kw):
    base = {"behaviour.kind": "attraction_repulsion"}
    base.update(kw)
    return Config().replace(base)


def test_settle_reading_is_the_zero_of_the_law():
    r = settle_reading(1.0, 4.0, 1.5)
    assert r == pytest.approx(math.sqrt(1.5 * math.log(4.0)))
    assert r == pytest.approx(1.442027, abs=1e-6)
    assert 1.0 - 4.0 * math.exp(-r * r / 1.5) == pytest.approx(0.0, abs=1e-12)
    assert settle_distance(Config()) == pytest.approx(r + 0.15)
    with pytest.raises(ConfigError):
        settle_reading(4.0, 1.0, 1.5)  # b < a: pure attraction, no equilibrium


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_attraction_matches_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    cfg = _ar_cfg(**{"behaviour.gain": float(rng.uniform(0.2, 3.0)), "behaviour.w_t": float(rng.uniform(0, 1)),
                     "behaviour.target_distance": float(rng.uniform(0, 2)), "behaviour.redraw_steps": 7,
                     "sonar.yaw_deg": [0.0, 80.0, 185.0, -95.0], "copters.max_speed": 0.7})
    ap = AttractionParams.from_config(cfg)
    B, N = 5, 6
    sonar = rng.uniform(0.2, 3.0, (B, N, 4))
    sonar[rng.random((B, N, 4)) < 0.3] = cfg.sonar.max_range  # no echo
    wall = rng.random((B, N, 4)) < 0.3
    env_ids = rng.integers(0, 1000, B)
    for step in (0, 6, 7, 1234):
        v, w = attraction_repulsion(sonar, 11, env_ids, step, ap, wall)
        v_ref, w_ref = naive.attraction(sonar, wall, 11, env_ids, step, cfg)
        np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(w, w_ref)
        assert np.all(np.linalg.norm(v, axis=-1) <= cfg.copters.max_speed * (1 + 1e-12))


def test_no_echo_contributes_nothing_and_equilibrium_reading_is_still():
    cfg = _ar_cfg(**{"behaviour.w_t": 0.0})
    ap = AttractionParams.from_config(cfg)
    r_star = settle_reading(cfg.behaviour.ar_a, cfg.behaviour.ar_b, cfg.behaviour.ar_c)
    sonar = np.full((1, 3, 4), cfg.sonar.max_range)
    sonar[0, 1, 0] = r_star  # copter 1 sees something ahead at exactly r*
    sonar[0, 2, 1] = 2.0  # copter 2 sees something on its left beyond r*: attracted to the left (+y)
    v, _ = attraction_repulsion(sonar, 0, [0], 0, ap)
    np.testing.assert_array_equal(v[0, 0], [0.0, 0.0])  # nothing within range: no motion
    np.testing.assert_allclose(v[0, 1], [0.0, 0.0], atol=1e-12)
    assert v[0, 2, 1] > 0.1 and abs(v[0, 2, 0]) < 1e-12


def test_wall_reading_repels_only():
    cfg = _ar_cfg(**{"behaviour.w_t": 0.0})
    ap = AttractionParams.from_config(cfg)
    sonar = np.full((1, 1, 4), cfg.sonar.max_range)
    sonar[0, 0, 0] = 2.0  # beyond r*: a swarm-mate attracts
    mate, _ = attraction_repulsion(sonar, 0, [0], 0, ap, wall=np.zeros((1, 1, 4), bool))
    wall = np.zeros((1, 1, 4), bool)
    wall[0, 0, 0] = True
    away, _ = attraction_repulsion(sonar, 0, [0], 0, ap, wall=wall)
    assert mate[0, 0, 0] > 0.0 and away[0, 0, 0] < 0.0
    b, c = cfg.behaviour.ar_b, cfg.behaviour.ar_c
    assert away[0, 0, 0] == pytest.approx(-cfg.behaviour.w_c * 2.0 * b * math.exp(-4.0 / c))


def test_target_is_redrawn_every_redraw_steps_and_batch_independent():
    cfg = _ar_cfg(**{"behaviour.w_c": 0.0, "behaviour.redraw_steps": 20, "copters.max_speed": 50.0})
    ap = AttractionParams.from_config(cfg)
    sonar = np.full((3, 2, 4), cfg.sonar.max_range)
    v0, _ = attraction_repulsion(sonar, 5, [0, 1, 2], 0, ap)
    v19, _ = attraction_repulsion(sonar, 5, [0, 1, 2], 19, ap)
    v20, _ = attraction_repulsion(sonar, 5, [0, 1, 2], 20, ap)
    np.testing.assert_array_equal(v0, v19)
    assert not np.allclose(v0, v20)
    expect = cfg.behaviour.gain * cfg.behaviour.w_t * cfg.behaviour.ar_a * cfg.behaviour.target_distance
    np.testing.assert_allclose(np.linalg.norm(v0, axis=-1), expect)
    lone, _ = attraction_repulsion(sonar[1:2], 5, [1], 0, ap)
    np.testing.assert_array_equal(lone[0], v0[1])


def test_body_to_world_rotates_by_the_heading():
    v = body_to_world(np.array([[0.0, np.pi / 2, -np.pi]]), np.array([[[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]]))
    np.testing.assert_allclose(v, [[[1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]], atol=1e-15)


# ------------------------------------------------------------------------------ per-reading check


def _wc_cfg(**kw):
    base = {"behaviour.wall_check": "per_reading"}
    base.update(kw)
    return Config().replace(base)


def test_per_reading_drops_a_wall_and_keeps_a_copter():
    cfg = _wc_cfg()
    wp = WallCheckParams.from_config(cfg)
    rim = cfg.copters.radius + cfg.sonar.offset
    # copter 0 sees copter 1 ahead (reading 1.35 m = 1.5 m centre distance − rim) and a wall behind at 0.5 m;
    # its ranging reads 1.5 m to copter 1. Side sonars: no echo.
    sonar = np.array([[[1.5 - rim, 3.0, 0.5, 3.0], [1.5 - rim, 3.0, 3.0, 3.0]]])
    ranging = np.array([[[0.0, 1.5], [1.5, 0.0]]])
    fail = per_reading_check(sonar, ranging, wp)
    np.testing.assert_array_equal(fail, [[[False, False, True, False], [False, False, False, False]]])
    # the match tolerance is epsilon around the centre-distance estimate
    eps = cfg.behaviour.wall_check_epsilon
    for delta, expect in ((0.99 * eps, False), (1.01 * eps, True), (-0.99 * eps, False), (-1.01 * eps, True)):
        s = np.array([[[1.5 - rim + delta, 3.0, 3.0, 3.0], [3.0] * 4]])
        assert per_reading_check(s, ranging, wp)[0, 0, 0] == expect, delta
    # a lone copter (no other tag): every echo is a wall; its own zero-distance column never matches
    lone = per_reading_check(np.array([[[0.05, 3.0, 0.8, 2.9]]]), np.zeros((1, 1, 1)), wp)
    np.testing.assert_array_equal(lone, [[[True, False, True, True]]])


def test_per_reading_out_of_range_ranging_matches_far_echoes():
    cfg = _wc_cfg()
    wp = WallCheckParams.from_config(cfg)
    far = cfg.ranging.max_range  # copter 1 is out of ranging range: at least 2.5 m away
    ranging = np.array([[[0.0, far], [far, 0.0]]])
    sonar = np.array([[[2.6 - 0.15, 1.0, 3.0, 3.0], [3.0] * 4]])
    fail = per_reading_check(sonar, ranging, wp)
    assert not fail[0, 0, 0]  # 2.6 m ahead is consistent with "beyond 2.5 m"
    assert fail[0, 0, 1]  # 1.15 m is not


@pytest.mark.parametrize("seed", [0, 1])
def test_per_reading_matches_numpy_reference(seed):
    rng = np.random.default_rng(seed)
    cfg = _wc_cfg(**{"sonar.offset": 0.05, "ranging.beacons": [[0.5, 0.5], [2.0, 3.0]]})
    wp = WallCheckParams.from_config(cfg)
    B, N, M = 6, 5, 2
    sonar = rng.uniform(0.2, 3.0, (B, N, 4))
    sonar[rng.random((B, N, 4)) < 0.2] = 3.0
    ranging = rng.uniform(0.0, 2.6, (B, N, N + M))
    ranging[rng.random((B, N, N + M)) < 0.2] = 2.5
    # put some readings right on the tolerance edges
    ranging[:, :, 0] = np.clip(sonar[:, :, 0] + 0.2 + rng.choice([-0.3, 0.3, 0.0], (B, N)), 0, None)
    np.testing.assert_array_equal(per_reading_check(sonar, ranging, wp), naive.per_reading(sonar, ranging, cfg))


# ------------------------------------------------------------------------------ dead reckoning and the sequence check


def test_dead_reckoning_matches_numpy_reference():
    rng = np.random.default_rng(3)
    cfg = _wc_cfg(**{"behaviour.wall_check": "sequence"})
    wp = WallCheckParams.from_config(cfg)
    B, N = 3, 4
    st = BehaviourState.zeros(B, N)
    pos, vel, yaw = np.zeros((B, N, 2)), np.zeros((B, N, 2)), np.zeros((B, N))
    for _ in range(30):
        acc, gyro = rng.normal(0, 1, (B, N, 2)), rng.normal(0, 0.5, (B, N))
        dead_reckon(acc, gyro, st, wp)
        pos, vel, yaw = naive.dead_reckon(acc, gyro, pos, vel, yaw, cfg.simulation.dt)
    np.testing.assert_allclose(st.dr_pos, pos, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(st.dr_vel, vel, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(st.dr_yaw, yaw, rtol=1e-12, atol=1e-12)


def test_sequence_matches_numpy_reference():
    rng = np.random.default_rng(4)
    cfg = _wc_cfg(**{"behaviour.wall_check": "sequence", "behaviour.sequence_fail_count": 3,
                     "behaviour.sequence_release_distance": 0.2, "behaviour.sequence_release_angle_deg": 20.0})
    wp = WallCheckParams.from_config(cfg)
    B, N = 4, 3
    st = BehaviourState.zeros(B, N)
    count, wall, anchor = np.zeros((B, N, 4), np.int64), np.zeros((B, N, 4), bool), np.zeros((B, N, 4, 3))
    onsets = np.zeros((B, N), np.int64)
    ranging = np.zeros((B, N, N))  # only own columns at 0 and others at 0: every echo above 0.286 fails
    for t in range(80):
        sonar = np.where(rng.random((B, N, 4)) < 0.8, 1.0, 0.05)  # 1.0 fails, 0.05 (+rim 0.2) matches 0
        st.dr_pos[:] += rng.normal(0, 0.03, (B, N, 2))
        st.dr_yaw[:] += rng.normal(0, 0.05, (B, N))
        wall_check(sonar, ranging, wp, st)
        fail = naive.per_reading(sonar, ranging, cfg)
        count, wall, anchor, new = naive.sequence(fail, count, wall, anchor, st.dr_pos, st.dr_yaw, cfg)
        onsets += new
        np.testing.assert_array_equal(st.wall, wall, err_msg=f"step {t}")
        np.testing.assert_array_equal(st.fail_count, count)
        np.testing.assert_array_equal(st.anchor, anchor)
    np.testing.assert_array_equal(st.wall_onsets, onsets)
    assert onsets.sum() > 10  # flags were set and released many times


def _one_sonar_run(cfg, fails, moves=None, turns=None):
    """Feed the sequence check one copter whose front sonar fails at steps where ``fails`` is True;
    dead-reckoned position / heading follow ``moves`` / ``turns`` (per step). Returns wall flags per step."""
    wp = WallCheckParams.from_config(cfg)
    st = BehaviourState.zeros(1, 1)
    ranging = np.zeros((1, 1, 1))
    out = []
    for t, f in enumerate(fails):
        if moves is not None:
            st.dr_pos[0, 0] = moves[t]
        if turns is not None:
            st.dr_yaw[0, 0] = turns[t]
        sonar = np.array([[[1.0 if f else 3.0, 3.0, 3.0, 3.0]]])  # fail = an echo nothing matches
        out.append(bool(wall_check(sonar, ranging, wp, st)[0, 0, 0]))
    return np.array(out), st


def test_sequence_flags_after_fail_count_consecutive_failures():
    cfg = _wc_cfg(**{"behaviour.wall_check": "sequence", "behaviour.sequence_fail_count": 4})
    # 3 failures, a pass (resets), then 4 failures: flagged at the 4th of them and held (no motion)
    fails = [True] * 3 + [False] + [True] * 4 + [False] * 5
    flags, st = _one_sonar_run(cfg, fails)
    np.testing.assert_array_equal(flags, [False] * 7 + [True] * 6)
    assert st.wall_onsets[0, 0] == 1


@pytest.mark.parametrize("how", ["move", "turn"])
def test_sequence_releases_after_moving_or_turning(how):
    cfg = _wc_cfg(**{"behaviour.wall_check": "sequence", "behaviour.sequence_fail_count": 2,
                     "behaviour.sequence_release_distance": 0.3, "behaviour.sequence_release_angle_deg": 30.0})
    T = 20
    fails = [True] * 2 + [False] * (T - 2)
    ramp = np.maximum(0, np.arange(T) - 1) * 0.05  # starts moving after the flag (set at step 1)
    if how == "move":
        flags, _ = _one_sonar_run(cfg, fails, moves=np.stack([ramp, 0 * ramp], -1))
        first_free = int(np.argmax(ramp >= 0.3 - 1e-12))
    else:
        ang = ramp * 2.0  # rad: 0.1 rad per step
        flags, _ = _one_sonar_run(cfg, fails, turns=ang)
        first_free = int(np.argmax(ang >= math.radians(30.0)))
    assert flags[1] and flags[first_free - 1] and not flags[first_free]
    assert not flags[first_free:].any()


# ------------------------------------------------------------------------------ through the closed loop


def _facing_wall_sim(**kw):
    """One copter 1 m in front of the west net, facing it, ideal sensors, sequence check."""
    upd = {"arena.width": 30.0, "arena.length": 30.0, "copters.n": 1, "sonar.error": "none",
           "sonar.crosstalk": "off", "ranging.error": "none", "behaviour.wall_check": "sequence",
           "imu.acc_noise_density": 0.0, "imu.acc_bias_walk": 0.0, "imu.gyro_noise_density": 0.0,
           "imu.gyro_bias_walk": 0.0}
    upd.update(kw)
    return Config().replace(upd)


@pytest.mark.parametrize("how", ["move", "turn"])
def test_sequence_check_in_the_loop_flags_then_releases(how):
    cfg = _facing_wall_sim(**{"behaviour.sequence_fail_count": 5})
    T_hover = 10

    def backs_off(readings, memory, params):
        B, N = readings.wall.shape[:2]
        v = np.zeros((B, N, 2))
        w = np.zeros((B, N))
        if readings.step >= T_hover:
            if how == "move":
                v[..., 0] = -0.5  # body frame: backwards, away from the wall ahead
            else:
                w[:] = 1.0  # rad/s
        return v, w

    sim = SwarmSim(cfg, behaviour=backs_off)
    st = sim.init(n_envs=1, seed=0, positions=[[[1.0, 15.0]]], yaw=[[-np.pi]])  # facing -x
    final, rec = sim.rollout(st, 60, record=("wall", "pose", "imu_acc"))
    front = rec.wall[:, 0, 0, 0]
    first = int(np.argmax(front))
    assert first == 4 and front[4:T_hover].all()  # 5th failing reading (step index 4)
    released = first + int(np.argmax(~front[first:]))
    assert released > T_hover and not front[released:].all()
    x0, yaw0 = rec.pose[first, 0, 0, 0], rec.pose[first, 0, 0, 2]
    if how == "move":
        moved = np.abs(rec.pose[:, 0, 0, 0] - x0)
        # released at the first step whose dead-reckoned motion reaches 0.3 m (ideal IMU: = true motion)
        assert moved[released] >= 0.3 - 1e-9 and moved[released - 1] < 0.3
    else:
        turned = np.abs(np.unwrap(rec.pose[:, 0, 0, 2]) - yaw0)
        assert turned[released - 1] < math.radians(30.0) <= turned[released] + 1e-9
    assert rec.counters["wall_onsets"][0, 0] >= 1
