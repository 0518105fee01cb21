"""The swarm's data: behaviour codes, what a rollout can record, the state and record classes, and the
flat NamedTuple records the compiled loop (:mod:`finkensim.swarm.kernel`) takes.

Shapes: B environments, N copters, S plates, M beacons, T recorded steps; 4 horizontal sonars.
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..behaviours.wall_check import BehaviourState
from ..sensors.latency import delay_columns
from ..world import WorldState

__all__ = ["RECORDABLE", "SENSOR_OF", "SensorReadings", "SwarmState", "SwarmRecord", "RunSpec",
           "NO_RANGING_ROWS", "run_spec", "kernel_record", "Models"]

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


class SwarmState(NamedTuple):
    """World state plus everything the sensors and behaviours remember, one record for Python and the kernels:
    ``world`` (:class:`~finkensim.world.WorldState`), ``imu_bias`` (B, N, 3) (acc x, y m/s², gyro rad/s),
    ``behaviour`` (:class:`~finkensim.behaviours.wall_check.BehaviourState`: wall-check memory, dead reckoning,
    held sonar readings, the behaviour's own memory), and ``memory``: a Python behaviour's object (the kernels take
    the state with ``memory=None``: :meth:`for_kernels`). A changed copy is ``state._replace(world=...)``."""

    world: WorldState
    imu_bias: np.ndarray
    behaviour: BehaviourState
    memory: Any = None

    @property
    def step(self) -> int:
        """Steps taken since init."""
        return self.world.step

    @property
    def n_envs(self) -> int:
        """B, the number of environments."""
        return self.world.n_envs

    @property
    def n_copters(self) -> int:
        """N, copters per environment."""
        return self.world.n_copters

    def copy(self) -> "SwarmState":
        """Copies of every array (``memory`` is shared, not copied)."""
        return self._replace(world=self.world.copy(), imu_bias=self.imu_bias.copy(), behaviour=self.behaviour.copy())

    def select(self, envs) -> "SwarmState":
        """The sub-batch ``envs`` as an independent state (``memory`` is shared)."""
        return self._replace(world=self.world.select(envs), imu_bias=np.ascontiguousarray(self.imu_bias[envs]),
                             behaviour=self.behaviour.select(envs))

    def for_kernels(self) -> "SwarmState":
        """The same arrays without the Python behaviour's ``memory`` (numba cannot type an arbitrary object)."""
        return self._replace(memory=None)


class SwarmRecord(NamedTuple):
    """What :meth:`SwarmSim.rollout <finkensim.swarm.SwarmSim.rollout>` recorded: per-step arrays (see
    :data:`RECORDABLE`; None when not recorded), ``t`` (T,) s, and ``counters``: per-episode (B, N) int64
    counts over the rollout — ``collisions`` and ``wall_contacts`` (contact onsets), ``wall_onsets``
    (wall flags set) and ``wall_readings`` (echoes judged to be walls).

    One record for Python and the compiled rollout: the kernel fills one with ``t`` and ``counters`` None and every
    :data:`RECORDABLE` array present, of leading dimension T when recorded and 0 when not
    (:func:`kernel_record`)."""

    t: np.ndarray | None
    counters: dict | None
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
    arrays = {name: (None if getattr(first, name) is None else np.concatenate([getattr(r, name) for r in records], axis=0))
              for name in RECORDABLE}
    counters = {k: sum(r.counters[k] for r in records) for k in first.counters}
    return SwarmRecord(t=np.concatenate([r.t for r in records]), counters=counters, **arrays)


#: RunSpec.ranging_rows of a kernel that takes no rows from it
NO_RANGING_ROWS = np.empty((0, 0, 0))


class RunSpec(NamedTuple):
    """What a compiled rollout runs: seed, env_ids (B,) int64 global environment indices, step0 (the
    state's step), n_steps, dt s, which sensors run (sonar, down, ranging, imu), and
    ranging_rows (B, N, N + M) float64 m: the work buffer of the ranging rows (uninitialised; every entry the step
    reads is written in it first; (0, 0, 0) where the kernel takes no rows from it); lags (3,) int64: sonar, ranging
    and IMU latency in steps (:func:`~finkensim.sensors.latency.sensor_lags`; zeros: none); delay_columns (3,) int64:
    the first column of each sensor's block in the latency ring buffer (−1: no lag), computed once per rollout
    (:func:`~finkensim.sensors.latency.delay_columns`, :func:`run_spec`)."""

    seed: int
    env_ids: np.ndarray
    step0: int
    n_steps: int
    dt: float
    do_sonar: bool
    do_down: bool
    do_ranging: bool
    do_imu: bool
    ranging_rows: np.ndarray
    lags: np.ndarray = np.zeros(3, dtype=np.int64)
    delay_columns: np.ndarray = np.full(3, -1, dtype=np.int64)


def run_spec(world, n_steps: int, dt: float, sensors: tuple, ranging_rows: np.ndarray, lags: np.ndarray,
             n_ranging: int) -> RunSpec:
    """The :class:`RunSpec` of a rollout from ``world`` (its seed, env_ids and step), with the latency ring buffer's
    column offsets computed once here for ``lags`` and ``n_ranging`` = N + M ranging columns.

    Parameters
    ----------
    world : WorldState
        The state the rollout starts from.
    n_steps : int
        Steps to run.
    dt : float
        The step, s.
    sensors : tuple
        (sonar, down, ranging, imu): which sensors run.
    ranging_rows : numpy.ndarray
        The ranging rows' work buffer (B, N, N + M), or :data:`NO_RANGING_ROWS`.
    lags : numpy.ndarray
        (3,) int64 sensor latencies in steps.
    n_ranging : int
        Ranging columns N + M.

    Returns
    -------
    RunSpec
        The record.
    """
    lags = np.asarray(lags, dtype=np.int64)
    columns = delay_columns(lags, int(n_ranging))[0]
    return RunSpec(int(world.seed), world.env_ids, int(world.step), int(n_steps), float(dt), *(bool(s) for s in sensors),
                   ranging_rows, lags, columns)


def kernel_record(arrays: dict) -> SwarmRecord:
    """The record the compiled rollout fills: ``arrays`` (a :data:`RECORDABLE` name → array, leading dimension T
    when recorded, 0 when not), ``t`` and ``counters`` None.

    Parameters
    ----------
    arrays : dict
        Every :data:`RECORDABLE` name → its output array.

    Returns
    -------
    SwarmRecord
        The record.
    """
    return SwarmRecord(t=None, counters=None, **{name: arrays[name] for name in RECORDABLE})


class Models(NamedTuple):
    """Every model the engine's kernels read, as one record (static during a rollout).

    copter (:class:`~finkensim.copters.CopterParams`), hinge (:class:`~finkensim.arena.HingeParams`), geometry
    (:class:`~finkensim.arena.WallGeometry`), sonar (:class:`~finkensim.sensors.sonar.SonarModel`), ranging
    (``RangingModel.params``), beacons (M, 2) m, imu (:class:`~finkensim.sensors.imu.ImuModel`), wall_check
    (:class:`~finkensim.behaviours.wall_check.WallCheckParams`). A new sensor's or effect's model is one more field
    at the end. The flown behaviour's parameter record travels beside it (its type differs per behaviour: inside
    this record it would make numba compile the shared sense step once per behaviour)."""

    copter: Any
    hinge: Any
    geometry: Any
    sonar: Any
    ranging: Any
    beacons: np.ndarray
    imu: Any
    wall_check: Any
