"""Arena geometry and the Bernoulli hinge walls: amplitude law, plates, hinge dynamics.

The settling time of a plate pulled by a copter 0.3 m away is measured and printed
(run ``pytest -s tests/test_arena.py -k settling`` to see it); docs/user-guide/walls.md quotes it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.arena import (Arena, _amplitude_law, amplitude_law, contact_angle, hinge_substeps, target_angle,
                             target_angles, walls_step)
from finkensim.config import Config, load_config
from finkensim.behaviours.open_loop import RandomWalk, hover
from finkensim.world import World
from tests.naive import world as naive

AMP30 = math.radians(30.0)


# --------------------------------------------------------------------------- amplitude law

def test_amplitude_law_anchor_values():
    assert amplitude_law(0.0) == 0.0
    assert amplitude_law(0.5) == pytest.approx(1.0625, abs=1e-12)
    assert amplitude_law(1.0) == pytest.approx(1.1, abs=1e-12)
    x = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(amplitude_law(x), naive.amplitude_law(x), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose([_amplitude_law(v) for v in x], amplitude_law(x), rtol=0, atol=0)


def test_amplitude_law_shape():
    rising = np.linspace(0.0, 0.58, 2001)
    assert np.all(np.diff(amplitude_law(rising)) > 0.0)  # increasing up to its local maximum at x ~ 0.584
    near = amplitude_law(np.linspace(0.5, 1.0, 2001))
    assert near.min() >= 1.04 and near.max() <= 1.10 + 1e-12  # "nearly full amplitude closer than 0.5 m"
    assert np.all(amplitude_law(np.linspace(1e-6, 1.0, 2001)) > 0.0)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.05, 10.0), st.floats(0.0, 100.0), st.floats(0.0, 1.4))
def test_target_zero_at_and_beyond_threshold(threshold, beyond, amplitude):
    d = threshold + beyond
    assert target_angle(d, threshold, amplitude) == 0.0
    assert target_angles(d, threshold, amplitude) == 0.0
    assert target_angle(threshold, threshold, amplitude) == 0.0


@settings(max_examples=200, deadline=None)
@given(st.floats(0.05, 10.0), st.floats(0.0, 1.0, exclude_max=True), st.floats(0.01, 1.4))
def test_target_inside_threshold(threshold, frac, amplitude):
    d = frac * threshold
    t = target_angle(d, threshold, amplitude)
    assert t == pytest.approx(float(target_angles(d, threshold, amplitude)), rel=1e-12, abs=1e-15)
    assert 0.0 <= t <= 1.1 * amplitude + 1e-12
    assert t == pytest.approx(amplitude * naive.amplitude_law((threshold - d) / threshold), rel=1e-9, abs=1e-12)


# --------------------------------------------------------------------------- plate geometry

@pytest.mark.parametrize("width, length, n, frac", [(3.0, 4.0, 16, 0.9), (3.0, 4.0, 1, 1.0), (7.5, 2.0, 5, 0.3)])
def test_plate_geometry(width, length, n, frac):
    cfg = Config().replace({"arena.width": width, "arena.length": length, "walls.n_segments": n,
                            "walls.plate_width_fraction": frac})
    a = Arena.from_config(cfg.arena, cfg.walls)
    S = 4 * n
    assert a.n_plates == S
    for arr in (a.seg_a, a.seg_b, a.plate_a, a.plate_b, a.normal):
        assert arr.shape == (S, 2)
    np.testing.assert_array_equal(np.bincount(a.wall_index), [n, n, n, n])
    # every segment and plate lies on the arena rectangle's boundary
    for pts in (a.seg_a, a.seg_b, a.plate_a, a.plate_b):
        assert np.all((pts >= -1e-12) & (pts <= np.array([width, length]) + 1e-12))
        on_edge = np.isclose(pts[:, 0], 0) | np.isclose(pts[:, 0], width) | np.isclose(pts[:, 1], 0) \
            | np.isclose(pts[:, 1], length)
        assert np.all(on_edge)
    # the segments of one wall tile it exactly: pitch = wall length / n, consecutive
    seg_len = np.linalg.norm(a.seg_b - a.seg_a, axis=1)
    wall_len = np.where(a.wall_index % 2 == 0, width, length)
    np.testing.assert_allclose(seg_len, wall_len / n, rtol=1e-12)
    np.testing.assert_allclose(np.roll(a.seg_a, -1, axis=0), a.seg_b, atol=1e-12)  # a closed loop
    # plates: their own width, centred in the pitch
    plate_len = np.linalg.norm(a.plate_b - a.plate_a, axis=1)
    np.testing.assert_allclose(plate_len, frac * seg_len, rtol=1e-12)
    np.testing.assert_allclose(0.5 * (a.plate_a + a.plate_b), 0.5 * (a.seg_a + a.seg_b), atol=1e-12)
    # unit inward normals, perpendicular to the wall
    np.testing.assert_allclose(np.linalg.norm(a.normal, axis=1), 1.0)
    mid = 0.5 * (a.seg_a + a.seg_b)
    centre = np.array([width / 2, length / 2])
    assert np.all(np.sum((centre - mid) * a.normal, axis=1) > 0.0)
    np.testing.assert_allclose(np.sum((a.seg_b - a.seg_a) * a.normal, axis=1), 0.0, atol=1e-12)
    # the naive reference builds the same rest lines
    na, nb = naive.wall_segments(cfg)
    np.testing.assert_allclose(a.seg_a, na, atol=1e-12)
    np.testing.assert_allclose(a.seg_b, nb, atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1.5, 1.5), min_size=8, max_size=8), st.floats(0.65, 3.0))
def test_plate_surfaces_displaced_by_lever_sin_theta(thetas, hinge_height):
    cfg = Config().replace({"walls.n_segments": 2, "walls.hinge_height": hinge_height,
                            "walls.plate_length": min(1.0, hinge_height)})
    a = Arena.from_config(cfg.arena, cfg.walls)
    lever = hinge_height - cfg.arena.altitude
    assert a.lever == pytest.approx(lever)
    theta = np.array([thetas])  # (B = 1, S = 8)
    sa, sb = a.plate_surfaces(theta)
    assert sa.shape == sb.shape == (1, 8, 2)
    shift_a, shift_b = sa[0] - a.plate_a, sb[0] - a.plate_b
    expected = (lever * np.sin(theta[0]))[:, None] * a.normal
    np.testing.assert_allclose(shift_a, expected, atol=1e-12)
    np.testing.assert_allclose(shift_b, expected, atol=1e-12)
    np.testing.assert_allclose(a.displacement(theta), lever * np.sin(theta), atol=1e-15)


def test_default_displacement_magnitude():
    """docs/user-guide/walls.md: lever 0.4 m moves the surface up to 0.21 m at the 31.9 deg target."""
    a = Arena.from_config(Config().arena, Config().walls)
    assert a.lever == pytest.approx(0.4)
    assert a.displacement(np.deg2rad(31.857)) == pytest.approx(0.211, abs=1e-3)


# --------------------------------------------------------------------------- hinge dynamics

def _run_plate(cfg, dist, seconds, theta0=0.0):
    """One plate driven by a fixed nearest-body distance; returns (t, theta) sampled every world step."""
    a = Arena.from_config(cfg.arena, cfg.walls)
    dt = cfg.simulation.dt
    th, om, ig = np.full((1, 1), theta0), np.zeros((1, 1)), np.zeros((1, 1))
    d = np.full((1, 1), float(dist))
    out = [theta0]
    for _ in range(int(round(seconds / dt))):
        walls_step(th, om, ig, d, a.hinge, a.lever, dt)
        out.append(th[0, 0])
    return np.arange(len(out)) * dt, np.array(out)


def settling_time(t, x, target, band=0.02):
    """First time after which x stays within band * |target| of target (inf if it never does)."""
    outside = np.nonzero(np.abs(x - target) > band * abs(target))[0]
    if outside.size == 0:
        return float(t[0])
    if outside[-1] == len(x) - 1:
        return math.inf
    return float(t[outside[-1] + 1])


SETTLING_S = 2.00  # the hinge is deterministic: 2.00 s at dt = 0.05 s (last sample outside the 2 % band at 1.95 s)


def test_plate_settling_time_with_copter_at_0_3_m():
    """A hovering copter whose body is 0.3 m from a south plate pulls it to 31.9 deg; measure the 2 % settling."""
    cfg = Config().replace({"copters.n": 1, "behaviour.kind": "hover"})
    world = World(cfg)
    r = cfg.copters.radius
    x = 1.5 + 0.5 * 3.0 / 16  # above the middle of south plate 8
    state = world.init(n_envs=1, positions=[[[x, 0.3 + r]]])
    final, traj = world.rollout(state, n_steps=int(round(10.0 / world.dt)), controller=hover)
    plate = 8
    theta = np.append(traj.theta[:, 0, plate], final.theta[0, plate])
    t = np.arange(theta.size) * world.dt
    target = target_angle(0.3, cfg.walls.threshold, math.radians(cfg.walls.max_amplitude_deg))
    assert math.degrees(target) == pytest.approx(31.857, abs=1e-3)
    ts = settling_time(t, theta, target)
    print(f"\nplate settling time (2 %, copter body 0.3 m away, default walls): {ts:.2f} s; "
          f"peak {math.degrees(theta.max()):.2f} deg for target {math.degrees(target):.2f} deg")
    assert ts == pytest.approx(SETTLING_S, abs=0.5 * world.dt)  # docs/user-guide/walls.md: "settles ... after 2.0 s"
    assert abs(theta[-1] - target) < 0.02 * target
    # the world step gives exactly what the hinge kernel alone gives for d = 0.3 m
    _, alone = _run_plate(cfg, 0.3 + 0.0, 10.0)
    np.testing.assert_allclose(theta, alone, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("friction", [3.0, 0.1])  # default (overdamped) and a lightly damped hinge
def test_plate_swings_back_without_copter(friction):
    cfg = Config().replace({"walls.friction": friction})
    t, th = _run_plate(cfg, dist=5.0, seconds=20.0, theta0=0.5)
    mag = np.abs(th)
    # peaks of |theta| (local maxima, plus the start) decrease monotonically
    peaks = [0] + [k for k in range(1, len(mag) - 1) if mag[k] >= mag[k - 1] and mag[k] >= mag[k + 1]]
    assert np.all(np.diff(mag[peaks]) <= 1e-12)
    if friction == 3.0:  # overdamped: |theta| itself never grows
        assert np.all(np.diff(mag) <= 1e-15)
        assert mag[int(round(10.0 / cfg.simulation.dt))] < math.radians(0.3)  # walls.md: below 0.3 deg in 10 s
    assert mag[-1] < math.radians(0.05)
    assert np.all(mag <= 0.5 + 1e-12)


def test_seed_profile_saturates_near_motor_limit():
    """40 kg plate: 15 N m holds at most asin(15 / (40 * 9.81 * 0.5)) ~ 4.4 deg, never the 31.9 deg target."""
    cfg = load_config({"profile": "seed"})
    assert cfg.walls.plate_mass == 40.0
    limit = math.asin(15.0 / (40.0 * 9.81 * 0.5))
    assert math.degrees(limit) == pytest.approx(4.385, abs=1e-3)
    assert Arena.from_config(cfg.arena, cfg.walls).max_equilibrium_angle() == pytest.approx(limit)
    t, th = _run_plate(cfg, dist=0.3, seconds=90.0)
    assert th.max() < math.radians(5.0)  # never anywhere near 30 deg
    late = th[t >= 30.0]
    assert abs(late.mean() - limit) < math.radians(0.25)
    assert np.all(np.abs(late - limit) < math.radians(0.5))


def test_rigid_walls_never_move():
    cfg = Config().replace({"walls.bending": False, "copters.n": 4, "copters.min_separation": 0.3})
    world = World(cfg)
    r = cfg.copters.radius
    pos = np.array([[[r, 2.0], [3.0 - r, 1.0], [1.5, r], [1.0, 4.0 - r]]])  # touching all four walls
    state = world.init(n_envs=1, positions=pos)
    _, traj = world.rollout(state, n_steps=100, controller=RandomWalk(cfg))
    assert np.all(traj.theta == 0.0)
    # and the kernel forgets any deflection it is given
    a = Arena.from_config(cfg.arena, cfg.walls)
    assert hinge_substeps(0.7, 1.0, 0.3, 0.5, True, a.hinge, 0.05) == (0.0, 0.0, 0.0)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 3.0), min_size=6, max_size=6),
    st.lists(st.floats(-1.5, 1.5), min_size=6, max_size=6),
    st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6),
    st.lists(st.floats(-8.0, 8.0), min_size=6, max_size=6),
    st.floats(0.05, 50.0),  # plate mass
    st.integers(1, 12),  # substeps
    st.sampled_from([0.0, 0.5, 2.0]),  # pid_i (0: no anti-windup clip)
)
def test_walls_step_matches_naive(dist, theta, omega, integ, mass, substeps, pid_i):
    cfg = Config().replace({"walls.plate_mass": mass, "walls.substeps": substeps, "walls.pid_i": pid_i})
    a = Arena.from_config(cfg.arena, cfg.walls)
    shape = (2, 3)
    arrays = [np.array(v, dtype=float).reshape(shape) for v in (theta, omega, integ, dist)]
    th, om, ig, d = (x.copy() for x in arrays)
    walls_step(th, om, ig, d, a.hinge, a.lever, cfg.simulation.dt)
    p = naive.params(cfg)
    nth, nom, nig = naive.hinge_step(*arrays[:3], arrays[3], p)
    np.testing.assert_allclose(th, nth, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(om, nom, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ig, nig, rtol=1e-9, atol=1e-12)
    assert np.all(np.abs(th) <= 0.5 * np.pi)


@njit(cache=True)
def _walls_step_serial(theta, omega, integ, dist, hp, lever, dt):
    """The per-plate formulation walls_step_env replaced: hinge_substeps then the contact cap, plate by plate."""
    for b in range(theta.shape[0]):
        for s in range(theta.shape[1]):
            d = dist[b, s]
            active = d < hp.threshold
            tgt = target_angle(d, hp.threshold, hp.max_amplitude) if active else 0.0
            theta[b, s], omega[b, s], integ[b, s] = hinge_substeps(theta[b, s], omega[b, s], integ[b, s], tgt, active,
                                                                   hp, dt)
            cap = contact_angle(d, lever)
            if theta[b, s] > cap:
                theta[b, s] = cap
                omega[b, s] = min(omega[b, s], 0.0)


_ZEROS = st.sampled_from([0.0, -0.0])


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.one_of(st.floats(0.0, 3.0), st.sampled_from([0.0, 1.0, np.inf, np.nan, -0.2])), min_size=24,
             max_size=24),
    st.lists(st.one_of(st.floats(-1.6, 1.6), _ZEROS), min_size=24, max_size=24),
    st.lists(st.one_of(st.floats(-6.0, 6.0), _ZEROS), min_size=24, max_size=24),
    st.lists(st.one_of(st.floats(-8.0, 8.0), _ZEROS), min_size=24, max_size=24),
    st.floats(0.05, 50.0),  # plate mass
    st.integers(1, 12),  # substeps
    st.sampled_from([0.0, 0.5, 2.0]),  # pid_i
    st.sampled_from([0.0, 3.0, 1e5]),  # friction
    st.booleans(),  # bending
)
def test_walls_step_bit_identical_to_per_plate_substeps(dist, theta, omega, integ, mass, substeps, pid_i, friction,
                                                        bending):
    """The interleaved kernel (substeps outside the plate loop, plates at rest skipped) equals the per-plate
    hinge_substeps + cap bit for bit, signed zeros included."""
    cfg = Config().replace({"walls.plate_mass": mass, "walls.substeps": substeps, "walls.pid_i": pid_i,
                            "walls.friction": friction, "walls.bending": bending})
    a = Arena.from_config(cfg.arena, cfg.walls)
    arrays = [np.array(v, dtype=float).reshape(4, 6) for v in (theta, omega, integ, dist)]
    fast = [x.copy() for x in arrays[:3]]
    ref = [x.copy() for x in arrays[:3]]
    walls_step(*fast, arrays[3], a.hinge, a.lever, cfg.simulation.dt)
    _walls_step_serial(*ref, arrays[3], a.hinge, a.lever, cfg.simulation.dt)
    for f, r in zip(fast, ref):
        np.testing.assert_array_equal(f.view(np.int64), r.view(np.int64))  # bits: -0.0 and NaN payloads too


def test_plates_at_rest_stay_at_rest_bit_for_bit():
    """The skip of plates at rest relies on theta = omega = +0 staying +0 with the motor off: check it over many steps."""
    cfg = Config()
    a = Arena.from_config(cfg.arena, cfg.walls)
    th, om, ig = np.zeros((1, 8)), np.zeros((1, 8)), np.full((1, 8), 0.3)
    dist = np.full((1, 8), 2.0 * a.hinge.threshold)
    ref = [th.copy(), om.copy(), ig.copy()]
    for _ in range(50):
        walls_step(th, om, ig, dist, a.hinge, a.lever, cfg.simulation.dt)
        _walls_step_serial(*ref, dist, a.hinge, a.lever, cfg.simulation.dt)
    for f, r in zip((th, om, ig), ref):
        np.testing.assert_array_equal(f.view(np.int64), r.view(np.int64))
    assert np.all(th.view(np.int64) == 0) and np.all(om.view(np.int64) == 0) and np.all(ig.view(np.int64) == 0)


def test_hinge_matches_an_independent_ode_solution():
    """The plate ODE, written here from DESIGN's hinge model and integrated by scipy's solve_ivp (RK45, tight
    tolerances): θ' = ω, ω' = (clip(P·e + I·z − D·ω, ±F) − g·sin θ) / J, z' = e = target − θ with z held at ±F/I
    (anti-windup). The engine's semi-implicit Euler substeps are first order, so their error is bounded from the
    engine itself: within 3× the change when the substeps are doubled (Richardson), and the final angle within
    1e-3 of the target (the integral term removes the steady-state error: the equilibrium is the target)."""
    from scipy.integrate import solve_ivp

    cfg = Config()
    hp = Arena.from_config(cfg.arena, cfg.walls).hinge
    target = target_angle(0.3, hp.threshold, hp.max_amplitude)
    lim = hp.joint_force / hp.i

    def rhs(_, s):
        th, om, z = s
        e = target - th
        tau = min(hp.joint_force, max(-hp.joint_force, hp.p * e + hp.i * z - hp.d * om))
        dz = 0.0 if (z >= lim and e > 0) or (z <= -lim and e < 0) else e
        return [om, (tau - hp.gravity_torque * math.sin(th)) / hp.inertia, dz]

    t, theta = _run_plate(cfg, 0.3, 10.0)
    _, theta_fine = _run_plate(cfg.replace({"walls.substeps": 2 * hp.substeps}), 0.3, 10.0)
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0, 0.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=1e-3)
    assert sol.success
    err = np.abs(theta - sol.y[0]).max()
    richardson = np.abs(theta - theta_fine).max()
    print(f"\nhinge vs solve_ivp: max |Δθ| {err:.2e} rad, substep-halving change {richardson:.2e} rad")
    assert err < 3 * richardson + 1e-9
    assert abs(sol.y[0, -1] - target) < 1e-3 and abs(theta[-1] - target) < 1e-3
