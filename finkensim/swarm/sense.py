"""The sense step, written once: what every copter of one environment senses at step k, in the order the hardware
does it — plates → sonars → sonar hold → down sonar → ranging → IMU.

Both engines call :func:`sense_env`: the closed loop (:func:`finkensim.swarm.kernel.engine_for`, then dead reckoning,
the wall check and the behaviour) and the externally commanded step of the RL environments
(:mod:`finkensim.swarm.control`), so their readings are equal by construction (``tests/test_envs.py`` keeps checking).

**Adding a sensor-side effect** is one field and one call: the effect's model goes at the end of
:class:`~finkensim.swarm.state.Models`, its per-copter history (if any) at the end of
:class:`~finkensim.behaviours.wall_check.BehaviourState` (``SwarmState.behaviour``), its output buffer at the end of
:class:`SenseBuffers`, and its kernel call into :func:`sense_env` at its place in the sequence (a correction of
readings goes after the sensor it corrects, a latency history after all of them).

The per-sensor kernels are called through their outlined copies (:mod:`finkensim.kernels.outline`): one compilation
of each serves both engines.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..arena import shift_plates_env
from ..kernels.outline import INTERNAL, outlined
from ..sensors.imu import imu_env
from ..sensors.latency import LAG_IMU, LAG_RANGING, LAG_SONAR, delay_env
from ..sensors.ranging_kernels import ranging_grid_env
from ..sensors.sonar_hold import hold_env
from ..sensors.sonar import N_SONARS, displaced_plates_env, down_env, sonar_env

__all__ = ["SenseBuffers", "sense_buffers", "sense_env", "plates_outlined", "sonar_outlined", "hold_outlined", "down_outlined",
           "ranging_outlined", "imu_outlined", "shift_outlined", "delay_outlined"]

plates_outlined = outlined(displaced_plates_env)
sonar_outlined = outlined(sonar_env)
hold_outlined = outlined(hold_env)
down_outlined = outlined(down_env)
ranging_outlined = outlined(ranging_grid_env)
imu_outlined = outlined(imu_env)
shift_outlined = outlined(shift_plates_env)
delay_outlined = outlined(delay_env)


class SenseBuffers(NamedTuple):
    """One environment's readings (written by :func:`sense_env`) and the scratch arrays of its sensing.

    Readings: sonar (N, 4) m; sonar_ideal (N, 4) m error-free distances; sonar_hit (N, 4) int64 hit kinds;
    sonar_down (N,) m; ranging (N, N + M) m (or (N, 0)); imu_acc (N, 2) m/s² body frame; imu_gyro (N,) rad/s.
    Scratch: plate_a, plate_b (S, 2) m displaced plate ends; sonar_rays (N, 4, 4); hit_point (N, 4, 2) m;
    slot (N,) int64; altitude (N,) m flight heights of the down sonar. fill_ranging: write every ranging entry
    (False: only those in range on the cell grid, when nothing else reads the rest)."""

    sonar: np.ndarray
    sonar_ideal: np.ndarray
    sonar_hit: np.ndarray
    sonar_down: np.ndarray
    ranging: np.ndarray
    imu_acc: np.ndarray
    imu_gyro: np.ndarray
    plate_a: np.ndarray
    plate_b: np.ndarray
    sonar_rays: np.ndarray
    hit_point: np.ndarray
    slot: np.ndarray
    altitude: np.ndarray
    fill_ranging: bool


@njit(cache=True, **INTERNAL)
def sense_buffers(sonar, ranging, imu_acc, imu_gyro, models, fill_ranging):
    """:class:`SenseBuffers` around the given reading arrays (sonar (N, 4), ranging (N, R), imu_acc (N, 2), imu_gyro
    (N,)) with fresh scratch arrays and a zeroed down-sonar row (N,); models: the
    :class:`~finkensim.swarm.state.Models` (plate count, flight altitude)."""
    N = sonar.shape[0]
    S = models.geometry.plate_a.shape[0]
    return SenseBuffers(sonar, np.empty((N, N_SONARS)), np.empty((N, N_SONARS), dtype=np.int64), np.zeros(N),
                        ranging, imu_acc, imu_gyro, np.empty((S, 2)), np.empty((S, 2)), np.empty((N, N_SONARS, 4)),
                        np.empty((N, N_SONARS, 2)), np.zeros(N, dtype=np.int64), np.full(N, models.sonar.altitude),
                        fill_ranging)


@njit(cache=True, inline="always")  # why: one level of calls less below the engines (finkensim.kernels.outline)
def sense_env(b, k, state, run, models, buf, grid, cells):
    """The sensors of environment b at step k → ``buf`` (:class:`SenseBuffers`), each when ``run`` enables it:
    sonars on the plates displaced by their current angles and by the curtain bulge where the walls have one
    (``walls.model``; then held between measurements when ``sonar.update_hz`` > 0: ``memory.sonar_held``), the down
    sonar, ranging to every copter and beacon, the IMU (its bias ``state.imu_bias`` advances); a sensor with a
    latency (``run.lags``) then shows the reading of that many steps earlier (the ring buffer
    ``state.behaviour.sensor_delay``, :mod:`finkensim.sensors.latency`). state: :class:`~finkensim.swarm.state.SwarmState` (held readings in
    ``state.behaviour.sonar_held``); run: :class:`~finkensim.swarm.state.RunSpec`; models:
    :class:`~finkensim.swarm.state.Models`; grid, cells: the batch's cell grid and environment b's buffers."""
    world = state.world
    seed = run.seed
    env = run.env_ids[b]
    pos = world.pos[b]
    yaw = world.yaw[b]
    geometry = models.geometry
    sonar = models.sonar
    lags = run.lags
    delay = state.behaviour.sensor_delay[b]
    cols = run.delay_columns  # each sensor's columns in the ring buffer, computed once per rollout
    if run.do_sonar:
        plates_outlined(world.theta[b], geometry.plate_a, geometry.plate_b, geometry.normal, geometry.lever, buf.plate_a, buf.plate_b)
        if world.bulge.shape[1] > 0:  # the curtain bulge (walls.model) on top of the hinge
            shift_outlined(world.bulge[b], geometry.normal, buf.plate_a, buf.plate_b)
        sonar_outlined(pos, yaw, (buf.plate_a, buf.plate_b, geometry.width, geometry.length), sonar, (seed, env, k),
                   (buf.sonar_rays, buf.sonar_ideal, buf.sonar_hit, buf.hit_point, buf.slot), buf.sonar, grid, cells)
        if sonar.update_hz > 0.0:
            hold_outlined(buf.sonar, state.behaviour.sonar_held[b], k, run.dt, sonar.update_hz, sonar.update_phase)
        if lags[LAG_SONAR] > 0:
            delay_outlined(buf.sonar, delay, cols[LAG_SONAR], k, lags[LAG_SONAR])
    if run.do_down:
        down_outlined(buf.altitude, sonar, seed, env, k, buf.sonar_down)
    if run.do_ranging:
        ranging_outlined(pos, yaw, models.beacons, (seed, env, k), models.ranging, buf.ranging, grid, cells,
                     buf.fill_ranging)
        if lags[LAG_RANGING] > 0:
            delay_outlined(buf.ranging, delay, cols[LAG_RANGING], k, lags[LAG_RANGING])
    if run.do_imu:
        imu_outlined(world.acc[b], yaw, world.yaw_rate[b], state.imu_bias[b], models.imu, seed, env, k, buf.imu_acc,
                 buf.imu_gyro)
        if lags[LAG_IMU] > 0:
            delay_outlined(buf.imu_acc, delay, cols[LAG_IMU], k, lags[LAG_IMU])
            delay_outlined(buf.imu_gyro.reshape((buf.imu_gyro.shape[0], 1)), delay, cols[LAG_IMU] + 2, k, lags[LAG_IMU])
