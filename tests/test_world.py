"""The batched world: physical invariants, batch independence, purity, the NumPy reference, contacts, errors."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from finkensim.behaviours.open_loop import RandomWalk, hover
from finkensim.behaviours.random_walk import random_walk_env
from finkensim.determinism import check_determinism, first_difference
from finkensim.config import Config, ConfigError
from finkensim.copters import wrap_angle
from finkensim.testing import strategies as fst
from finkensim.world import World, WorldState
from tests.naive import world as naive

TOL = 1e-9


def _arrays(state):
    return {name: v for name, v in state._asdict().items() if isinstance(v, np.ndarray)}


def _assert_states_equal(a, b):
    for name, v in _arrays(a).items():
        np.testing.assert_array_equal(v, getattr(b, name), err_msg=name)
    assert (a.step, a.seed) == (b.step, b.seed)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# --------------------------------------------------------------------------- invariants under any commands

def _room(width, length, radius) -> int:
    """Most copters of ``radius`` the arena holds (config.PACKING_DENSITY: more is a ConfigError)."""
    from finkensim.config import PACKING_DENSITY

    return max(1, int(PACKING_DENSITY * width * length / (math.pi * radius ** 2)))


# the configs of the invariant tests: any arena and copter size, up to 4 copters, dynamics from gentle to extreme
INVARIANT_BOUNDS = {"arena.width": (0.5, 6.0), "arena.length": (0.5, 6.0), "copters.radius": (0.01, 2.0),
                    "copters.n": (1, 4), "walls.n_segments": (1, 4), "copters.max_speed": (0.1, 50.0),
                    "copters.max_accel": (0.1, 1000.0), "copters.velocity_tau": (0.0, 2.0), "simulation.dt": (0.001, 1.0)}


@st.composite
def command_scenarios(draw):
    """(config, commands (T, B, N, 2) m/s, yaw-rate commands (T, B, N) rad/s, seed): huge, reversing commands."""
    cfg = draw(fst.configs(sections=(), bounds=INVARIANT_BOUNDS, fixed={"copters.min_separation": 0.0}))
    n = cfg.copters.n
    T = draw(st.integers(1, 25))
    B = 2
    scale = draw(st.sampled_from([1.0, 1e3, 1e8]))
    cmds = draw(hnp.arrays(np.float64, (T, B, n, 2), elements=st.floats(-1.0, 1.0)))
    if draw(st.booleans()):  # alternating: full reversal every step
        cmds = cmds * np.where(np.arange(T) % 2 == 0, 1.0, -1.0)[:, None, None, None]
    yaw_cmds = draw(hnp.arrays(np.float64, (T, B, n), elements=st.floats(-1e6, 1e6)))
    return cfg, cmds * scale, yaw_cmds, draw(st.integers(0, 2**31))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(command_scenarios())
def test_copters_stay_inside_and_within_limits(scenario):
    cfg, cmds, yaw_cmds, seed = scenario
    world = World(cfg)
    c, r = cfg.copters, cfg.copters.radius
    lo, hi = np.array([r, r]), np.array([cfg.arena.width - r, cfg.arena.length - r])
    state = world.init(n_envs=cmds.shape[1], seed=seed)
    for k in range(cmds.shape[0]):
        new = world.step(state, cmds[k], yaw_cmds[k])
        assert np.all(new.pos >= lo) and np.all(new.pos <= hi), "copter centre left [r, W-r] x [r, L-r]"
        assert np.all(np.linalg.norm(new.vel, axis=-1) <= c.max_speed + TOL)
        # the motor's acceleration is limited; the stop at a wall (also in acc) is not
        gap = np.minimum(np.minimum(new.pos[..., 0], cfg.arena.width - new.pos[..., 0]),
                         np.minimum(new.pos[..., 1], cfg.arena.length - new.pos[..., 1])) - c.radius
        free = gap > 1e-12
        assert np.all(np.linalg.norm(new.acc, axis=-1)[free] <= c.max_accel + TOL)
        # the velocity change equals the applied acceleration except where a wall took a component away
        dv = np.linalg.norm(new.vel - state.vel, axis=-1) / world.dt
        assert np.all(dv[~new.in_wall] <= c.max_accel * (1 + TOL) + TOL)
        assert np.all(np.abs(new.yaw_rate) <= math.radians(c.max_yaw_rate_deg) + TOL)
        assert np.all((new.yaw >= -np.pi) & (new.yaw <= np.pi))  # [-pi, pi) up to the wrap_angle bug below
        assert np.all(np.abs(new.theta) <= 0.5 * np.pi)
        for v in _arrays(new).values():
            assert np.all(np.isfinite(v)) if v.dtype.kind == "f" else True
        state = new


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31), st.floats(0.5, 6.0), st.floats(0.5, 6.0))
def test_random_walk_rollout_stays_inside(seed, width, length):
    n = min(6, _room(width, length, 0.15))  # at most what fits (crowding is a ConfigError)
    cfg = Config().replace({"arena.width": width, "arena.length": length, "copters.min_separation": 0.2, "copters.n": n})
    world = World(cfg)
    final, traj = world.rollout(world.init(n_envs=2, seed=seed), n_steps=200, controller=RandomWalk(world.cfg))
    r = cfg.copters.radius
    xy = traj.pose[..., :2]
    assert np.all(xy[..., 0] >= r) and np.all(xy[..., 0] <= width - r)
    assert np.all(xy[..., 1] >= r) and np.all(xy[..., 1] <= length - r)
    assert np.all(np.linalg.norm(traj.vel, axis=-1) <= cfg.copters.max_speed + TOL)
    p = traj.pose[..., :2]
    gap = np.minimum(np.minimum(p[..., 0], cfg.arena.width - p[..., 0]),
                     np.minimum(p[..., 1], cfg.arena.length - p[..., 1])) - cfg.copters.radius
    free = gap > 1e-12  # acc[k] is the last step's: the stop at a wall shows where the copter now touches it
    assert np.all(np.linalg.norm(traj.acc, axis=-1)[free] <= cfg.copters.max_accel + TOL)


@settings(max_examples=200, deadline=None)
@given(st.floats(-100.0, 100.0))
def test_wrap_angle_range(a):
    w = wrap_angle(a)
    assert -np.pi <= w <= np.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-9) and math.isclose(math.sin(w), math.sin(a), abs_tol=1e-9)


def _wrap_angle_reference(a):
    """The plain form of wrap_angle: Python's float remainder, then the round-up fix."""
    w = (a + math.pi) % (2.0 * math.pi) - math.pi
    return w - 2.0 * math.pi if w >= math.pi else w


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.floats(-8.0, 8.0), st.floats(allow_nan=True, allow_infinity=True),
                 st.sampled_from([-math.pi, math.pi, np.nextafter(-math.pi, 0.0), np.nextafter(math.pi, 0.0),
                                  np.nextafter(-math.pi, -np.inf), np.nextafter(math.pi, np.inf), 0.0, -0.0])))
def test_wrap_angle_equals_the_plain_remainder(a):
    """The in-range shortcut of wrap_angle (no fmod call) gives the plain form's result bit for bit."""
    got, want = wrap_angle(a), _wrap_angle_reference(a)
    assert np.array([got]).view(np.int64)[0] == np.array([want]).view(np.int64)[0] or (math.isnan(got) and math.isnan(want))


def test_wrap_angle_half_open():
    assert wrap_angle(np.nextafter(-np.pi, -np.inf)) < np.pi


# --------------------------------------------------------------------------- batch independence, purity

def test_batch_step_equals_separate_runs():
    world = World(Config().replace({"copters.n": 5}))
    B, T = 4, 40
    rng = np.random.default_rng(7)
    cmds = rng.normal(scale=2.0, size=(T, B, 5, 2))
    yaw_cmds = rng.normal(scale=3.0, size=(T, B, 5))
    batch = world.init(n_envs=B, seed=11)
    for t in range(T):
        batch = world.step(batch, cmds[t], yaw_cmds[t])
    for k in range(B):
        lone = world.init(env_ids=[k], seed=11)
        for t in range(T):
            lone = world.step(lone, cmds[t, k:k + 1], yaw_cmds[t, k:k + 1])
        _assert_states_equal(lone, batch.select([k]))


def test_batch_rollout_equals_separate_runs():
    world = World()
    B, T = 4, 120
    final, traj = world.rollout(world.init(n_envs=B, seed=3), T, controller=RandomWalk(world.cfg))
    for k in range(B):
        lone_final, lone_traj = world.rollout(world.init(env_ids=[k], seed=3), T, controller=RandomWalk(world.cfg))
        _assert_states_equal(lone_final, final.select([k]))
        for name in ("pose", "vel", "acc", "yaw_rate", "theta"):
            np.testing.assert_array_equal(getattr(lone_traj, name)[:, 0], getattr(traj, name)[:, k], err_msg=name)
        np.testing.assert_array_equal(lone_traj.t, traj.t)


@pytest.mark.parametrize("cfg", [
    Config(),
    Config("seed"),
    Config().replace({"copters.n": 12, "walls.n_segments": 5, "copters.min_separation": 0.3}),
])
def test_check_determinism_passes(cfg):
    check_determinism(cfg, n_envs=3, n_steps=50, seed=5)


def test_check_determinism_with_callable_controller():
    world = World()
    check_determinism(world, n_envs=2, n_steps=10, controller=_random_walk_controller)


def test_check_determinism_catches_a_batch_dependent_controller():
    """A controller whose noise depends on the batch position (not env_ids) must be caught, and named."""
    def leaky(world, state):
        rng = np.random.default_rng(state.step)  # same stream for every batch size: env k != lone run
        return rng.normal(size=state.pos.shape), None

    with pytest.raises(AssertionError, match=r"lone env \d+ vs batch: (final|traj)\.\w+\["):
        check_determinism(World(), n_envs=3, n_steps=5, controller=leaky)


def test_check_determinism_catches_an_unseeded_controller():
    def unseeded(world, state):
        return np.random.default_rng().normal(size=state.pos.shape), None

    with pytest.raises(AssertionError, match=r"repeat: (final|traj)\.(pos|vel|acc|pose)"):
        check_determinism(World(), n_envs=2, n_steps=3, controller=unseeded)


def test_first_difference():
    a = np.zeros((2, 3))
    b = a.copy()
    b[1, 2] = 1.0
    assert first_difference(a, a) is None
    assert first_difference(a, b) == (1, 2)
    assert first_difference(np.array([np.nan]), np.array([np.nan])) is None
    assert first_difference(a, a[:1])[0] == "shape"


def test_step_is_pure():
    world = World()
    state = world.init(n_envs=3, seed=2)
    state = world.step(state, np.full((3, 6, 2), 0.7), np.ones((3, 6)))  # non-trivial state
    before = state.copy()
    new = world.step(state, np.full((3, 6, 2), -5.0), np.full((3, 6), 4.0))
    _assert_states_equal(state, before)
    assert new.step == state.step + 1
    for name, v in _arrays(new).items():
        assert not np.shares_memory(v, getattr(state, name)), name
    # same input, same output
    _assert_states_equal(world.step(state, np.full((3, 6, 2), -5.0), np.full((3, 6), 4.0)), new)


def test_rollout_is_pure_and_records_before_each_step():
    world = World()
    state = world.init(n_envs=2, seed=4)
    before = state.copy()
    final, traj = world.rollout(state, 30, controller=RandomWalk(world.cfg))
    _assert_states_equal(state, before)
    assert final.step == 30
    np.testing.assert_array_equal(traj.pose[0], state.pose)
    np.testing.assert_allclose(traj.t, np.arange(30) * world.dt)
    # continuing from the final state is the same as one longer rollout
    f2, _ = world.rollout(final, 20, controller=RandomWalk(world.cfg))
    f_all, _ = world.rollout(state, 50, controller=RandomWalk(world.cfg))
    _assert_states_equal(f2, f_all)
    none_final, none_traj = world.rollout(state, 30, controller=RandomWalk(world.cfg), record=False)
    assert none_traj is None
    _assert_states_equal(none_final, final)


# --------------------------------------------------------------------------- reference implementation

@st.composite
def small_cases(draw):
    """(config, state fields, commands): any state :func:`finkensim.testing.strategies.world_states` draws (plates
    swinging, copters moving), contact flags set at random, a few steps of commands beyond the limits."""
    cfg = draw(fst.configs(sections=(), bounds={
        "arena.width": (1.0, 5.0), "arena.length": (1.0, 5.0), "copters.radius": (0.02, 0.3), "copters.n": (1, 4),
        "walls.n_segments": (1, 3), "walls.substeps": (1, 6), "walls.plate_mass": (0.05, 40.0),
        "walls.threshold": (0.2, 2.0), "copters.yaw_tau": (0.0, 0.2), "copters.velocity_tau": (0.0, 0.3),
        "copters.max_accel": (0.5, 20.0)}, fixed={"copters.min_separation": 0.0, "walls.bending": draw(st.booleans())}))
    state = draw(fst.world_states(cfg, n_envs=(1, 2)))
    B, n = state.n_envs, state.n_copters
    u = lambda shape, lo, hi: draw(hnp.arrays(np.float64, shape, elements=st.floats(lo, hi)))  # noqa: E731
    fields_ = dict(pos=state.pos, vel=state.vel, yaw=state.yaw, yaw_rate=state.yaw_rate, theta=state.theta,
                   omega=state.omega, integ=state.integ, in_wall=draw(hnp.arrays(bool, (B, n))),
                   in_collision=draw(hnp.arrays(bool, (B, n))))
    cmds = [(u((B, n, 2), -3.0, 3.0), u((B, n), -5.0, 5.0)) for _ in range(draw(st.integers(1, 4)))]
    return cfg, fields_, cmds


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(small_cases())
def test_step_matches_naive_reference(case):
    cfg, fields_, cmds = case
    world = World(cfg)
    B = fields_["pos"].shape[0]
    state = world.init(n_envs=B, positions=fields_["pos"])._replace(**fields_)
    ref = state.copy()
    for cmd_v, cmd_w in cmds:
        state = world.step(state, cmd_v, cmd_w)
        ref = naive.world_step(cfg, ref, cmd_v, cmd_w)
        for name in ("pos", "vel", "acc", "yaw_rate", "theta", "omega", "integ"):
            np.testing.assert_allclose(getattr(state, name), getattr(ref, name), rtol=1e-9, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(_wrap(state.yaw - ref.yaw), 0.0, atol=1e-9, err_msg="yaw")
        for name in ("in_wall", "in_collision", "wall_contacts", "collisions"):
            np.testing.assert_array_equal(getattr(state, name), getattr(ref, name), err_msg=name)
        assert state.step == ref.step


# --------------------------------------------------------------------------- contacts

def _one_env(world, positions):
    return world.init(n_envs=1, positions=np.array([positions], dtype=float))


def test_wall_contact_counts_onsets():
    world = World(Config().replace({"copters.n": 1}))
    state = _one_env(world, [[1.5, 2.0]])
    into_east = np.array([[[1.0, 0.0]]])
    counts, touching = [], []
    for _ in range(100):  # 1.5 m at <= 1 m/s: reaches the wall after ~1.5 s and keeps pushing
        state = world.step(state, into_east)
        counts.append(int(state.wall_contacts[0, 0]))
        touching.append(bool(state.in_wall[0, 0]))
    assert state.pos[0, 0, 0] == 3.0 - world.cfg.copters.radius
    assert touching[-1] and sum(touching) > 40  # it stays at the wall ...
    assert counts[-1] == 1  # ... and that is one contact
    assert counts == sorted(counts)
    for _ in range(20):  # away from the wall
        state = world.step(state, -into_east)
    assert not state.in_wall[0, 0] and state.wall_contacts[0, 0] == 1
    for _ in range(40):  # and back into it: a second contact
        state = world.step(state, into_east)
    assert state.wall_contacts[0, 0] == 2
    # into a corner: still one ongoing contact
    for _ in range(80):
        state = world.step(state, np.array([[[1.0, 1.0]]]))
    assert state.wall_contacts[0, 0] == 2 and state.in_wall[0, 0]


def test_collision_counts_onsets_per_copter():
    world = World(Config().replace({"copters.n": 3, "copters.min_separation": 0.0}))
    state = _one_env(world, [[1.0, 2.0], [2.0, 2.0], [1.5, 3.5]])  # third copter stays away
    toward = np.array([[[0.2, 0.0], [-0.2, 0.0], [0.0, 0.0]]])
    stop = np.zeros_like(toward)
    steps = 0
    while not state.in_collision[0, 0]:  # close the 1 m gap until the bodies touch (2 r = 0.3 m) ...
        state = world.step(state, toward)
        steps += 1
        assert steps < 200
    assert state.in_collision[0, :2].all() and not state.in_collision[0, 2]
    for _ in range(40):  # ... then stop: they stay overlapping (the model does not resolve overlaps)
        state = world.step(state, stop)
        assert state.in_collision[0, :2].all()
    np.testing.assert_array_equal(state.collisions[0], [1, 1, 0])
    for _ in range(60):  # separate
        state = world.step(state, -toward)
    assert not state.in_collision[0].any()
    np.testing.assert_array_equal(state.collisions[0], [1, 1, 0])
    for _ in range(80):  # meet again (and pass through each other): a second collision each
        state = world.step(state, toward)
    np.testing.assert_array_equal(state.collisions[0], [2, 2, 0])
    assert state.wall_contacts.sum() == 0


# --------------------------------------------------------------------------- controllers

def _random_walk_controller(world, state):
    """The compiled random walk, called from Python once per step (for the callable path)."""
    B, N = state.n_envs, state.n_copters
    cmd_v, cmd_w = np.zeros((B, N, 2)), np.zeros((B, N))
    for b in range(B):
        random_walk_env(state.pos[b], state.seed, state.env_ids[b], state.step, RandomWalk(world.cfg).params,
                        cmd_v[b], cmd_w[b])
    return cmd_v, cmd_w


def test_random_walk_controller_equals_the_per_environment_kernel():
    world = World()
    state = world.init(n_envs=3, seed=9)
    compiled_final, compiled_traj = world.rollout(state, 80, controller=RandomWalk(world.cfg))
    py_final, py_traj = world.rollout(state, 80, controller=_random_walk_controller)
    _assert_states_equal(py_final, compiled_final)
    for name in ("t", "pose", "vel", "acc", "yaw_rate", "theta"):
        np.testing.assert_array_equal(getattr(py_traj, name), getattr(compiled_traj, name), err_msg=name)


def test_hover_controller_keeps_copters_still():
    world = World()
    state = world.init(n_envs=2, seed=1)
    final, _ = world.rollout(state, 40, controller=hover)
    np.testing.assert_array_equal(final.pos, state.pos)


# --------------------------------------------------------------------------- init

@pytest.mark.parametrize("seed", [0, 1, 12345])
@pytest.mark.parametrize("n, min_sep", [(6, 0.5), (12, 0.6), (2, 2.0)])
def test_init_respects_min_separation(seed, n, min_sep):
    cfg = Config().replace({"copters.n": n, "copters.min_separation": min_sep})
    world = World(cfg)
    state = world.init(n_envs=8, seed=seed)
    r = cfg.copters.radius
    assert np.all(state.pos >= r) and np.all(state.pos <= np.array([3.0 - r, 4.0 - r]))
    d = np.linalg.norm(state.pos[:, :, None] - state.pos[:, None], axis=-1)
    d[:, np.arange(n), np.arange(n)] = np.inf
    assert d.min() >= min_sep
    assert np.all((state.yaw >= -np.pi) & (state.yaw < np.pi))
    assert not state.vel.any() and not state.theta.any()


def test_init_env_ids_and_seed():
    world = World()
    a = world.init(n_envs=4, seed=1)
    b = world.init(n_envs=4, seed=2)
    assert not np.array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(world.init(env_ids=[2, 3], seed=1).pos, a.pos[2:])
    assert not np.array_equal(a.pos[0], a.pos[1])


# --------------------------------------------------------------------------- bad inputs

@pytest.fixture(scope="module")
def world_and_state():
    world = World()
    return world, world.init(n_envs=2, seed=0)


@pytest.mark.parametrize("call, name", [
    (lambda w, s: w.step(s, 1.0), "cmd_vel"),  # scalar: not a velocity
    (lambda w, s: w.step(s, np.full((2, 6, 2), np.nan)), "cmd_vel"),
    (lambda w, s: w.step(s, np.zeros((2, 6, 2)), np.full((2, 6), np.inf)), "cmd_yaw_rate"),
    (lambda w, s: w.rollout(s, -1, hover), "n_steps"),
    (lambda w, s: w.rollout(s, 2.5, hover), "n_steps"),
    (lambda w, s: w.rollout(s, 3, controller="dance"), "controller"),
    (lambda w, s: w.init(n_envs=1, positions=[[[5.0, 1.0]] * 6]), "positions"),
    (lambda w, s: w.init(n_envs=1, positions=[[[0.0, 1.0]] * 6]), "positions"),  # centre on the wall line
    (lambda w, s: w.init(n_envs=1, positions=[[[np.nan, 1.0]] * 6]), "positions"),
    (lambda w, s: w.init(n_envs=2, positions=np.ones((1, 6, 2))), "positions"),
    (lambda w, s: w.init(n_envs=1, yaw=np.zeros(6)), "yaw"),
    (lambda w, s: w.init(env_ids=[]), "env_ids"),
])
def test_bad_inputs_raise_config_error_naming_the_argument(world_and_state, call, name):
    world, state = world_and_state
    with pytest.raises(ConfigError, match=name):
        call(world, state)


@pytest.mark.parametrize("cmd_v, cmd_w", [(np.zeros((2, 6, 3)), None), (np.zeros(3), None),
                                          (np.zeros((2, 6, 2)), np.zeros((2, 5)))])
def test_wrong_command_shape_raises_config_error(world_and_state, cmd_v, cmd_w):
    world, state = world_and_state
    name = "cmd_vel" if cmd_w is None else "cmd_yaw_rate"
    try:
        world.step(state, cmd_v, cmd_w)
    except ConfigError as exc:
        assert name in str(exc)
    except ValueError as exc:
        raise AssertionError(f"plain ValueError without the argument name: {exc}") from exc
    else:
        raise AssertionError("accepted a wrongly shaped command")


def test_broadcastable_commands_are_accepted(world_and_state):
    world, state = world_and_state
    full = world.step(state, np.broadcast_to([0.3, -0.2], (2, 6, 2)), np.full((2, 6), 0.1))
    _assert_states_equal(world.step(state, [0.3, -0.2], 0.1), full)
    assert isinstance(full, WorldState)


# --------------------------------------------------------------------------- known answers of the copter model
# The continuous model (DESIGN "copters"): dv/dt = (v_cmd − v)/τ_v, dω/dt = (ω_cmd − ω)/τ_ψ, dp/dt = v, dψ/dt = ω,
# with |dv/dt| ≤ max_accel. These tests compare the engine with the closed-form solutions, not with a restated
# discretisation: the lag factor 1 − exp(−dt/τ) is exact at the sample times for a command held over the step,
# and the position (a right Riemann sum of an increasing velocity) lies above the exact integral by less than
# one step's velocity change times dt summed, i.e. by at most |v_cmd|·dt.

def _lone_copter(**extra):
    cfg = Config().replace({"copters.n": 1, "walls.bending": False, "simulation.dt": 0.01,
                            "copters.max_speed": 5.0, **extra})
    world = World(cfg)
    state = world.init(n_envs=1, seed=0, positions=np.array([[[1.5, 2.0]]]), yaw=np.zeros((1, 1)))
    return world, state


def test_velocity_and_position_follow_the_first_order_lag_in_closed_form():
    tau, dt, c = 0.3, 0.01, np.array([0.2, -0.1])
    world, state = _lone_copter(**{"copters.velocity_tau": tau, "copters.max_accel": 1000.0})
    p0 = state.pos[0, 0].copy()
    for k in range(1, 101):
        state = world.step(state, c[None, None, :])
        t = k * dt
        np.testing.assert_allclose(state.vel[0, 0], c * (1.0 - math.exp(-t / tau)), rtol=0, atol=1e-12)
        exact = p0 + c * (t - tau * (1.0 - math.exp(-t / tau)))
        err = (state.pos[0, 0] - exact) * np.sign(c)
        assert np.all(err >= -1e-12) and np.all(err <= np.abs(c) * dt + 1e-12), (k, err)


def test_acceleration_limit_gives_a_linear_ramp_to_the_command():
    a_max, dt, c = 0.5, 0.01, np.array([0.3, 0.4])  # |c| = 0.5 m/s, reached after 1 s
    world, state = _lone_copter(**{"copters.velocity_tau": 0.0, "copters.max_accel": a_max})
    for k in range(1, 151):
        state = world.step(state, c[None, None, :])
        speed = min(a_max * k * dt, 0.5)
        np.testing.assert_allclose(state.vel[0, 0], c / 0.5 * speed, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.hypot(*state.acc[0, 0]), a_max if k * dt <= 1.0 + 1e-9 else 0.0, atol=1e-9)


def test_yaw_rate_follows_its_lag_and_yaw_its_integral_in_closed_form():
    tau, dt, w = 0.2, 0.01, 1.0  # rad/s, below the default max_yaw_rate
    world, state = _lone_copter(**{"copters.yaw_tau": tau})
    assert w < math.radians(world.cfg.copters.max_yaw_rate_deg)
    for k in range(1, 101):
        state = world.step(state, np.zeros((1, 1, 2)), np.full((1, 1), w))
        t = k * dt
        assert state.yaw_rate[0, 0] == pytest.approx(w * (1.0 - math.exp(-t / tau)), abs=1e-12)
        exact = w * (t - tau * (1.0 - math.exp(-t / tau)))
        assert 0.0 <= state.yaw[0, 0] - exact <= w * dt + 1e-12
