"""The closed swarm loop: compiled rollout == per-step Python reference bit for bit, batch invariance,
the two-copter equilibrium of attraction–repulsion, the wall check in flight, user Python behaviours."""
from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest

from finkensim.behaviours.attraction import settle_distance, settle_reading
from finkensim.determinism import first_difference
from finkensim.config import Config, ConfigError
from finkensim.sensors.ranging import RangingModel, ranging_readings
from finkensim.behaviours.open_loop import RandomWalk
from finkensim.swarm import SwarmRecord, SwarmSim, ranging_batch
from finkensim.world import World


def _noisy_cfg(kind="attraction_repulsion", wall_check="sequence", n=3, **kw):
    """Every sensor on, with its default (noisy) error model and geometric cross-talk; a beacon."""
    upd = {"behaviour.kind": kind, "behaviour.wall_check": wall_check, "copters.n": n,
           "behaviour.sequence_fail_count": 3, "ranging.beacons": [[1.5, 2.0]],
           "imu.acc_noise_density": 0.05, "imu.acc_bias_walk": 0.01, "copters.min_separation": 0.3}
    upd.update(kw)
    return Config().replace(upd)


def _assert_same(a, b, what):
    """Bit-for-bit equality of two dataclass / NamedTuple trees (states, records), naming the first difference."""
    names = a._fields if hasattr(a, "_fields") else [f.name for f in fields(a)]
    for name in names:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, dict):
            for k in x:
                assert first_difference(x[k], y[k]) is None, f"{what}.{name}[{k}]: {first_difference(x[k], y[k])}"
        elif isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert first_difference(x, y) is None, f"{what}.{name}: first difference at {first_difference(x, y)}"
        elif hasattr(x, "__dataclass_fields__") or hasattr(x, "_fields"):
            _assert_same(x, y, f"{what}.{name}")
        elif name != "memory":
            assert x == y, f"{what}.{name}: {x!r} != {y!r}"


# ------------------------------------------------------------------------------ compiled == per-step reference


@pytest.mark.parametrize("B", [1, 7, 64])
def test_compiled_rollout_equals_step_by_step_reference(B):
    sim = SwarmSim(_noisy_cfg())
    state = sim.init(n_envs=B, seed=12)
    before = state.copy()
    fast, rec_fast = sim.rollout(state, 50, record=True)
    slow, rec_slow = sim.rollout(state, 50, record=True, python=True)
    _assert_same(state, before, "input state")  # both paths are pure
    _assert_same(rec_fast, rec_slow, "record")
    _assert_same(fast, slow, "final")
    assert fast.step == 50 and rec_fast.sonar.shape == (50, B, 3, 4) and rec_fast.ranging.shape == (50, B, 3, 4)
    assert rec_fast.wall.any() and (rec_fast.sonar < 3.0).any()  # the check and the sonars were exercised


@pytest.mark.parametrize("kind,wall_check", [("random_walk", "per_reading"), ("hover", "none"),
                                             ("attraction_repulsion", "per_reading")])
def test_compiled_equals_reference_for_every_builtin_behaviour(kind, wall_check):
    sim = SwarmSim(_noisy_cfg(kind, wall_check, n=4, **{"sonar.error": "seed", "sonar.crosstalk": "constant",
                                                           "ranging.error": "seed"}))
    state = sim.init(n_envs=5, seed=3)
    fast, rec_fast = sim.rollout(state, 30)
    slow, rec_slow = sim.rollout(state, 30, python=True)
    _assert_same(rec_fast, rec_slow, "record")
    _assert_same(fast, slow, "final")


def test_random_walk_flies_exactly_as_the_world_rollout():
    cfg = _noisy_cfg("random_walk", "none", n=4)
    sim = SwarmSim(cfg)
    state = sim.init(n_envs=3, seed=8)
    _, rec = sim.rollout(state, 40, record=("pose", "vel", "acc", "yaw_rate", "theta"))
    _, traj = World(cfg).rollout(state.world, 40, RandomWalk(cfg))
    np.testing.assert_array_equal(rec.pose, traj.pose)
    np.testing.assert_array_equal(rec.theta, traj.theta)
    for name in ("vel", "acc", "yaw_rate"):
        np.testing.assert_array_equal(getattr(rec, name), getattr(traj, name), err_msg=name)
    # without sensors (for open-loop behaviours only): the same flight, memory untouched
    quiet = SwarmSim(cfg, sensors=False)
    assert quiet.recordable() == ("pose", "vel", "acc", "yaw_rate", "theta", "wall", "cmd_vel", "cmd_yaw_rate")
    final, rec2 = quiet.rollout(state, 40, record=("pose",))
    np.testing.assert_array_equal(rec2.pose, traj.pose)
    assert not final.imu_bias.any() and not final.behaviour.dr_pos.any()
    with pytest.raises(ConfigError, match="sensors = False"):
        SwarmSim(_noisy_cfg(), sensors=False)


def test_rollout_continues_where_it_stopped():
    sim = SwarmSim(_noisy_cfg())
    state = sim.init(n_envs=4, seed=1)
    whole, rec = sim.rollout(state, 40, record=("pose", "wall"))
    half, rec1 = sim.rollout(state, 25, record=("pose", "wall"))
    end, rec2 = sim.rollout(half, 15, record=("pose", "wall"))
    _assert_same(whole, end, "final")
    np.testing.assert_array_equal(rec.pose, np.concatenate([rec1.pose, rec2.pose]))
    np.testing.assert_array_equal(rec.wall, np.concatenate([rec1.wall, rec2.wall]))
    np.testing.assert_array_equal(rec.counters["wall_readings"],
                                  rec1.counters["wall_readings"] + rec2.counters["wall_readings"])


# ------------------------------------------------------------------------------ batch invariance


def _select_record(rec: SwarmRecord, k):
    out = {}
    for name, v in rec._asdict().items():
        if name == "counters":
            out[name] = {n: c[k:k + 1] for n, c in v.items()}
        elif v is None or name == "t":
            out[name] = v
        else:
            out[name] = v[:, k:k + 1]
    return SwarmRecord(**out)


def test_lone_environment_equals_its_row_in_a_batch():
    sim = SwarmSim(_noisy_cfg())
    batch = sim.init(n_envs=7, seed=5)
    final, rec = sim.rollout(batch, 40)
    for k in (0, 3, 6):
        lone = sim.init(env_ids=[k], seed=5)
        _assert_same(lone, batch.select([k]), f"init {k}")
        lone_final, lone_rec = sim.rollout(lone, 40)
        _assert_same(lone_rec, _select_record(rec, k), f"record env {k}")
        _assert_same(lone_final, final.select([k]), f"final env {k}")
    rev = np.arange(7)[::-1].copy()
    rev_final, _ = sim.rollout(sim.init(env_ids=rev, seed=5), 40)
    _assert_same(rev_final, final.select(rev), "reversed env_ids")


# ------------------------------------------------------------------------------ the ranging kernel


@pytest.mark.parametrize("mode", ["mixture", "seed", "gaussian", "none"])
def test_ranging_env_equals_ranging_readings(mode):
    rng = np.random.default_rng(0)
    model = RangingModel(mode)
    pos = rng.uniform(0, 3, (5, 4, 2))
    beacons = np.array([[0.1, 0.2], [2.9, 3.5]])
    env_ids = np.array([3, 1, 4, 1, 5])
    out = np.empty((5, 4, 6))
    ranging_batch(pos, np.zeros(pos.shape[:2]), beacons, 9, env_ids, 17, model.params, out)
    np.testing.assert_array_equal(out, ranging_readings(pos, beacons, 9, env_ids, 17, model))


# ------------------------------------------------------------------------------ behaviour in flight


def _two_copters(**kw):
    upd = {"arena.width": 30.0, "arena.length": 30.0, "copters.n": 2, "behaviour.kind": "attraction_repulsion",
           "behaviour.w_t": 0.0, "sonar.error": "none", "sonar.crosstalk": "off", "ranging.error": "none"}
    upd.update(kw)
    return Config().replace(upd)


@pytest.mark.parametrize("d0", [1.0, 2.5, 3.0])
def test_two_copters_settle_where_attraction_equals_repulsion(d0):
    """Facing each other along their front sonars in open space, two copters settle where a = b exp(−r²/c)
    for the sonar reading r = d − radius − offset: d* = sqrt(c ln(b/a)) + radius + offset = 1.5920 m."""
    cfg = _two_copters()
    sim = SwarmSim(cfg)
    state = sim.init(n_envs=1, seed=0, positions=[[[15.0 - d0 / 2, 15.0], [15.0 + d0 / 2, 15.0]]],
                     yaw=[[0.0, -np.pi]])
    final, rec = sim.rollout(state, 400, record=("pose", "sonar"))
    d = np.linalg.norm(final.world.pos[0, 1] - final.world.pos[0, 0])
    expect = settle_distance(cfg)
    assert expect == pytest.approx(np.sqrt(1.5 * np.log(4.0)) + 0.15)
    assert d == pytest.approx(expect, abs=1e-4)
    r = rec.sonar[-1, 0, :, 0]  # each front sonar reads the equilibrium reading
    np.testing.assert_allclose(r, settle_reading(1.0, 4.0, 1.5), atol=1e-4)
    np.testing.assert_allclose(final.world.pos[0, :, 1], 15.0)  # stays on the axis
    assert (rec.sonar[:, 0, :, 1:] == cfg.sonar.max_range).all()  # the other sonars never see anything


def test_sonar_offset_moves_the_equilibrium():
    cfg = _two_copters(**{"sonar.offset": 0.1})
    sim = SwarmSim(cfg)
    state = sim.init(n_envs=1, seed=0, positions=[[[14.0, 15.0], [16.0, 15.0]]], yaw=[[0.0, -np.pi]])
    final, _ = sim.rollout(state, 400, record=False)
    d = np.linalg.norm(final.world.pos[0, 1] - final.world.pos[0, 0])
    assert d == pytest.approx(settle_distance(cfg), abs=1e-4)
    assert settle_distance(cfg) == pytest.approx(settle_reading() + 0.25)


@pytest.mark.parametrize("check", ["none", "per_reading"])
def test_wall_check_stops_a_copter_sticking_to_a_wall(check):
    """Without the check the wall attracts like a swarm-mate and the copter hangs at r* from it; with the
    per-reading check (no ranging tag there) the wall only repels."""
    cfg = _two_copters(**{"copters.n": 1, "behaviour.wall_check": check})
    sim = SwarmSim(cfg)
    state = sim.init(n_envs=1, seed=0, positions=[[[2.0, 15.5]]], yaw=[[0.0]])  # back sonar sees the west net
    final, rec = sim.rollout(state, 400, record=("wall",))
    x = final.world.pos[0, 0, 0]
    if check == "none":
        assert x == pytest.approx(settle_reading(), abs=1e-3)
        assert rec.counters["wall_readings"][0, 0] == 0
    else:
        assert x > 2.5
        assert rec.wall[0, 0, 0, 2] and rec.counters["wall_readings"][0, 0] > 0


# ------------------------------------------------------------------------------ user behaviours


def explorer(readings, memory, params):
    """The module docstring's example."""
    r = readings.sonar
    heading = np.radians([0.0, 90.0, 180.0, -90.0])[r.argmax(-1)]
    speed = np.where(r.min(-1) < 0.5, 0.0, 0.3)
    v = speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], -1)
    memory["steps"] = memory.get("steps", 0) + 1
    return v, None


def test_user_python_behaviour_runs():
    cfg = _noisy_cfg("random_walk", "per_reading", n=4)
    sim = SwarmSim(cfg, behaviour=explorer)
    state = sim.init(n_envs=3, seed=2)
    final, rec = sim.rollout(state, 30)
    assert final.memory["steps"] == 30 and final.step == 30
    assert np.abs(rec.cmd_vel).max() > 0.0 and np.isfinite(rec.pose).all()
    speeds = np.linalg.norm(rec.cmd_vel, axis=-1)
    assert np.all((np.abs(speeds - 0.3) < 1e-12) | (speeds == 0.0))
    # the same function, run again from the same state, gives the same flight (memory aside)
    again, rec2 = sim.rollout(sim.init(n_envs=3, seed=2), 30)
    np.testing.assert_array_equal(rec.pose, rec2.pose)


def test_user_behaviour_sees_only_sensors_and_can_command_in_the_world_frame():
    seen = {}

    def go_east(readings, memory, params):
        seen.update(readings._asdict())
        memory.setdefault("calls", 0)
        memory["calls"] += 1
        return np.broadcast_to([0.2, 0.0], readings.wall.shape[:2] + (2,)), np.zeros(readings.wall.shape[:2])

    cfg = _two_copters(**{"copters.n": 1})
    sim = SwarmSim(cfg, behaviour=go_east, command_frame="world", memory_factory=lambda B, N: {"B": B})
    state = sim.init(n_envs=1, seed=0, positions=[[[10.0, 10.0]]], yaw=[[1.0]])
    final, _ = sim.rollout(state, 100, record=False)
    assert final.memory == {"B": 1, "calls": 100}
    assert final.world.pos[0, 0, 0] > 10.5 and final.world.pos[0, 0, 1] == pytest.approx(10.0)
    assert set(seen) == {"sonar", "sonar_down", "ranging", "imu_acc", "imu_gyro", "wall", "step", "dt", "seed",
                         "env_ids"}

    def bad(readings, memory, params):
        return np.zeros(3)

    with pytest.raises(ConfigError, match="expected a tuple"):
        SwarmSim(cfg, behaviour=bad).rollout(sim.init(n_envs=1, seed=0), 1)


# ------------------------------------------------------------------------------ errors and options


def test_configuration_errors_name_the_key():
    with pytest.raises(ConfigError, match="sonar.enabled"):
        SwarmSim(Config().replace({"behaviour.kind": "attraction_repulsion", "sonar.enabled": False}))
    with pytest.raises(ConfigError, match="ranging.enabled"):
        SwarmSim(Config().replace({"behaviour.wall_check": "per_reading", "ranging.enabled": False}))
    with pytest.raises(ConfigError, match="imu.enabled"):
        SwarmSim(Config().replace({"behaviour.wall_check": "sequence", "imu.enabled": False}))
    with pytest.raises(ConfigError, match="behaviour"):
        SwarmSim(Config(), behaviour="flocking")
    sim = SwarmSim(Config().replace({"imu.enabled": False}))
    with pytest.raises(ConfigError, match="imu_acc"):
        sim.rollout(sim.init(n_envs=1, seed=0), 2, record=("imu_acc",))
    with pytest.raises(ConfigError, match="unknown name"):
        sim.rollout(sim.init(n_envs=1, seed=0), 2, record=("posee",))
    with pytest.raises(ConfigError, match="n_steps"):
        sim.rollout(sim.init(n_envs=1, seed=0), -1)


def test_disabled_sensors_are_skipped_and_record_false_keeps_counters():
    cfg = _noisy_cfg("random_walk", "none", n=3, **{"imu.enabled": False, "ranging.enabled": False})
    sim = SwarmSim(cfg)
    assert "imu_acc" not in sim.recordable() and "ranging" not in sim.recordable()
    state = sim.init(n_envs=2, seed=0)
    final, rec = sim.rollout(state, 20, record=False)
    assert rec.pose is None and set(rec.counters) == {"collisions", "wall_contacts", "wall_onsets", "wall_readings"}
    slow, _ = sim.rollout(state, 20, record=False, python=True)
    _assert_same(final, slow, "final")
    zero, rec0 = sim.rollout(state, 0)
    _assert_same(zero, state, "zero steps")
    assert rec0.pose.shape == (0, 2, 3, 3)


def test_a_rollout_in_parts_with_a_progress_bar_equals_one_rollout(capsys):
    """progress=True runs the flight in ~100 parts (the CLI's progress bar): every record, counter and the final state
    are those of one compiled call (the behaviour memory, IMU bias and plates carry over in the state)."""
    sim = SwarmSim(Config().replace({"behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "sequence",
                                     "copters.n": 8}))
    state = sim.init(n_envs=2, seed=4)
    one_state, one = sim.rollout(state, 230)
    parts_state, parts = sim.rollout(state, 230, progress="test flight")
    assert "test flight" in capsys.readouterr().err
    for name in ("pose", "sonar", "sonar_ideal", "ranging", "imu_acc", "wall", "theta", "cmd_vel"):
        np.testing.assert_array_equal(getattr(parts, name), getattr(one, name), err_msg=name)
    np.testing.assert_array_equal(parts.t, one.t)
    for k in one.counters:
        np.testing.assert_array_equal(parts.counters[k], one.counters[k])
    np.testing.assert_array_equal(parts_state.world.pos, one_state.world.pos)
    np.testing.assert_array_equal(parts_state.imu_bias, one_state.imu_bias)
    assert parts_state.step == one_state.step
