"""The swarm's data: behaviour codes, what a rollout can record, the state and record classes, and the
flat NamedTuple records the compiled loop (:mod:`finkensim.swarm.kernel`) takes.

Shapes: B environments, N copters, S plates, M beacons, T recorded steps; 4 horizontal sonars.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

import numpy as np

from ..behaviours.wall_check import BehaviourState
from ..world import WorldState

__all__ = ["KIND_HOVER", "KIND_RANDOM_WALK", "KIND_ATTRACTION", "KIND_PYTHON", "KIND_CODES", "RECORDABLE",
           "SENSOR_OF", "SensorReadings", "SwarmState", "SwarmRecord", "MemoryArrays", "RunSpec", "NO_RANGING_ROWS", "Recording"]

KIND_HOVER = 0
KIND_RANDOM_WALK = 1
KIND_ATTRACTION = 2
KIND_PYTHON = 3
#: ``behaviour.kind`` → code of the built-in behaviours compiled into the loop.
KIND_CODES = {"hover": KIND_HOVER, "random_walk": KIND_RANDOM_WALK, "attraction_repulsion": KIND_ATTRACTION}

#: Arrays :meth:`SwarmSim.rollout <finkensim.swarm.SwarmSim.rollout>` can record per step, with their
#: shapes. Sensor arrays exist only when their sensor is enabled.
RECORDABLE = {
    "pose": "(T, B, N, 3) x m, y m, yaw rad — the state before each step",
    "vel": "(T, B, N, 2) m/s world frame",
    "acc": "(T, B, N, 2) m/s² world frame, the acceleration of the step that ended there",
    "yaw_rate": "(T, B, N) rad/s",
    "theta": "(T, B, S) rad plate angles",
    "sonar": "(T, B, N, 4) m horizontal sonar readings (front, left, back, right)",
    "sonar_ideal": "(T, B, N, 4) m error-free sonar distances (max_range when no echo, not clamped to min_range)",
    "sonar_hit": "(T, B, N, 4) int64 what each sonar's nearest hit is: 0 none, 1 wall, 2 copter",
    "sonar_down": "(T, B, N) m down-sonar readings",
    "ranging": "(T, B, N, N + M) m virtual-ranging readings",
    "imu_acc": "(T, B, N, 2) m/s² accelerometer, body frame",
    "imu_gyro": "(T, B, N) rad/s gyro",
    "wall": "(T, B, N, 4) bool readings judged to be walls",
    "cmd_vel": "(T, B, N, 2) m/s world-frame velocity command",
    "cmd_yaw_rate": "(T, B, N) rad/s yaw-rate command",
}
#: Recordable name → the sensor (key of ``SwarmSim.enabled``) it needs.
SENSOR_OF = {"sonar": "sonar", "sonar_ideal": "sonar", "sonar_hit": "sonar", "sonar_down": "down",
             "ranging": "ranging", "imu_acc": "imu", "imu_gyro": "imu"}


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
    """World state plus everything the sensors and behaviours remember: ``imu_bias`` (B, N, 3) (acc x, y
    m/s², gyro rad/s), ``behaviour`` (:class:`~finkensim.behaviours.wall_check.BehaviourState`), and
    ``memory``: a user behaviour's object."""

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

    def memory_arrays(self) -> "MemoryArrays":
        """The IMU bias and behaviour memory as a :class:`MemoryArrays` record (the same arrays)."""
        m = self.behaviour
        return MemoryArrays(self.imu_bias, m.fail_count, m.wall, m.anchor, m.dr_pos, m.dr_vel, m.dr_yaw,
                            m.wall_onsets, m.wall_readings, m.sonar_held, m.sensor_delay)


@dataclass(frozen=True)
class SwarmRecord:
    """What :meth:`SwarmSim.rollout <finkensim.swarm.SwarmSim.rollout>` recorded: per-step arrays (see
    :data:`RECORDABLE`; None when not recorded), ``t`` (T,) s, and ``counters``: per-episode (B, N) int64
    counts over the rollout — ``collisions`` and ``wall_contacts`` (contact onsets), ``wall_onsets``
    (wall flags set) and ``wall_readings`` (echoes judged to be walls)."""

    t: np.ndarray
    counters: dict
    pose: np.ndarray | None = None
    vel: np.ndarray | None = None
    acc: np.ndarray | None = None
    yaw_rate: np.ndarray | None = None
    theta: np.ndarray | None = None
    sonar: np.ndarray | None = None
    sonar_ideal: np.ndarray | None = None
    sonar_hit: np.ndarray | None = None
    sonar_down: np.ndarray | None = None
    ranging: np.ndarray | None = None
    imu_acc: np.ndarray | None = None
    imu_gyro: np.ndarray | None = None
    wall: np.ndarray | None = None
    cmd_vel: np.ndarray | None = None
    cmd_yaw_rate: np.ndarray | None = None


def concat_records(records: list["SwarmRecord"]) -> "SwarmRecord":
    """One :class:`SwarmRecord` of consecutive rollouts (the arrays joined along time, the counters summed)."""
    first = records[0]
    arrays = {f.name: (None if getattr(first, f.name) is None else
                       np.concatenate([getattr(r, f.name) for r in records], axis=0))
              for f in fields(SwarmRecord) if f.name not in ("t", "counters")}
    counters = {k: sum(r.counters[k] for r in records) for k in first.counters}
    return SwarmRecord(t=np.concatenate([r.t for r in records]), counters=counters, **arrays)


class MemoryArrays(NamedTuple):
    """The sensors' and behaviours' memory as one flat record for the kernels (views of a
    :class:`SwarmState`): bias (B, N, 3) IMU bias; fail_count (B, N, 4) int64; wall (B, N, 4) bool;
    anchor (B, N, 4, 3); dr_pos (B, N, 2) m; dr_vel (B, N, 2) m/s; dr_yaw (B, N) rad; wall_onsets,
    wall_readings (B, N) int64; sonar_held (B, N, 4) m; sensor_delay (B, slots, N, W) the latency ring buffer (see
    :class:`~finkensim.behaviours.wall_check.BehaviourState`)."""

    bias: np.ndarray
    fail_count: np.ndarray
    wall: np.ndarray
    anchor: np.ndarray
    dr_pos: np.ndarray
    dr_vel: np.ndarray
    dr_yaw: np.ndarray
    wall_onsets: np.ndarray
    wall_readings: np.ndarray
    sonar_held: np.ndarray
    sensor_delay: np.ndarray


#: RunSpec.ranging_rows of a kernel that takes no rows from it
NO_RANGING_ROWS = np.empty((0, 0, 0))


class RunSpec(NamedTuple):
    """What a compiled rollout runs: seed, env_ids (B,) int64 global environment indices, step0 (the
    state's step), n_steps, kind (``KIND_*``), dt s, which sensors run (sonar, down, ranging, imu), and
    ranging_rows (B, N, N + M) float64 m: the work buffer of the ranging rows (uninitialised; every entry the step
    reads is written in it first; (0, 0, 0) where the kernel takes no rows from it); lags (3,) int64: sonar, ranging
    and IMU latency in steps (:func:`~finkensim.sensors.latency.sensor_lags`; zeros: none)."""

    seed: int
    env_ids: np.ndarray
    step0: int
    n_steps: int
    kind: int
    dt: float
    do_sonar: bool
    do_down: bool
    do_ranging: bool
    do_imu: bool
    ranging_rows: np.ndarray
    lags: np.ndarray = np.zeros(3, dtype=np.int64)


class Recording(NamedTuple):
    """The output arrays of a compiled rollout, one per :data:`RECORDABLE` name (same order and shapes);
    an array whose leading dimension is 0 instead of T is not recorded."""

    pose: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    yaw_rate: np.ndarray
    theta: np.ndarray
    sonar: np.ndarray
    sonar_ideal: np.ndarray
    sonar_hit: np.ndarray
    sonar_down: np.ndarray
    ranging: np.ndarray
    imu_acc: np.ndarray
    imu_gyro: np.ndarray
    wall: np.ndarray
    cmd_vel: np.ndarray
    cmd_yaw_rate: np.ndarray
