"""One simulated flight, end to end: scenario config → compiled rollout → flight log.

    from finkensim.scenario import load_scenario, simulate_flight
    cfg = load_scenario()                        # the embedded default: 6 copters, random walk, 60 s
    log, traj, world = simulate_flight(cfg, duration=10.0, seed=3)
    flightlog.save(log, "flight.npz")

:func:`simulate_flight` runs exactly one environment (B = 1) of the configured behaviour in the
compiled loop of :class:`finkensim.swarm.SwarmSim` (sense → behave → step) and turns its record into a
:class:`~finkensim.flightlog.FlightLog`: the state before each step, and the sensor readings taken in
the loop (for a closed-loop behaviour, the very readings it acted on). Sensor readings join the log in
one place, :func:`sensor_blocks`, so each sensor model plugs in without touching the rest of the
pipeline. The default scenario itself lives in :mod:`finkensim.default_scenario` (re-exported here).

:func:`fly_recorded_poses` is the other way to fly a config: its sensors along poses someone recorded (a real
flight's tracked poses, heights included), so simulated and real readings of the same motion stand side by side.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from . import __version__
from .budget import check_memory, flight_advice, flight_arrays
from .config import Config, ConfigError
from .default_scenario import DEFAULT_SCENARIO_TOML, default_scenario_path, load_scenario
from .flightlog import HEIGHTS, FlightLog, heights, validate
from .swarm import SwarmRecord, SwarmSim, needs_sensors
from .world import Trajectory, World

__all__ = [
    "DEFAULT_SCENARIO_TOML",
    "default_scenario_path",
    "load_scenario",
    "flight_log",
    "flight_record_names",
    "fly_recorded_poses",
    "sensor_blocks",
    "simulate_flight",
    "preflight",
]


def flight_record_names(sim: SwarmSim, ideal: bool = False) -> tuple[str, ...]:
    """What :func:`simulate_flight` records from ``sim``'s rollout: the state (pose, vel, acc, yaw_rate,
    theta), every enabled sensor, with ``ideal`` the sonars' error-free values, and the wall judgements
    of a closed-loop behaviour."""
    wanted = ("pose", "vel", "acc", "yaw_rate", "theta", "sonar", "sonar_down", "ranging", "imu_acc", "imu_gyro")
    if ideal:
        wanted += ("sonar_ideal", "sonar_hit")
    if needs_sensors(sim.kind):
        wanted += ("wall",)
    avail = sim.recordable()
    return tuple(n for n in wanted if n in avail)


def sensor_blocks(cfg: Config, rec: SwarmRecord, seed: int, env_ids, step0: int = 0,
                  ideal: bool = False) -> dict[str, Any]:
    """Sensor readings of one simulated flight, as keyword arguments of :class:`FlightLog`.

    The one place where sensor models join the flight log. ``rec`` is the :class:`~finkensim.swarm.SwarmRecord`
    of one environment (B = 1, T samples) recorded with :func:`flight_record_names`; sample k is step
    ``step0 + k`` of the run keyed by ``seed`` and ``env_ids`` (1,).

    Returns the sonar readings as the flight-log arrays ``ultrasonic`` (T, N, 4) m (the spec's names) with ``ultrasonic_yaw``/``ultrasonic_offset``; ``ranging``
    (T, N, N) m; ``imu_acc`` (T, N, 2) m/s² and ``imu_gyro`` (T, N) rad/s; each only when its
    ``enabled`` key is true. Extras: ``ultrasonic_down`` (T, N) m (down-facing sonar),
    ``ranging_beacons`` (T, N, M) m and ``beacon_positions`` (M, 2) m when beacons are configured, and,
    when the record has the wall judgements (closed-loop behaviours), ``ultrasonic_wall_flag`` (T, N, 4)
    int8 (1 = the behaviour's wall check took the reading for a wall). With ``ideal=True`` also the
    error-free values as extras ``<name>_ideal`` and the sonar hit type ``ultrasonic_hit_type``
    (T, N, 4; 0 none, 1 wall, 2 copter).
    """
    from .sensors.imu import ideal_imu
    from .sensors.ranging import RangingModel, ranging_readings

    T, _, N, _ = rec.pose.shape
    out: dict[str, Any] = {}
    extras: dict[str, np.ndarray] = {}
    if cfg.sonar.enabled:
        if rec.wall is not None:
            extras["ultrasonic_wall_flag"] = np.ascontiguousarray(rec.wall[:, 0]).astype(np.int8)
        out["ultrasonic"] = np.ascontiguousarray(rec.sonar[:, 0])
        out["ultrasonic_yaw"] = np.deg2rad(np.asarray(cfg.sonar.yaw_deg, dtype=float))
        out["ultrasonic_offset"] = float(cfg.sonar.offset)
        if ideal:
            extras["ultrasonic_ideal"] = np.ascontiguousarray(rec.sonar_ideal[:, 0])
            extras["ultrasonic_hit_type"] = np.ascontiguousarray(rec.sonar_hit[:, 0]).astype(np.int64)
        if cfg.sonar.down_enabled:
            extras["ultrasonic_down"] = np.ascontiguousarray(rec.sonar_down[:, 0])
    if cfg.ranging.enabled:
        model = RangingModel.from_config(cfg.ranging)
        beacons = np.asarray(cfg.ranging.beacons, dtype=float).reshape(-1, 2)
        rows = rec.ranging[:, 0]
        out["ranging"] = np.ascontiguousarray(rows[:, :, :N])
        if beacons.shape[0]:
            extras["ranging_beacons"] = np.ascontiguousarray(rows[:, :, N:])
            extras["beacon_positions"] = beacons
        if ideal:
            # the error-free values draw no random numbers (no seed, step or environment enters them): the T samples
            # as one batch of T rows, one parallel call instead of one per sample, the same values
            extras["ranging_ideal"] = np.ascontiguousarray(ranging_readings(
                np.ascontiguousarray(rec.pose[:, 0, :, :2]), beacons, seed, np.repeat(np.asarray(env_ids)[:1], T),
                step0, model, ideal=True, yaw=np.ascontiguousarray(rec.pose[:, 0, :, 2]))[:, :, :N])
    if cfg.imu.enabled:
        out["imu_acc"] = np.ascontiguousarray(rec.imu_acc[:, 0])
        out["imu_gyro"] = np.ascontiguousarray(rec.imu_gyro[:, 0])
        if ideal:
            acc_i, gyro_i = ideal_imu(rec.acc, rec.pose[..., 2], rec.yaw_rate)
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


def preflight(cfg: Config, ideal: bool = False):
    """Everything a flight of ``cfg`` checks before it flies, without flying: at least one step of
    ``simulation.dt`` in ``simulation.duration``, the memory the flight would hold, the sensor and
    behaviour models (ranges, mixture files, a wall check's sensors) and the start placement of
    environment 0 of ``simulation.seed`` (which warns when ``copters.min_separation`` cannot be met).

    Returns (swarm, state0, n_steps): the :class:`~finkensim.swarm.SwarmSim`, its initial state (B = 1)
    and the number of steps. ``finkensim check`` runs it on a scenario file, so that check and run agree.
    """
    sim = cfg.simulation
    n_steps = _n_steps(sim.duration, sim.dt)
    check_memory(flight_arrays(cfg, ideal=ideal), f"a flight of {sim.duration:g} s of {cfg.copters.n} copters",
                 flight_advice(cfg))
    swarm = SwarmSim(cfg)
    return swarm, swarm.init(n_envs=1, seed=sim.seed), n_steps


def simulate_flight(cfg: Config | str | Path | Mapping[str, Any] | None = None, *, duration: float | None = None,
                    seed: int | None = None, ideal: bool = False,
                    progress: bool = False) -> tuple[FlightLog, Trajectory, World]:
    """Simulate one flight of the configured behaviour and build its flight log.

    One environment (B = 1, environment index 0) is placed at random and flown for
    round(duration / dt) steps by ``behaviour.kind`` in the compiled loop of
    :class:`~finkensim.swarm.SwarmSim`, whose sensor readings (for ``attraction_repulsion``, those the
    behaviour acted on) become the log's sensor blocks; a closed-loop behaviour's wall judgements
    become the extra ``ultrasonic_wall_flag`` (T, N, 4) int8. The log has
    T = steps + 1 samples at t = 0, dt, ..., duration (the state before each step plus the
    final one). ``duration``/``seed`` overrides are written into the config, so
    ``meta["config"]`` always describes the run exactly: ``config_from_dict(log.meta["config"])``
    rebuilds it.

    Parameters
    ----------
    cfg : Config, str, Path, Mapping or None
        A Config, a TOML path or text, a dict, or None for the embedded default scenario.
    duration : float, optional
        Flight length, s (default ``simulation.duration``).
    seed : int, optional
        Random seed (default ``simulation.seed``).
    ideal : bool
        Also store the error-free sensor values (extras ``*_ideal``, ``ultrasonic_hit_type``).
    progress : bool
        A progress bar on stderr (the flight runs in about 100 parts; the same results).

    Returns
    -------
    log : FlightLog
        The validated flight log (T samples, N copters).
    traj : Trajectory
        The flight's trajectory (arrays with a leading time axis and B = 1, e.g. ``traj.theta`` (T, 1, S)
        plate angles in rad).
    world : World
        The physics that ran it.

    Notes
    -----
    Besides poses, the log carries ``meta`` = {copter_radius, altitude, source, tracking_sigma_xy,
    tracking_sigma_yaw, dt, duration, seed, behaviour, config} and the plate
    angles as the extra array ``wall_theta`` (T, S) rad (plates ordered south, east, north, west). The poses are the
    true ones unless ``log.tracking_sigma_xy`` / ``log.tracking_sigma_yaw`` (m, rad) are set: then they are what a
    tracker with that noise records (:func:`~finkensim.sensors.tracking.tracked_poses`; meta says the σ), and with
    ``ideal`` the true poses are the extra ``pose_true`` (T, N, 3).
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
    swarm, state0, n_steps = preflight(cfg, ideal=ideal)
    # n_steps + 1 steps record the states at t = 0 .. duration inclusive
    _, rec = swarm.rollout(state0, n_steps + 1, record=flight_record_names(swarm, ideal),
                           progress="flight" if progress else False)
    log, traj = flight_log(cfg, swarm, state0, rec, ideal=ideal)
    return log, traj, swarm.world


def flight_log(cfg: Config, swarm: SwarmSim, state0, rec: SwarmRecord, ideal: bool = False) -> tuple[FlightLog,
                                                                                                    Trajectory]:
    """The :class:`FlightLog` and :class:`~finkensim.world.Trajectory` of ``swarm``'s rollout ``rec`` (B = 1,
    recorded with :func:`flight_record_names`) from ``state0``: the second half of :func:`simulate_flight`."""
    sim = cfg.simulation
    world = swarm.world
    traj = Trajectory(t=rec.t, pose=rec.pose, vel=rec.vel, acc=rec.acc, yaw_rate=rec.yaw_rate, theta=rec.theta)

    n = world.n_copters
    meta: dict[str, Any] = {
        "copter_radius": cfg.copters.radius,
        "altitude": cfg.arena.altitude,
        "source": f"finkensim {__version__}",
        "tracking_sigma_xy": cfg.log.tracking_sigma_xy,
        "tracking_sigma_yaw": cfg.log.tracking_sigma_yaw,
        "dt": sim.dt,
        "duration": sim.duration,
        "seed": sim.seed,
        "behaviour": cfg.behaviour.kind,
        "config": json.loads(json.dumps(cfg.to_dict())),  # plain JSON types only
    }
    extras: dict[str, np.ndarray] = {"wall_theta": np.ascontiguousarray(traj.theta[:, 0])}

    blocks = sensor_blocks(cfg, rec, state0.world.seed, state0.world.env_ids, state0.step, ideal=ideal)
    meta.update(blocks.pop("meta", {}) or {})
    extras.update(blocks.pop("extras", {}) or {})

    pose = np.ascontiguousarray(traj.pose[:, 0])
    if cfg.log.tracking_sigma_xy > 0.0 or cfg.log.tracking_sigma_yaw > 0.0:
        if ideal:
            extras["pose_true"] = pose
        pose = _tracked(pose, cfg.log, sim.seed, int(state0.world.env_ids[0]))
        np.clip(pose[..., 0], 0.0, cfg.arena.width, out=pose[..., 0])
        np.clip(pose[..., 1], 0.0, cfg.arena.length, out=pose[..., 1])
    log = FlightLog(
        t=np.asarray(traj.t, dtype=float),
        arena=np.array([cfg.arena.width, cfg.arena.length]),
        pose=pose,
        copter_ids=np.array([f"copter{i}" for i in range(n)]),
        meta=meta,
        extras=extras,
        **blocks,
    )
    validate(log)
    return log, traj


def _tracked(pose, log_cfg, seed: int, env_id: int):
    """The poses (T, N, 3) a tracker with the configured noise records (:mod:`finkensim.sensors.tracking`), x and y
    kept inside the arena (the flight-log format's frame), yaw wrapped to [−π, π]."""
    from .sensors.tracking import tracked_poses

    pos = np.ascontiguousarray(pose[..., :2])
    yaw = np.ascontiguousarray(pose[..., 2])
    out_pos, out_yaw = np.empty_like(pos), np.empty_like(yaw)
    tracked_poses(pos, yaw, float(log_cfg.tracking_sigma_xy), float(log_cfg.tracking_sigma_yaw), int(seed), env_id,
                  out_pos, out_yaw)
    return np.concatenate([out_pos, np.arctan2(np.sin(out_yaw), np.cos(out_yaw))[..., None]], axis=-1)


def fly_recorded_poses(log: FlightLog, cfg: Config | str | Path | Mapping[str, Any] | None = None, *,
                       seed: int | None = None) -> FlightLog:
    """The config's ranging sensor flown along a log's recorded poses: a flight log of the same motion whose readings
    the simulator made.

    The copters do not fly themselves: at every sample of ``log`` they sit at its poses (and heights, the extra
    ``z``, so distances are 3-D where the log has them), and the ranging readings are the engine's kernel at those
    poses (:func:`~finkensim.sensors.ranging.readings_along_poses`): sample k is step k of environment 0 of the run
    ``seed``, so on a simulated flight's own true poses it reproduces that flight's readings. ``ranging.latency``
    shows the reading of that many samples earlier, as in the engine (the log's sample period is the step).

    Parameters
    ----------
    log : FlightLog
        The recorded flight: ``t``, ``arena``, ``pose``, ``copter_ids`` and the optional heights ``z`` are used; its
        own readings are not read.
    cfg : Config, str, Path, Mapping or None
        The scenario whose ``[ranging]`` section is flown (a Config, TOML path or text, dict; None = the default
        scenario); ``ranging.enabled`` must be true and ``ranging.beacons`` empty (fixed nodes are copters of the
        log).
    seed : int, optional
        The run seed of the readings' random numbers (default ``simulation.seed``).

    Returns
    -------
    FlightLog
        ``t``, ``arena``, ``pose``, ``copter_ids`` and ``z`` of ``log``; ``ranging`` (T, N, N) m simulated at every
        sample (NaN only for a reading lost to ``ranging.dropout_*``); meta ``source``, ``seed``, ``config`` and
        the log's ``copter_radius``.

    Raises
    ------
    ConfigError
        Ranging disabled, beacons configured, or a latency on a log whose samples are not evenly spaced.
    """
    from .sensors.latency import delayed_steps, lag_steps
    from .sensors.ranging import RangingModel, readings_along_poses

    cfg = load_scenario(cfg)
    rc = cfg.ranging
    if not rc.enabled:
        raise ConfigError("ranging.enabled = false: fly_recorded_poses flies the ranging sensor; expected true")
    if len(rc.beacons):
        raise ConfigError(f"ranging.beacons = {list(rc.beacons)!r}: expected none when flying recorded poses "
                          "(a fixed node is a copter of the log, tracked at its place)")
    seed = cfg.simulation.seed if seed is None else int(seed)
    t = np.asarray(log.t, dtype=np.float64)
    z = heights(log)
    readings = readings_along_poses(log.pose, RangingModel.from_config(rc), z=z, seed=seed)
    if rc.latency > 0.0 and t.size > 1:
        dt = np.diff(t)
        if dt.max() - dt.min() > 1e-6 * dt.mean():
            raise ConfigError(f"ranging.latency = {rc.latency!r} s: expected 0 for a log whose samples are not evenly "
                              f"spaced (intervals {dt.min():g}..{dt.max():g} s); the latency counts samples")
        readings = readings[delayed_steps(np.arange(t.size), lag_steps(rc.latency, float(dt.mean())), t.size)]
    extras = {} if z is None else {HEIGHTS: z.copy()}
    meta = {"source": f"finkensim {__version__}: ranging flown along the poses of {log.meta.get('source', 'a log')}",
            "seed": seed, "config": json.loads(json.dumps(cfg.to_dict()))}
    if "copter_radius" in log.meta:
        meta["copter_radius"] = log.meta["copter_radius"]
    out = FlightLog(t=t.copy(), arena=np.asarray(log.arena, dtype=np.float64).copy(),
                    pose=np.asarray(log.pose, dtype=np.float64).copy(), copter_ids=np.asarray(log.copter_ids).copy(),
                    ranging=readings, meta=meta, extras=extras)
    validate(out)
    return out
