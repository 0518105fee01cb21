"""One simulated flight, end to end: scenario config → compiled rollout → flight log.

    from finkensim.scenario import load_scenario, simulate_flight
    cfg = load_scenario()                        # the embedded default: 6 copters, random walk, 60 s
    log, traj, world = simulate_flight(cfg, duration=10.0, seed=3)
    flightlog.save(log, "flight.npz")

:func:`simulate_flight` runs exactly one environment (B = 1) of the configured behaviour with
:meth:`World.rollout <finkensim.world.World.rollout>` (compiled, no per-step Python) and turns
the recorded trajectory into a :class:`~finkensim.flightlog.FlightLog`. Sensor readings are
added in one place, :func:`_sensor_blocks`, so each sensor model plugs in without touching
the rest of the pipeline.
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


def _sensor_blocks(world: World, traj: Trajectory, state0: WorldState) -> dict[str, Any]:
    """Sensor readings of one simulated flight, as keyword arguments of :class:`FlightLog`.

    The one place where sensor models join the flight log. ``traj`` holds the recorded states of
    the single environment (``traj.pose`` (T, 1, N, 3), ``vel``/``acc`` (T, 1, N, 2), ``yaw_rate``
    (T, 1, N), ``theta`` (T, 1, S): everything a sonar, ranging or IMU model needs); ``state0`` is
    the initial state, whose ``seed`` and ``env_ids`` key the sensors' random streams.

    Return any of ``ultrasonic``, ``ultrasonic_yaw``, ``ultrasonic_offset``, ``ranging``,
    ``imu_acc``, ``imu_gyro`` (each block all-or-nothing, see ``spec/flightlog.md``), plus
    optionally ``meta`` and ``extras`` dicts, which are merged into the log's own.
    Sensors are not modelled yet (sensor-model issue): no blocks.
    """
    return {}


def _n_steps(duration: float, dt: float) -> int:
    n = int(round(duration / dt))
    if n < 1:
        raise ConfigError(f"simulation.duration = {duration!r}: expected at least one step of simulation.dt = {dt!r} s")
    return n


def simulate_flight(cfg: Config | str | Path | Mapping[str, Any] | None = None, *, duration: float | None = None,
                    seed: int | None = None) -> tuple[FlightLog, Trajectory, World]:
    """Simulate one flight of the configured behaviour and build its flight log.

    Args:
        cfg: a Config, a TOML path or text, a dict, or None for the embedded default scenario.
        duration: flight length in s (default ``simulation.duration``).
        seed: random seed (default ``simulation.seed``).

    One environment (B = 1, environment index 0) is placed at random and flown for
    round(duration / dt) steps by ``behaviour.kind`` in compiled code. The log has
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

    world = World(cfg)
    state0 = world.init(n_envs=1, seed=sim.seed)
    # n_steps + 1 steps record the states at t = 0 .. duration inclusive
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

    blocks = dict(_sensor_blocks(world, traj, state0))
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
