"""The closed swarm loop: sense → behave → step, compiled, for B environments at once.

    from finkensim.swarm import SwarmSim
    sim = SwarmSim(cfg)                                   # behaviour.kind from the config
    state = sim.init(n_envs=1024, seed=1)                 # world + IMU bias + behaviour memory
    final, rec = sim.rollout(state, n_steps=200, record=("pose", "wall"))
    rec.pose            # (T, B, N, 3) state before each step
    rec.counters        # per-episode counters (B, N): collisions, wall_contacts, wall_onsets, wall_readings

Each step k (the state after k steps, ``WorldState.step``), for every environment:

1. **sense** — horizontal sonars (:func:`~finkensim.sensors.ultrasonic.ultrasonic_env` on the plates
   displaced by their current angles), the down sonar, virtual ranging to every other copter and beacon,
   and the IMU (reading the acceleration of the step that ended at k; its bias state advances). Every
   sensor uses exactly the random numbers of its batched function at step k (same keys, same indices),
   and only runs when its ``enabled`` key is true;
2. **behave** — IMU dead reckoning, the wall plausibility check (``behaviour.wall_check``), then the
   controller: ``attraction_repulsion`` (body-frame command from the sonar readings, rotated to the
   world frame by the flight controller), ``random_walk`` (the open-loop bounded walk of
   :mod:`finkensim.behaviours.random_walk`, identical to ``World.rollout``) or ``hover``;
3. **step** — :func:`~finkensim.world.step_env` (copters, contacts, Bernoulli plates).

:meth:`SwarmSim.rollout` runs T steps of B environments in ONE numba kernel (``prange`` over B, the T
loop inside, buffers allocated once per environment, no Python per step). The loop body calls
non-inlined twins of the per-environment kernels (the same Python functions compiled as functions):
identical results, and a cold compilation of ≈ 20 s instead of about a minute with everything inlined.
:meth:`SwarmSim.step` is the same step through the batched Python-facing functions
(``ultrasonic_readings``, ``down_readings``, ``ranging_readings``, ``imu_step``,
:func:`~finkensim.behaviours.wall_check.wall_check`, :func:`~finkensim.behaviours.attraction.attraction_repulsion`,
``World.step``); both give identical results bit for bit (tested; ``rollout(..., python=True)`` runs the
per-step path), and a result depends only on (seed, environment index, step, copter).

**Your own behaviour.** Pass a Python function ``f(readings, memory, params) -> (cmd_vel, cmd_yaw_rate)``
as ``SwarmSim(cfg, behaviour=f)``. It sees only the copters' own sensors, a :class:`SensorReadings`
(sonar (B, N, 4) m, sonar_down (B, N) m, ranging (B, N, N + M) m, imu_acc (B, N, 2) m/s² body frame,
imu_gyro (B, N) rad/s, wall (B, N, 4) bool from the configured wall check, plus step, dt, seed and
env_ids for reproducible randomness; a disabled sensor is None). ``memory`` is the object in
``state.memory`` (from ``memory=`` of :meth:`SwarmSim.init`, or the ``memory_factory(B, N)`` given to
the constructor, else a new empty dict) — mutate it in place to remember things across steps.
``params`` is ``SwarmSim(..., params=...)`` (default: ``cfg.behaviour``). Return the velocity
command (B, N, 2) m/s — body frame (x forward, y left) by default, or world frame with
``command_frame="world"`` — and the yaw-rate command (B, N) rad/s (or None for 0). Such a behaviour
runs through the per-step Python path (``rollout`` loops over :meth:`SwarmSim.step`). Example — fly
toward the farthest echo, stop when something is closer than 0.5 m::

    import numpy as np
    from finkensim.swarm import SwarmSim

    def explorer(readings, memory, params):
        r = readings.sonar                                  # (B, N, 4): front, left, back, right
        heading = np.radians([0.0, 90.0, 180.0, -90.0])[r.argmax(-1)]
        speed = np.where(r.min(-1) < 0.5, 0.0, 0.3)
        v = speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], -1)
        memory["steps"] = memory.get("steps", 0) + 1
        return v, None                                      # body frame, no turning

    sim = SwarmSim(cfg, behaviour=explorer)
    final, rec = sim.rollout(sim.init(n_envs=4, seed=0), 100)

The :class:`SwarmState` carries the world state, the IMU bias (B, N, 3) and the behaviour memory
(:class:`~finkensim.behaviours.wall_check.BehaviourState`: fail counters, wall flags, dead reckoning).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable, NamedTuple

import numpy as np
from numba import njit, prange

from .behaviours.attraction import AttractionParams, attraction_env, attraction_repulsion, body_to_world, \
    body_to_world_env
from .behaviours.random_walk import random_walk_env
from .behaviours.wall_check import WALL_CHECK_NONE, WALL_CHECK_SEQUENCE, BehaviourState, WallCheckParams, \
    dead_reckon, dead_reckon_env, wall_check, wall_check_env
from .config import Config, ConfigError, load_config
from .kernels.rng import STREAM_RANGING, counter_key
from .sensors.imu import ImuModel, imu_env, imu_step
from .sensors.ranging import MODE_SEED, RangingModel, _fast_reading, _seed_reading, ranging_readings
from .sensors.ultrasonic import N_SONARS, SonarModel, displaced_plates_env, down_env, down_readings, \
    ultrasonic_env, ultrasonic_readings
from .world import World, WorldState, step_env

__all__ = ["SwarmSim", "SwarmState", "SwarmRecord", "SensorReadings", "RECORDABLE", "ranging_env",
           "KIND_HOVER", "KIND_RANDOM_WALK", "KIND_ATTRACTION", "KIND_PYTHON"]

KIND_HOVER = 0
KIND_RANDOM_WALK = 1
KIND_ATTRACTION = 2
KIND_PYTHON = 3
KIND_CODES = {"hover": KIND_HOVER, "random_walk": KIND_RANDOM_WALK, "attraction_repulsion": KIND_ATTRACTION}

#: Arrays :meth:`SwarmSim.rollout` can record per step, with their shapes (T = steps, S = plates,
#: M = beacons). Sensor arrays exist only when their sensor is enabled.
RECORDABLE = {
    "pose": "(T, B, N, 3) x m, y m, yaw rad — the state before each step",
    "vel": "(T, B, N, 2) m/s world frame",
    "theta": "(T, B, S) rad plate angles",
    "sonar": "(T, B, N, 4) m horizontal sonar readings (front, left, back, right)",
    "sonar_down": "(T, B, N) m down-sonar readings",
    "ranging": "(T, B, N, N + M) m virtual-ranging readings",
    "imu_acc": "(T, B, N, 2) m/s² accelerometer, body frame",
    "imu_gyro": "(T, B, N) rad/s gyro",
    "wall": "(T, B, N, 4) bool readings judged to be walls",
    "cmd_vel": "(T, B, N, 2) m/s world-frame velocity command",
    "cmd_yaw_rate": "(T, B, N) rad/s yaw-rate command",
}
_SENSOR_OF = {"sonar": "sonar", "sonar_down": "down", "ranging": "ranging", "imu_acc": "imu", "imu_gyro": "imu"}


class SensorReadings(NamedTuple):
    """What the copters sense at one step (B environments). Disabled sensors are None.

    sonar (B, N, 4) m; sonar_down (B, N) m; ranging (B, N, N + M) m (row i = measuring copter, columns
    copters then beacons); imu_acc (B, N, 2) m/s² body frame; imu_gyro (B, N) rad/s; wall (B, N, 4) bool
    (the configured wall check; all False for ``wall_check = "none"``); step, dt s, seed, env_ids (B,).
    """

    sonar: np.ndarray | None
    sonar_down: np.ndarray | None
    ranging: np.ndarray | None
    imu_acc: np.ndarray | None
    imu_gyro: np.ndarray | None
    wall: np.ndarray
    step: int
    dt: float
    seed: int
    env_ids: np.ndarray


@dataclass(frozen=True)
class SwarmState:
    """World state plus everything the sensors and behaviours remember. ``memory``: a user behaviour's object."""

    world: WorldState
    imu_bias: np.ndarray
    behaviour: BehaviourState
    memory: Any = None

    @property
    def step(self) -> int:
        return self.world.step

    @property
    def n_envs(self) -> int:
        return self.world.n_envs

    @property
    def n_copters(self) -> int:
        return self.world.n_copters

    def copy(self) -> "SwarmState":
        """Copies of every array (``memory`` is shared, not copied)."""
        return replace(self, world=self.world.copy(), imu_bias=self.imu_bias.copy(), behaviour=self.behaviour.copy())

    def select(self, envs) -> "SwarmState":
        """The sub-batch ``envs`` as an independent state (``memory`` is shared)."""
        return replace(self, world=self.world.select(envs), imu_bias=np.ascontiguousarray(self.imu_bias[envs]),
                       behaviour=self.behaviour.select(envs))


@dataclass(frozen=True)
class SwarmRecord:
    """What :meth:`SwarmSim.rollout` recorded: per-step arrays (see :data:`RECORDABLE`; None when not
    recorded), ``t`` (T,) s, and ``counters``: per-episode (B, N) int64 counts over the rollout —
    ``collisions`` and ``wall_contacts`` (contact onsets), ``wall_onsets`` (wall flags set) and
    ``wall_readings`` (echoes judged to be walls)."""

    t: np.ndarray
    counters: dict
    pose: np.ndarray | None = None
    vel: np.ndarray | None = None
    theta: np.ndarray | None = None
    sonar: np.ndarray | None = None
    sonar_down: np.ndarray | None = None
    ranging: np.ndarray | None = None
    imu_acc: np.ndarray | None = None
    imu_gyro: np.ndarray | None = None
    wall: np.ndarray | None = None
    cmd_vel: np.ndarray | None = None
    cmd_yaw_rate: np.ndarray | None = None


# ---------------------------------------------------------------------------------------------
# kernels


@njit(cache=True, inline="always")
def ranging_env(pos_b, beacons, seed, env, step, p, out):
    """Virtual-ranging readings of one environment → out (N, N + M) m.

    The loop body of ``finkensim.sensors.ranging._readings_kernel`` (mode ``ideal=False``) for one
    environment, built from the same helpers (``_fast_reading``, ``_seed_reading``) and the same keys,
    so the values are identical to :func:`~finkensim.sensors.ranging.ranging_readings`. ``p`` is
    ``RangingModel.params``.
    """
    n = pos_b.shape[0]
    m = beacons.shape[0]
    mode, max_range, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std, log_wn, half_inv_covar, seed_std = p
    for i in range(n):
        key = counter_key(seed, env, step, i, STREAM_RANGING)
        xi = pos_b[i, 0]
        yi = pos_b[i, 1]
        for j in range(n + m):
            if j == i:
                out[i, j] = 0.0
                continue
            if j < n:
                dx = pos_b[j, 0] - xi
                dy = pos_b[j, 1] - yi
            else:
                dx = beacons[j - n, 0] - xi
                dy = beacons[j - n, 1] - yi
            x = np.sqrt(dx * dx + dy * dy)
            if x > max_range:
                y = max_range
            elif mode == MODE_SEED:
                y = _seed_reading(x, key, j, mean, cond_mean, log_wn, half_inv_covar, seed_std)
            else:
                y = _fast_reading(x, key, j, mode, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std)
            out[i, j] = y if y > 0.0 else 0.0


@njit(cache=True, parallel=True)
def _ranging_batch(pos, beacons, seed, env_ids, step, p, out):
    for b in prange(pos.shape[0]):
        ranging_env(pos[b], beacons, seed, env_ids[b], step, p, out[b])


@njit(cache=True, parallel=True)
def _random_walk_batch(pos, seed, env_ids, step, rw, cmd_v, cmd_w):
    for b in prange(pos.shape[0]):
        random_walk_env(pos[b], seed, env_ids[b], step, rw, cmd_v[b], cmd_w[b])


def _twin(kernel):
    """A non-inlined twin of an ``inline="always"`` per-environment kernel: the same Python function compiled
    once as a function. Identical results; the rollout kernel that calls twins compiles in a fraction of the
    time it takes with everything inlined (numba's IR inlining and type inference grow steeply with size)."""
    return njit(cache=True)(kernel.py_func)


_plates_fn = _twin(displaced_plates_env)
_sonar_fn = _twin(ultrasonic_env)
_down_fn = _twin(down_env)
_ranging_fn = _twin(ranging_env)
_imu_fn = _twin(imu_env)
_dead_reckon_fn = _twin(dead_reckon_env)
_wall_check_fn = _twin(wall_check_env)
_attraction_fn = _twin(attraction_env)
_body_to_world_fn = _twin(body_to_world_env)
_random_walk_fn = _twin(random_walk_env)
_step_fn = _twin(step_env)


@njit(cache=True)
def _swarm_env(b, pos, vel, acc, yaw, yaw_rate, theta, omega, integ, in_wall, in_collision, wall_contacts,
               collisions, bias, fail_count, wall, anchor, dr_pos, dr_vel, dr_yaw, wall_onsets, wall_readings,
               seed, env_ids, step0, n_steps, kind, on,
               cp, hp, seg_a, seg_b, plate_a, plate_b, normal, lever, width, length, dt,
               sp, rp, beacons, ip, rw, ap, wp,
               rec_pose, rec_vel, rec_theta, rec_sonar, rec_down, rec_ranging, rec_acc, rec_gyro, rec_wall,
               rec_cmd_v, rec_cmd_w):
    """T steps of the closed loop for environment b, in place: the body of :func:`_swarm_rollout`'s
    ``prange`` loop, as a plain function calling the per-environment kernels' twins (fast to compile)."""
    B, N, _ = pos.shape
    S = plate_a.shape[0]
    R = N + beacons.shape[0]
    do_sonar, do_down, do_ranging, do_imu = on
    env = env_ids[b]
    # work buffers, once per environment
    pa = np.empty((S, 2))
    pb = np.empty((S, 2))
    sonar_buf = np.empty((N, N_SONARS, 4))
    dist = np.empty((N, N_SONARS))
    hit_kind = np.empty((N, N_SONARS), dtype=np.int64)
    hit = np.empty((N, N_SONARS, 2))
    slot = np.zeros(N, dtype=np.int64)
    son = np.full((N, N_SONARS), sp.max_range)
    alt = np.full(N, sp.altitude)
    down = np.empty(N)
    rng = np.zeros((N, R))
    imu_a = np.zeros((N, 2))
    imu_g = np.zeros(N)
    fail_buf = np.zeros((N, N_SONARS), dtype=np.bool_)
    cmd_body = np.zeros((N, 2))
    cmd_v = np.zeros((N, 2))
    cmd_w = np.zeros(N)
    dist_buf = np.empty(seg_a.shape[0])
    gap_buf = np.empty(N)
    for t in range(n_steps):
        k = step0 + t
        # explicit loops: slice assignments would pull in numba's broadcast-error machinery (slow to compile)
        if rec_pose.shape[0] > 0:
            for n in range(N):
                rec_pose[t, b, n, 0] = pos[b, n, 0]
                rec_pose[t, b, n, 1] = pos[b, n, 1]
                rec_pose[t, b, n, 2] = yaw[b, n]
        if rec_vel.shape[0] > 0:
            for n in range(N):
                rec_vel[t, b, n, 0] = vel[b, n, 0]
                rec_vel[t, b, n, 1] = vel[b, n, 1]
        if rec_theta.shape[0] > 0:
            for s in range(S):
                rec_theta[t, b, s] = theta[b, s]
        # 1. sense
        if do_sonar:
            _plates_fn(theta[b], plate_a, plate_b, normal, lever, pa, pb)
            _sonar_fn(pos[b], yaw[b], pa, pb, width, length, sp, seed, env, k, sonar_buf, dist, hit_kind,
                           hit, slot, son)
        if do_down:
            _down_fn(alt, sp, seed, env, k, down)
        if do_ranging:
            _ranging_fn(pos[b], beacons, seed, env, k, rp, rng)
        if do_imu:
            _imu_fn(acc[b], yaw[b], yaw_rate[b], bias[b], ip, seed, env, k, imu_a, imu_g)
            _dead_reckon_fn(imu_a, imu_g, wp.dt, dr_pos[b], dr_vel[b], dr_yaw[b])
        # 2. behave
        if do_sonar:
            _wall_check_fn(son, rng, wp, fail_buf, fail_count[b], wall[b], anchor[b], dr_pos[b], dr_yaw[b],
                           wall_onsets[b], wall_readings[b])
        if kind == KIND_ATTRACTION:
            _attraction_fn(son, wall[b], seed, env, k, ap, cmd_body, cmd_w)
            _body_to_world_fn(yaw[b], cmd_body, cmd_v)
        elif kind == KIND_RANDOM_WALK:
            _random_walk_fn(pos[b], seed, env, k, rw, cmd_v, cmd_w)
        for n in range(N):
            if rec_sonar.shape[0] > 0:
                for j in range(N_SONARS):
                    rec_sonar[t, b, n, j] = son[n, j]
            if rec_wall.shape[0] > 0:
                for j in range(N_SONARS):
                    rec_wall[t, b, n, j] = wall[b, n, j]
            if rec_down.shape[0] > 0:
                rec_down[t, b, n] = down[n]
            if rec_ranging.shape[0] > 0:
                for j in range(R):
                    rec_ranging[t, b, n, j] = rng[n, j]
            if rec_acc.shape[0] > 0:
                rec_acc[t, b, n, 0] = imu_a[n, 0]
                rec_acc[t, b, n, 1] = imu_a[n, 1]
            if rec_gyro.shape[0] > 0:
                rec_gyro[t, b, n] = imu_g[n]
            if rec_cmd_v.shape[0] > 0:
                rec_cmd_v[t, b, n, 0] = cmd_v[n, 0]
                rec_cmd_v[t, b, n, 1] = cmd_v[n, 1]
            if rec_cmd_w.shape[0] > 0:
                rec_cmd_w[t, b, n] = cmd_w[n]
        # 3. step
        _step_fn(pos[b], vel[b], acc[b], yaw[b], yaw_rate[b], theta[b], omega[b], integ[b], in_wall[b],
                 in_collision[b], wall_contacts[b], collisions[b], cmd_v, cmd_w, cp, hp, seg_a, seg_b,
                 lever, dt, dist_buf, gap_buf)


@njit(cache=True, parallel=True)
def _swarm_rollout(pos, vel, acc, yaw, yaw_rate, theta, omega, integ, in_wall, in_collision, wall_contacts,
                   collisions, bias, fail_count, wall, anchor, dr_pos, dr_vel, dr_yaw, wall_onsets, wall_readings,
                   seed, env_ids, step0, n_steps, kind, on,
                   cp, hp, seg_a, seg_b, plate_a, plate_b, normal, lever, width, length, dt,
                   sp, rp, beacons, ip, rw, ap, wp,
                   rec_pose, rec_vel, rec_theta, rec_sonar, rec_down, rec_ranging, rec_acc, rec_gyro, rec_wall,
                   rec_cmd_v, rec_cmd_w):
    """T steps of the closed loop for B environments, in place: ``prange`` over B, the T loop inside
    (:func:`_swarm_env`). ``on`` = (sonar, down, ranging, imu) enabled flags; rec_* are recorded when
    their leading dimension is n_steps (else 0)."""
    for b in prange(pos.shape[0]):
        # np.int64: the prange index is typed uint64 in one numba pass and int64 in another (two compilations)
        _swarm_env(np.int64(b), pos, vel, acc, yaw, yaw_rate, theta, omega, integ, in_wall, in_collision, wall_contacts,
                   collisions, bias, fail_count, wall, anchor, dr_pos, dr_vel, dr_yaw, wall_onsets, wall_readings,
                   seed, env_ids, step0, n_steps, kind, on, cp, hp, seg_a, seg_b, plate_a, plate_b, normal, lever,
                   width, length, dt, sp, rp, beacons, ip, rw, ap, wp, rec_pose, rec_vel, rec_theta, rec_sonar,
                   rec_down, rec_ranging, rec_acc, rec_gyro, rec_wall, rec_cmd_v, rec_cmd_w)


# ---------------------------------------------------------------------------------------------
# Python API


class SwarmSim:
    """A configured swarm: world, sensor models and behaviour, with compiled and per-step stepping.

    Args:
        cfg: a :class:`~finkensim.config.Config`, a TOML path/string, a dict, or None for defaults.
        behaviour: None (``behaviour.kind`` from the config), one of ``"hover"``, ``"random_walk"``,
            ``"attraction_repulsion"``, or a Python function ``f(readings, memory, params)`` (module doc).
        params: the ``params`` passed to a Python behaviour (default ``cfg.behaviour``).
        command_frame: ``"body"`` (default) or ``"world"``: the frame of a Python behaviour's velocity.
        memory_factory: ``(n_envs, n_copters) -> object``, a Python behaviour's initial memory.

    Attributes: ``world`` (:class:`~finkensim.world.World`), ``sonar`` (SonarModel), ``ranging``
    (RangingModel), ``imu`` (ImuModel), ``attraction`` (AttractionParams), ``wall_check``
    (WallCheckParams), ``beacons`` (M, 2) m, ``kind`` (str or the function).
    """

    def __init__(self, cfg: Config | str | dict | None = None, behaviour: str | Callable | None = None,
                 params: Any = None, command_frame: str = "body", memory_factory: Callable | None = None):
        self.cfg = cfg if isinstance(cfg, Config) else load_config(cfg)
        c = self.cfg
        self.world = World(c)
        self.dt = self.world.dt
        self.sonar = SonarModel.from_config(c)
        self.ranging = RangingModel.from_config(c.ranging)
        self.imu = ImuModel.from_config(c.imu, self.dt)
        self.attraction = AttractionParams.from_config(c)
        self.wall_check = WallCheckParams.from_config(c)
        self.beacons = np.ascontiguousarray(np.asarray(c.ranging.beacons, dtype=np.float64).reshape(-1, 2))
        kind = c.behaviour.kind if behaviour is None else behaviour
        if callable(kind):
            self.kind_code = KIND_PYTHON
        elif kind in KIND_CODES:
            self.kind_code = KIND_CODES[kind]
        else:
            raise ConfigError(f"behaviour = {kind!r}: expected one of {', '.join(map(repr, KIND_CODES))} "
                              "or a function f(readings, memory, params)")
        self.kind = kind
        if command_frame not in ("body", "world"):
            raise ConfigError(f"command_frame = {command_frame!r}: expected 'body' or 'world'")
        self.command_frame = command_frame
        self.params = c.behaviour if params is None else params
        self.memory_factory = memory_factory
        self.enabled = {"sonar": bool(c.sonar.enabled), "down": bool(c.sonar.enabled and c.sonar.down_enabled),
                        "ranging": bool(c.ranging.enabled), "imu": bool(c.imu.enabled)}
        if self.kind_code == KIND_ATTRACTION and not self.enabled["sonar"]:
            raise ConfigError("behaviour.kind = 'attraction_repulsion' needs sonar.enabled = true")
        if self.wall_check.mode != WALL_CHECK_NONE:
            need = [("sonar.enabled", self.enabled["sonar"]), ("ranging.enabled", self.enabled["ranging"])]
            if self.wall_check.mode == WALL_CHECK_SEQUENCE:
                need.append(("imu.enabled", self.enabled["imu"]))
            for key, ok in need:
                if not ok:
                    raise ConfigError(f"behaviour.wall_check = {c.behaviour.wall_check!r} needs {key} = true")

    @property
    def n_copters(self) -> int:
        return self.cfg.copters.n

    def recordable(self) -> tuple[str, ...]:
        """Names :meth:`rollout` can record with this config (see :data:`RECORDABLE`)."""
        return tuple(name for name in RECORDABLE if name not in _SENSOR_OF or self.enabled[_SENSOR_OF[name]])

    def init(self, n_envs: int | None = None, seed: int | None = None, env_ids=None, positions=None, yaw=None,
             memory: Any = None) -> SwarmState:
        """Initial state: :meth:`World.init <finkensim.world.World.init>` (same arguments), zero IMU bias,
        empty behaviour memory (dead reckoning at 0, no flags), and a Python behaviour's ``memory``."""
        ws = self.world.init(n_envs=n_envs, seed=seed, env_ids=env_ids, positions=positions, yaw=yaw)
        B, N = ws.n_envs, ws.n_copters
        if memory is None:
            memory = self.memory_factory(B, N) if self.memory_factory is not None else {}
        return SwarmState(world=ws, imu_bias=np.zeros((B, N, 3)), behaviour=BehaviourState.zeros(B, N, N_SONARS),
                          memory=memory)

    # -- one step through the batched functions (the reference path; also runs Python behaviours) --

    def sense(self, state: SwarmState) -> tuple[SensorReadings, np.ndarray, BehaviourState]:
        """Sensor readings of ``state`` (its step), plus the advanced IMU bias and behaviour memory
        (new arrays; ``state`` is unchanged)."""
        ws = state.world
        k, seed, env_ids = ws.step, ws.seed, ws.env_ids
        B, N = ws.n_envs, ws.n_copters
        on = self.enabled
        sonar = ultrasonic_readings(ws.pos, ws.yaw, ws.theta, self.world.arena, self.sonar, seed, env_ids, k) \
            if on["sonar"] else None
        down = down_readings(ws.pos, self.sonar, seed, env_ids, k) if on["down"] else None
        rng = ranging_readings(ws.pos, self.beacons, seed, env_ids, k, self.ranging) if on["ranging"] else None
        bias = state.imu_bias.copy()
        mem = state.behaviour.copy()
        imu_acc = imu_gyro = None
        if on["imu"]:
            imu_acc, imu_gyro = imu_step(ws.acc, ws.yaw, ws.yaw_rate, bias, self.imu, seed, env_ids, k)
            dead_reckon(imu_acc, imu_gyro, mem, self.wall_check)
        if on["sonar"]:
            rng_in = rng if rng is not None else np.zeros((B, N, N + self.beacons.shape[0]))
            wall = wall_check(sonar, rng_in, self.wall_check, mem)
        else:
            wall = mem.wall.copy()
        readings = SensorReadings(sonar=sonar, sonar_down=down, ranging=rng, imu_acc=imu_acc, imu_gyro=imu_gyro,
                                  wall=wall, step=k, dt=self.dt, seed=seed, env_ids=env_ids.copy())
        return readings, bias, mem

    def commands(self, state: SwarmState, readings: SensorReadings) -> tuple[np.ndarray, np.ndarray]:
        """World-frame commands (cmd_vel (B, N, 2) m/s, cmd_yaw_rate (B, N) rad/s) of the behaviour."""
        ws = state.world
        B, N = ws.n_envs, ws.n_copters
        if self.kind_code == KIND_ATTRACTION:
            v_body, w = attraction_repulsion(readings.sonar, ws.seed, ws.env_ids, ws.step, self.attraction,
                                             readings.wall)
            return body_to_world(ws.yaw, v_body), w
        if self.kind_code == KIND_RANDOM_WALK:
            v = np.zeros((B, N, 2))
            w = np.zeros((B, N))
            _random_walk_batch(np.ascontiguousarray(ws.pos), int(ws.seed), ws.env_ids, int(ws.step),
                               self.world.random_walk_params, v, w)
            return v, w
        if self.kind_code == KIND_HOVER:
            return np.zeros((B, N, 2)), np.zeros((B, N))
        out = self.kind(readings, state.memory, self.params)
        if not isinstance(out, tuple) or len(out) != 2:
            raise ConfigError(f"behaviour {getattr(self.kind, '__name__', self.kind)!r} returned "
                              f"{type(out).__name__}: expected a tuple (cmd_vel (B, N, 2) m/s, cmd_yaw_rate (B, N) "
                              "rad/s or None)")
        v, w = out
        v, w = self.world._check_commands(ws, v, w)
        if self.command_frame == "body":
            v = body_to_world(ws.yaw, v)
        return v, w

    def step(self, state: SwarmState) -> tuple[SwarmState, SensorReadings, tuple[np.ndarray, np.ndarray]]:
        """One closed-loop step through the batched functions: (new state, readings, (cmd_vel, cmd_yaw_rate)).

        Pure for the arrays (``state`` is left unchanged); a Python behaviour may mutate ``state.memory``,
        which the new state shares.
        """
        readings, bias, mem = self.sense(state)
        cmd_v, cmd_w = self.commands(state, readings)
        ws = self.world.step(state.world, cmd_v, cmd_w)
        return SwarmState(world=ws, imu_bias=bias, behaviour=mem, memory=state.memory), readings, (cmd_v, cmd_w)

    # -- many steps --

    def _record_names(self, record) -> tuple[str, ...]:
        avail = self.recordable()
        if record is True:
            return avail
        if record is False or record is None:
            return ()
        names = (record,) if isinstance(record, str) else tuple(record)
        for name in names:
            if name not in RECORDABLE:
                raise ConfigError(f"record: unknown name {name!r}; expected True, False or names from "
                                  f"{', '.join(RECORDABLE)}")
            if name not in avail:
                raise ConfigError(f"record: {name!r} is not available because its sensor is disabled "
                                  f"({_SENSOR_OF[name]})")
        return names

    def rollout(self, state: SwarmState, n_steps: int, record: bool | str | Iterable[str] = True,
                python: bool = False) -> tuple[SwarmState, SwarmRecord]:
        """Run ``n_steps`` closed-loop steps; returns (final state, :class:`SwarmRecord`). ``state`` is unchanged.

        ``record``: True (everything available), False (only the per-episode counters), or names from
        :data:`RECORDABLE`. Built-in behaviours run in one compiled kernel; a Python behaviour (or
        ``python=True``) loops over :meth:`step`.
        """
        if not isinstance(n_steps, (int, np.integer)) or isinstance(n_steps, bool) or n_steps < 0:
            raise ConfigError(f"n_steps = {n_steps!r}: expected a non-negative integer")
        names = self._record_names(record)
        T = int(n_steps)
        ws0 = state.world
        B, N, S, R = ws0.n_envs, ws0.n_copters, self.world.arena.n_plates, ws0.n_copters + self.beacons.shape[0]
        shapes = {"pose": (B, N, 3), "vel": (B, N, 2), "theta": (B, S), "sonar": (B, N, N_SONARS),
                  "sonar_down": (B, N), "ranging": (B, N, R), "imu_acc": (B, N, 2), "imu_gyro": (B, N),
                  "wall": (B, N, N_SONARS), "cmd_vel": (B, N, 2), "cmd_yaw_rate": (B, N)}
        rec = {name: np.zeros(((T if name in names else 0),) + shapes[name],
                              dtype=np.bool_ if name == "wall" else np.float64) for name in RECORDABLE}
        if self.kind_code == KIND_PYTHON or python:
            new = state
            for t in range(T):
                if "pose" in names:
                    rec["pose"][t] = new.world.pose
                if "vel" in names:
                    rec["vel"][t] = new.world.vel
                if "theta" in names:
                    rec["theta"][t] = new.world.theta
                new, readings, (cmd_v, cmd_w) = self.step(new)
                for name, value in (("sonar", readings.sonar), ("sonar_down", readings.sonar_down),
                                    ("ranging", readings.ranging), ("imu_acc", readings.imu_acc),
                                    ("imu_gyro", readings.imu_gyro), ("wall", readings.wall),
                                    ("cmd_vel", cmd_v), ("cmd_yaw_rate", cmd_w)):
                    if name in names:
                        rec[name][t] = value
            if T == 0:
                new = state.copy()
        else:
            new = state.copy()
            w, m = new.world, new.behaviour
            ar = self.world.arena
            on = (self.enabled["sonar"], self.enabled["down"], self.enabled["ranging"], self.enabled["imu"])
            _swarm_rollout(w.pos, w.vel, w.acc, w.yaw, w.yaw_rate, w.theta, w.omega, w.integ, w.in_wall,
                           w.in_collision, w.wall_contacts, w.collisions, new.imu_bias, m.fail_count, m.wall,
                           m.anchor, m.dr_pos, m.dr_vel, m.dr_yaw, m.wall_onsets, m.wall_readings,
                           int(w.seed), w.env_ids, int(w.step), T, self.kind_code, on,
                           self.world.copter_params, self.world.hinge_params, ar.seg_a, ar.seg_b, ar.plate_a,
                           ar.plate_b, ar.normal, float(ar.lever), float(ar.width), float(ar.length), self.dt,
                           self.sonar, self.ranging.params, self.beacons, self.imu, self.world.random_walk_params,
                           self.attraction, self.wall_check,
                           rec["pose"], rec["vel"], rec["theta"], rec["sonar"], rec["sonar_down"], rec["ranging"],
                           rec["imu_acc"], rec["imu_gyro"], rec["wall"], rec["cmd_vel"], rec["cmd_yaw_rate"])
            new = replace(new, world=replace(new.world, step=w.step + T))
        counters = {
            "collisions": new.world.collisions - ws0.collisions,
            "wall_contacts": new.world.wall_contacts - ws0.wall_contacts,
            "wall_onsets": new.behaviour.wall_onsets - state.behaviour.wall_onsets,
            "wall_readings": new.behaviour.wall_readings - state.behaviour.wall_readings,
        }
        out = {name: rec[name] for name in names}
        return new, SwarmRecord(t=(ws0.step + np.arange(T)) * self.dt, counters=counters, **out)
