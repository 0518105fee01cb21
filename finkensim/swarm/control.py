"""Externally commanded swarm steps, compiled and batched: the engine under :mod:`finkensim.envs`.

A learning agent (or any outside controller) replaces the behaviour: it sees the sensor readings of
step k, chooses body-frame velocity commands, and the world advances to k + 1, where the copters sense
again. :func:`control_step` does "apply commands → :func:`~finkensim.world.step_env` → sense" for B
environments in ONE numba call (``prange`` over B; no Python per copter or per environment), with the
very per-environment kernels of the closed loop (:mod:`finkensim.swarm.kernel`): the sonars on the plates
displaced by their current angles, virtual ranging, the IMU. Sensing step k uses the random numbers of
step k, so readings driven with zero commands equal a ``"hover"`` :meth:`SwarmSim.rollout
<finkensim.swarm.SwarmSim.rollout>` bit for bit (``tests/test_envs.py`` checks this).

    ctl = Controlled(sim)                        # sim: a SwarmSim (its config's sensors and models)
    state = sim.init(n_envs=B, seed=0)
    obs = ctl.sense(state)                       # readings of step 0 (advances the IMU bias in place)
    state, obs = ctl.step(state, cmd_body)       # cmd_body (B, N, 2) m/s body frame; the arrays change in place
"""
from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..sensors.latency import LAG_IMU, LAG_RANGING, LAG_SONAR, delay_batch
from ..sensors.sonar_hold import hold_env
from ..sensors.ultrasonic import N_SONARS
from ..kernels.cellgrid import engine_grid, env_grid, no_grid_buffers
from ..kernels.twin import INTERNAL
# the closed loop's compiled twins of the per-environment kernels: the same compilations
from .kernel import (body_to_world_twin, imu_twin, plates_twin, ranging_twin, shift_twin, sonar_twin,
                     sonar_work_buffers, step_twin)
from .state import NO_RANGING_ROWS, RunSpec, SwarmState

__all__ = ["ControlReadings", "Controlled", "control_step", "control_step_serial", "PARALLEL_MIN_COPTERS"]

#: the environments of a parallel step are split into this many runs, each with its own scratch arrays
#: (enough to keep every thread busy; numba's ``prange`` splits the chunks among the threads)
CHUNKS = 64


class ControlReadings(NamedTuple):
    """What the copters sense after a controlled step (float64; a disabled sensor's array keeps the value
    :meth:`Controlled.readings` gives it: max_range for the sonar, zero otherwise):
    sonar (B, N, 4) m (front, left, back, right); ranging (B, N, N + M) m; imu_acc (B, N, 2) m/s² body
    frame; imu_gyro (B, N) rad/s."""

    sonar: np.ndarray
    ranging: np.ndarray
    imu_acc: np.ndarray
    imu_gyro: np.ndarray


@njit(cache=True, inline="always")
def _sense_env(b, k, w, bias, run, obs, geo, sp, rp, beacons, ip, bufs, grid, grid_b):
    """Sensors of environment b at step k → environment b of ``obs`` (a :class:`ControlReadings`; the IMU bias
    advances); grid_b: its grid buffers."""
    pa, pb, sonar_buf, dist, hit_kind, hit, slot = bufs
    seed = run.seed
    env = run.env_ids[b]
    pos_b = w.pos[b]
    yaw_b = w.yaw[b]
    if run.do_sonar:
        plates_twin(w.theta[b], geo.plate_a, geo.plate_b, geo.normal, geo.lever, pa, pb)
        if w.bulge.shape[1] > 0:  # the curtain bulge (walls.model) on top of the hinge
            shift_twin(w.bulge[b], geo.normal, pa, pb)
        sonar_twin(pos_b, yaw_b, pa, pb, geo.width, geo.length, sp, seed, env, k,
                   (sonar_buf, dist, hit_kind, hit, slot), obs.sonar[b], grid, grid_b)
    if run.do_ranging:
        # fill passed explicitly: the same signature as swarm_env's call, so one compilation serves both
        ranging_twin(pos_b, beacons, seed, env, k, rp, obs.ranging[b], grid, grid_b, True)
    if run.do_imu:
        imu_twin(w.acc[b], yaw_b, w.yaw_rate[b], bias[b], ip, seed, env, k, obs.imu_acc[b], obs.imu_gyro[b])


@njit(cache=True, inline="always")
def _control_env(b, w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid, work):
    """Environment b of :func:`control_step`; ``work`` = (:func:`~finkensim.swarm.kernel.sonar_work_buffers`,
    cmd_v (N, 2), cmd_w (N,) zeros (no yaw-rate commands), dist_buf (S,), gap_buf (N,), the chunk's own empty grid
    buffers): scratch arrays, reused from one environment to the next."""
    bufs, cmd_v, cmd_w, dist_buf, gap_buf, no_grid = work
    # with the grid off, the chunk's own empty buffers: env_grid's views of the shared ones would be counted by
    # both threads on one reference count (an atomic on a contended cache line, per call)
    grid_b = env_grid(grid, b) if grid.on else no_grid
    if run.n_steps == 1:
        body_to_world_twin(w.yaw[b], cmd_body[b], cmd_v)
        step_twin(w, b, cmd_v, cmd_w, cp, hp, geo, run.dt, dist_buf, gap_buf, grid, grid_b)
    _sense_env(b, run.step0 + run.n_steps, w, bias, run, obs, geo, sp, rp, beacons, ip, bufs, grid, grid_b)


@njit(cache=True, error_model="numpy", **INTERNAL)
def _control_chunk(c, n_chunks, w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid):
    """Chunk c of n_chunks equal runs of environments of :func:`control_step`, with one set of scratch arrays
    (allocating them per environment and step cost more than a tenth of a 10-copter step)."""
    B = w.pos.shape[0]
    N = w.pos.shape[1]
    S = geo.plate_a.shape[0]
    work = (sonar_work_buffers(N, S), np.empty((N, 2)), np.zeros(N), np.empty(geo.seg_a.shape[0]), np.empty(N),
            no_grid_buffers())
    for b in range(c * B // n_chunks, (c + 1) * B // n_chunks):
        _control_env(b, w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid, work)


@njit(cache=True, parallel=True)
def control_step(w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid):
    """For every environment b (``prange``): if ``run.n_steps`` is 1, rotate ``cmd_body[b]`` (N, 2) m/s by the
    headings into the world frame and :func:`~finkensim.world.step_env` by ``run.dt`` with zero yaw-rate
    commands; then sense at step ``run.step0 + run.n_steps`` into ``obs`` (a :class:`ControlReadings`).
    ``w`` (WorldArrays) and ``bias`` (B, N, 3) change in place."""
    n_chunks = min(w.pos.shape[0], CHUNKS)
    for c in prange(n_chunks):
        _control_chunk(np.int64(c), n_chunks, w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid)


@njit(cache=True)
def control_step_serial(w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid):
    """:func:`control_step` without threads: a parallel launch costs far more than a small batch's work.

    Its own function on purpose, not ``njit(control_step.py_func)``: numba's on-disk cache files entries under
    the Python function, so a serial compilation of the same function shares the parallel one's cache entry and
    whichever compiled first was loaded for both — the vector env then ran on one thread from a warm cache."""
    _control_chunk(0, 1, w, bias, run, cmd_body, obs, cp, hp, geo, sp, rp, beacons, ip, grid)


#: batches with fewer copters in total than this run :data:`control_step_serial`
PARALLEL_MIN_COPTERS = 512


class Controlled:
    """Batched externally commanded stepping of a :class:`~finkensim.swarm.SwarmSim`'s world and sensors.

    The state's arrays change in place (the envs own their state); the returned readings are fresh arrays
    unless ``out`` is given.
    The behaviour, its wall check and dead reckoning do not run (the commands replace them).
    """

    def __init__(self, sim):
        self.sim = sim
        self.n_ranging = sim.n_copters + sim.beacons.shape[0]
        self._grid = (0, None)

    def _grid_buffers(self, B: int, N: int):
        """The grid buffers of B environments, allocated once per batch size."""
        if self._grid[0] != B:
            self._grid = (B, engine_grid(self.sim.world.grid, B, N))
        return self._grid[1]

    def readings(self, B: int, N: int) -> ControlReadings:
        """Fresh readings arrays for B environments of N copters (a disabled sensor's stay at these values)."""
        return ControlReadings(np.full((B, N, N_SONARS), self.sim.sonar.max_range), np.zeros((B, N, self.n_ranging)),
                               np.zeros((B, N, 2)), np.zeros((B, N)))

    def _run(self, state: SwarmState, cmd_body, n_steps: int, out: ControlReadings | None) -> ControlReadings:
        sim = self.sim
        ws = state.world
        B, N = ws.n_envs, ws.n_copters
        obs = self.readings(B, N) if out is None else out
        want = ((B, N, N_SONARS), (B, N, self.n_ranging), (B, N, 2), (B, N))
        if out is not None and (tuple(a.shape for a in out) != want
                                or any(a.dtype != np.float64 or not a.flags.c_contiguous for a in out)):
            raise ValueError(f"out has shapes {[a.shape for a in out]}: expected C-contiguous float64 arrays of shapes "
                             f"{list(want)}, as Controlled.readings({B}, {N}) makes them")
        run = RunSpec(int(ws.seed), ws.env_ids, int(ws.step), n_steps, 0, float(sim.dt), sim.enabled["sonar"],
                      False, sim.enabled["ranging"], sim.enabled["imu"], NO_RANGING_ROWS)
        cmd = np.ascontiguousarray(cmd_body, dtype=np.float64) if cmd_body is not None else np.zeros((B, N, 2))
        if cmd.shape != (B, N, 2):
            raise ValueError(f"cmd_body has shape {cmd.shape}: expected (B, N, 2) = ({B}, {N}, 2)")
        w = sim.world
        kernel = control_step if B * N >= PARALLEL_MIN_COPTERS else control_step_serial
        kernel(ws.arrays(), state.imu_bias, run, cmd, obs, w.copter_params, w.hinge_params, w.geometry,
                     sim.sonar, sim.ranging.params, sim.beacons, sim.imu, self._grid_buffers(B, N))
        if sim.enabled["sonar"] and sim.sonar.update_hz > 0.0:  # sample-and-hold, the state's held readings
            held = state.behaviour.sonar_held
            for b in range(B):
                hold_env(obs.sonar[b], held[b], run.step0 + n_steps, run.dt, sim.sonar.update_hz,
                         sim.sonar.update_phase)
        if sim.lags.any():  # latency: each reading describes the world that many steps earlier
            buf, k = state.behaviour.sensor_delay, run.step0 + n_steps
            sim._check_delay(buf, B, N)
            for name, sensor, arr, off in (("sonar", LAG_SONAR, obs.sonar, 0), ("ranging", LAG_RANGING, obs.ranging, 0),
                                           ("imu", LAG_IMU, obs.imu_acc, 0), ("imu", LAG_IMU, obs.imu_gyro, 2)):
                if sim.enabled[name]:
                    delay_batch(arr, buf, sim.lags, sensor, k, self.n_ranging, off)
        return obs

    def sense(self, state: SwarmState, out: ControlReadings | None = None) -> ControlReadings:
        """Readings at the state's step (the IMU bias in ``state`` advances by one draw). ``out``: arrays from
        :meth:`readings` to write them into (the enabled sensors' entries are all overwritten), else fresh ones."""
        return self._run(state, None, 0, out)

    def step(self, state: SwarmState, cmd_body, out: ControlReadings | None = None
             ) -> tuple[SwarmState, ControlReadings]:
        """Apply ``cmd_body`` (B, N, 2) m/s body frame (the world clips the speed to ``copters.max_speed``),
        step once, and sense. Returns (the advanced state — its arrays are ``state``'s, changed in place —,
        the readings of the new step, in ``out`` if given, as in :meth:`sense`)."""
        obs = self._run(state, cmd_body, 1, out)
        ws = state.world
        return replace(state, world=replace(ws, step=ws.step + 1)), obs
