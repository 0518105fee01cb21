"""One simulated flight, end to end: scenario config → compiled rollout → flight log.

    from finkensim.scenario import load_scenario, simulate_flight
    cfg = load_scenario()                        # the embedded default: 6 copters, random walk, 60 s
    log, traj, world = simulate_flight(cfg, duration=10.0, seed=3)
    flightlog.save(log, "flight.npz")

:func:`simulate_flight` runs exactly one environment (B = 1) of the configured behaviour and turns
the recorded trajectory into a :class:`~finkensim.flightlog.FlightLog`. The open-loop behaviours
(``random_walk``, ``hover``) fly in :meth:`World.rollout <finkensim.world.World.rollout>`; the
closed-loop ones that read sensors (``attraction_repulsion``) in the compiled closed loop of
:class:`finkensim.swarm.SwarmSim` (sense → behave → step), and the log's sensor blocks are then the
very readings the behaviour acted on. Sensor readings are added in one place,
:func:`_sensor_blocks`, so each sensor model plugs in without touching the rest of the pipeline.
"""
from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from . import __version__
from .config import Config, ConfigError, load_config
from .flightlog import FlightLog, validate
from .world import Trajectory, World, WorldState

__all__ = [
    "DEFAULT_SCENARIO_TOML",
    "default_scenario_path",
    "load_scenario",
    "simulate_flight",
]

DEFAULT_SCENARIO_TOML = """\
# finkensim default scenario: 6 FINken copters on a bounded random walk for 60 s
# in the 3 m x 4 m SwarmLab arena, with Bernoulli curtain walls (16 plates per wall).
# Every key not given here takes its default; see finkensim.config for all keys.
profile = "default"

[arena]
width = 3.0       # m, x extent
length = 4.0      # m, y extent
altitude = 0.6    # m, flight height

[walls]
bending = true
n_segments = 16
threshold = 1.0           # m, copters closer than this pull a plate
max_amplitude_deg = 30.0  # deg, target = max_amplitude * f(x)

[copters]
n = 6
radius = 0.15     # m
max_speed = 1.0   # m/s

[behaviour]
kind = "random_walk"
speed = 0.3           # m/s cruise speed
redraw_steps = 20     # new random heading every 20 steps (1 s)
wall_margin = 0.4     # m, steer inward when closer to a wall
yaw_rate_deg = 20.0   # deg/s, largest random yaw-rate command

[simulation]
dt = 0.05         # s
duration = 60.0   # s
seed = 0
"""
"""The embedded default scenario (same text as ``finkensim/data/default_scenario.toml``)."""


def default_scenario_path() -> Path:
    """Path of the shipped copy of :data:`DEFAULT_SCENARIO_TOML` (``finkensim/data/default_scenario.toml``)."""
    return Path(str(resources.files("finkensim") / "data" / "default_scenario.toml"))


def load_scenario(source: str | Path | Mapping[str, Any] | Config | None = None) -> Config:
    """A scenario :class:`~finkensim.config.Config` from a TOML path, TOML text, a dict, a Config,
    or None for the embedded default scenario. Errors are :class:`~finkensim.config.ConfigError`."""
    if source is None:
        return load_config(DEFAULT_SCENARIO_TOML)
    if isinstance(source, Config):
        return source
    return load_config(source)


def _sensor_blocks(world: World, traj: Trajectory, state0: WorldState, ideal: bool = False,
                   recorded=None) -> dict[str, Any]:
    """Sensor readings of one simulated flight, as keyword arguments of :class:`FlightLog`.

    The one place where sensor models join the flight log. ``traj`` holds the recorded states of
    the single environment (``traj.pose`` (T, 1, N, 3), ``acc`` (T, 1, N, 2), ``yaw_rate`` (T, 1, N),
    ``theta`` (T, 1, S)); sample k uses the random numbers of step k, keyed by ``state0.seed`` and
    ``state0.env_ids``, exactly as an online sensor would at that step.

    ``recorded``: the :class:`~finkensim.swarm.SwarmRecord` of a closed-loop flight (T samples). Its
    sonar, down-sonar, ranging and IMU readings — the ones the behaviour used — are taken as they are
    (the error-free values are still computed from ``traj``), and its wall judgements are added as the
    extra ``ultrasonic_wall_flag`` (T, N, 4) int8 (1 = the behaviour's wall check took the reading for
    a wall).

    Returns ``ultrasonic`` (T, N, 4) m with ``ultrasonic_yaw``/``ultrasonic_offset``; ``ranging``
    (T, N, N) m; ``imu_acc`` (T, N, 2) m/s² and ``imu_gyro`` (T, N) rad/s; each only when its
    ``enabled`` key is true. Extras: ``ultrasonic_down`` (T, N) m (down-facing sonar),
    ``ranging_beacons`` (T, N, M) m and ``beacon_positions`` (M, 2) m when beacons are configured.
    With ``ideal=True`` also the error-free values as extras ``<name>_ideal`` and the sonar hit
    type ``ultrasonic_hit_type`` (T, N, 4; 0 none, 1 wall, 2 copter).
    """
    from .sensors.imu import ImuModel, ideal_imu, imu_from_trajectory
    from .sensors.ranging import RangingModel, ranging_readings
    from .sensors.ultrasonic import SonarModel, down_readings, ultrasonic_from_trajectory

    cfg, seed, env_ids = world.cfg, state0.seed, state0.env_ids
    T, _, N, _ = traj.pose.shape
    out: dict[str, Any] = {}
    extras: dict[str, np.ndarray] = {}
    rec = recorded
    if cfg.sonar.enabled:
        sonar = SonarModel.from_config(cfg)
        if rec is None or ideal:
            res = ultrasonic_from_trajectory(traj, world.arena, sonar, seed, env_ids, state0.step, return_ideal=ideal)
            readings = res[0] if ideal else res
        if rec is not None:
            readings = rec.sonar
            extras["ultrasonic_wall_flag"] = np.ascontiguousarray(rec.wall[:, 0]).astype(np.int8)
        out["ultrasonic"] = np.ascontiguousarray(readings[:, 0])
        out["ultrasonic_yaw"] = np.deg2rad(np.asarray(cfg.sonar.yaw_deg, dtype=float))
        out["ultrasonic_offset"] = float(cfg.sonar.offset)
        if ideal:
            extras["ultrasonic_ideal"] = np.ascontiguousarray(res[1][:, 0])
            extras["ultrasonic_hit_type"] = np.ascontiguousarray(res[2][:, 0]).astype(np.int64)
        if cfg.sonar.down_enabled and rec is not None:
            extras["ultrasonic_down"] = np.ascontiguousarray(rec.sonar_down[:, 0])
        elif cfg.sonar.down_enabled:
            pos1 = np.zeros((1, N, 2))
            extras["ultrasonic_down"] = np.stack(
                [down_readings(pos1, sonar, seed, env_ids, state0.step + k)[0] for k in range(T)])
    if cfg.ranging.enabled:
        model = RangingModel.from_config(cfg.ranging)
        beacons = np.asarray(cfg.ranging.beacons, dtype=float).reshape(-1, 2)
        if rec is not None:
            rows = rec.ranging[:, 0]
        else:
            rows = np.empty((T, N, N + beacons.shape[0]))
            for k in range(T):
                pos = np.ascontiguousarray(traj.pose[k, :, :, :2])
                rows[k] = ranging_readings(pos, beacons, seed, env_ids, state0.step + k, model)[0]
        out["ranging"] = np.ascontiguousarray(rows[:, :, :N])
        if beacons.shape[0]:
            extras["ranging_beacons"] = np.ascontiguousarray(rows[:, :, N:])
            extras["beacon_positions"] = beacons
        if ideal:
            extras["ranging_ideal"] = np.stack([
                ranging_readings(np.ascontiguousarray(traj.pose[k, :, :, :2]), beacons, seed, env_ids,
                                 state0.step + k, model, ideal=True)[0, :, :N] for k in range(T)])
    if cfg.imu.enabled:
        imu = ImuModel.from_config(cfg.imu, world.dt)
        if rec is not None:
            acc, gyro = rec.imu_acc, rec.imu_gyro
        else:
            acc, gyro = imu_from_trajectory(traj, imu, seed, env_ids, state0.step)
        out["imu_acc"] = np.ascontiguousarray(acc[:, 0])
        out["imu_gyro"] = np.ascontiguousarray(gyro[:, 0])
        if ideal:
            acc_i, gyro_i = ideal_imu(traj.acc, traj.pose[..., 2], traj.yaw_rate)
            extras["imu_acc_ideal"] = np.ascontiguousarray(acc_i[:, 0])
            extras["imu_gyro_ideal"] = np.ascontiguousarray(gyro_i[:, 0])
    if extras:
        out["extras"] = extras
    return out


def _n_steps(duration: float, dt: float) -> int:
    n = int(round(duration / dt))
    if n < 1:
        raise ConfigError(f"simulation.duration = {duration!r}: expected at least one step of simulation.dt = {dt!r} s")
    return n


def _closed_loop_flight(cfg: Config, n_steps: int):
    """(world, state0, traj, record) of ``n_steps`` closed-loop steps of one environment in
    :class:`~finkensim.swarm.SwarmSim` (compiled).

    The record holds the poses, plate angles, every enabled sensor's readings and wall judgements, and
    the world-frame commands. The kinematic quantities a flight log also needs (acceleration, yaw rate)
    come from replaying those commands through :meth:`World.rollout <finkensim.world.World.rollout>`:
    the same deterministic step function, so the replayed states equal the closed loop's bit for bit
    (checked)."""
    from .swarm import SwarmSim

    sim = SwarmSim(cfg)
    s0 = sim.init(n_envs=1, seed=cfg.simulation.seed)
    names = ("pose", "theta", "cmd_vel", "cmd_yaw_rate") + tuple(
        n for n in ("sonar", "sonar_down", "ranging", "imu_acc", "imu_gyro", "wall") if n in sim.recordable())
    _, rec = sim.rollout(s0, n_steps, record=names)
    world, state0 = sim.world, s0.world
    cmd_v, cmd_w = rec.cmd_vel, rec.cmd_yaw_rate
    import numba

    threads = numba.get_num_threads()
    numba.set_num_threads(1)  # one environment: a parallel region per step only costs (a lot on a busy machine)
    try:
        _, traj = world.rollout(state0, n_steps, controller=lambda w, s: (cmd_v[s.step - state0.step],
                                                                          cmd_w[s.step - state0.step]))
    finally:
        numba.set_num_threads(threads)
    if not (np.array_equal(traj.pose, rec.pose) and np.array_equal(traj.theta, rec.theta)):
        raise RuntimeError("replaying the closed loop's commands gave another trajectory; please report this bug")
    return world, state0, traj, rec


def simulate_flight(cfg: Config | str | Path | Mapping[str, Any] | None = None, *, duration: float | None = None,
                    seed: int | None = None, ideal: bool = False) -> tuple[FlightLog, Trajectory, World]:
    """Simulate one flight of the configured behaviour and build its flight log.

    Args:
        cfg: a Config, a TOML path or text, a dict, or None for the embedded default scenario.
        duration: flight length in s (default ``simulation.duration``).
        seed: random seed (default ``simulation.seed``).
        ideal: also store the error-free sensor values (extras ``*_ideal``, ``ultrasonic_hit_type``).

    One environment (B = 1, environment index 0) is placed at random and flown for
    round(duration / dt) steps by ``behaviour.kind`` in compiled code: ``random_walk`` and ``hover``
    in :meth:`World.rollout <finkensim.world.World.rollout>`, ``attraction_repulsion`` in the closed
    loop of :class:`~finkensim.swarm.SwarmSim`, whose sensor readings (those the behaviour acted on)
    become the log's sensor blocks, with its wall judgements as the extra ``ultrasonic_wall_flag``
    (T, N, 4) int8. The log has
    T = steps + 1 samples at t = 0, dt, ..., duration (the state before each step plus the
    final one). ``duration``/``seed`` overrides are written into the config, so
    ``meta["config"]`` always describes the run exactly: ``config_from_dict(log.meta["config"])``
    rebuilds it.

    Returns:
        (log, traj, world): the validated :class:`FlightLog`; the :class:`Trajectory` of the
        flight (arrays with a leading time axis and B = 1, e.g. ``traj.theta`` (T, 1, S) plate
        angles in rad); the :class:`World` that ran it.

    Besides poses, the log carries ``meta`` = {copter_radius, altitude, source, tracking_sigma_xy
    = tracking_sigma_yaw = 0 (ground truth), dt, duration, seed, behaviour, config} and the plate
    angles as the extra array ``wall_theta`` (T, S) rad (plates ordered south, east, north, west).
    """
    cfg = load_scenario(cfg)
    updates: dict[str, Any] = {}
    if duration is not None:
        updates["simulation.duration"] = duration
    if seed is not None:
        updates["simulation.seed"] = seed
    if cfg.simulation.n_envs != 1:
        updates["simulation.n_envs"] = 1
    if updates:
        cfg = cfg.replace(updates)
    sim = cfg.simulation
    n_steps = _n_steps(sim.duration, sim.dt)

    from .episode import needs_sensors

    recorded = None
    # n_steps + 1 steps record the states at t = 0 .. duration inclusive
    if needs_sensors(cfg.behaviour.kind):
        world, state0, traj, recorded = _closed_loop_flight(cfg, n_steps + 1)
    else:
        world = World(cfg)
        state0 = world.init(n_envs=1, seed=sim.seed)
        _, traj = world.rollout(state0, n_steps + 1, controller=cfg.behaviour.kind)

    n = world.n_copters
    meta: dict[str, Any] = {
        "copter_radius": cfg.copters.radius,
        "altitude": cfg.arena.altitude,
        "source": f"finkensim {__version__}",
        "tracking_sigma_xy": 0.0,
        "tracking_sigma_yaw": 0.0,
        "dt": sim.dt,
        "duration": sim.duration,
        "seed": sim.seed,
        "behaviour": cfg.behaviour.kind,
        "config": json.loads(json.dumps(cfg.to_dict())),  # plain JSON types only
    }
    extras: dict[str, np.ndarray] = {"wall_theta": np.ascontiguousarray(traj.theta[:, 0])}

    blocks = dict(_sensor_blocks(world, traj, state0, ideal=ideal, recorded=recorded))
    meta.update(blocks.pop("meta", {}) or {})
    extras.update(blocks.pop("extras", {}) or {})

    log = FlightLog(
        t=np.asarray(traj.t, dtype=float),
        arena=np.array([cfg.arena.width, cfg.arena.length]),
        pose=np.ascontiguousarray(traj.pose[:, 0]),
        copter_ids=np.array([f"copter{i}" for i in range(n)]),
        meta=meta,
        extras=extras,
        **blocks,
    )
    validate(log)
    return log, traj, world
