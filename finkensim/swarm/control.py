"""Externally commanded swarm steps, compiled and batched: the engine under :mod:`finkensim.envs`.

A learning agent (or any outside controller) replaces the behaviour: it sees the sensor readings of
step k, chooses body-frame velocity commands, and the world advances to k + 1, where the copters sense
again. :func:`control_step` does "apply commands → :func:`~finkensim.world.step_env` → sense" for B
environments in one numba call per thread (:func:`~finkensim.kernels.threads.run_ranges` over B; no Python per
copter or per environment), with the very per-environment kernels of the closed loop (:mod:`finkensim.swarm.kernel`): the sonars on the plates
displaced by their current angles, virtual ranging, the IMU. Sensing step k uses the random numbers of
step k, so readings driven with zero commands equal a ``"hover"`` :meth:`SwarmSim.rollout
<finkensim.swarm.SwarmSim.rollout>` bit for bit (``tests/test_envs.py`` checks this).

    ctl = Controlled(sim)                        # sim: a SwarmSim (its config's sensors and models)
    state = sim.init(n_envs=B, seed=0)
    obs = ctl.sense(state)                       # readings of step 0 (advances the IMU bias in place)
    state, obs = ctl.step(state, cmd_body)       # cmd_body (B, N, 2) m/s body frame; the arrays change in place
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..sensors.sonar import N_SONARS
from ..kernels.cellgrid import engine_grid, env_grid, no_grid_buffers
from ..kernels.threads import run_ranges
# the closed loop's outlined copies of the per-environment kernels: the same compilations
from .kernel import body_to_world_outlined, step_outlined
from .sense import SenseBuffers, sense_buffers, sense_env
from .state import NO_RANGING_ROWS, SwarmState, run_spec

__all__ = ["ControlReadings", "Controlled", "control_step", "control_range", "PARALLEL_MIN_COPTERS"]


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
def _control_env(b, state, run, cmd_body, obs, models, grid, work):
    """Environment b of :func:`control_step`; ``work`` = (a :class:`~finkensim.swarm.sense.SenseBuffers` whose
    scratch arrays serve every environment of the chunk, cmd_v (N, 2), cmd_w (N,) zeros (no yaw-rate commands),
    dist_buf (S,), gap_buf (N,), the chunk's own empty grid buffers): scratch arrays, reused from one environment to
    the next."""
    s, cmd_v, cmd_w, dist_buf, gap_buf, no_grid = work
    # with the grid off, the chunk's own empty buffers: env_grid's views of the shared ones would be counted by
    # both threads on one reference count (an atomic on a contended cache line, per call)
    cells = env_grid(grid, b) if grid.on else no_grid
    world = state.world
    if run.n_steps == 1:
        body_to_world_outlined(world.yaw[b], cmd_body[b], cmd_v)
        step_outlined(world, b, cmd_v, cmd_w, (models.copter, models.hinge, models.geometry), run.dt, (dist_buf, gap_buf),
                  grid, cells)
    # environment b's readings in obs, the chunk's scratch arrays around them
    buf = SenseBuffers(obs.sonar[b], s.sonar_ideal, s.sonar_hit, s.sonar_down, obs.ranging[b], obs.imu_acc[b],
                       obs.imu_gyro[b], s.plate_a, s.plate_b, s.sonar_rays, s.hit_point, s.slot, s.altitude, True)
    sense_env(b, run.step0 + run.n_steps, state, run, models, buf, grid, cells)


@njit(cache=True, nogil=True, error_model="numpy", no_cfunc_wrapper=True)
def control_range(span, state, run, cmd_body, obs, models, grid):
    """Environments span[0] … span[1] − 1 of :func:`control_step`, one after another with one set of scratch arrays
    (allocating them per environment and step cost more than a tenth of a 10-copter step); releases the GIL."""
    if span[1] <= span[0]:
        return
    N = state.world.pos.shape[1]
    work = (sense_buffers(obs.sonar[0], obs.ranging[0], obs.imu_acc[0], obs.imu_gyro[0], models, True),
            np.empty((N, 2)), np.zeros(N), np.empty(models.geometry.seg_a.shape[0]), np.empty(N), no_grid_buffers())
    for b in range(span[0], span[1]):
        _control_env(b, state, run, cmd_body, obs, models, grid, work)


def control_step(state, run, cmd_body, obs, models, grid):
    """For every environment b: if ``run.n_steps`` is 1, rotate ``cmd_body[b]`` (N, 2) m/s by the headings into the
    world frame and :func:`~finkensim.world.step_env` by ``run.dt`` with zero yaw-rate commands; then
    :func:`~finkensim.swarm.sense.sense_env` at step ``run.step0 + run.n_steps`` into ``obs``.

    The environments split over numba's threads (:func:`~finkensim.kernels.threads.run_ranges`, as the rollout) when
    the batch has at least :data:`PARALLEL_MIN_COPTERS` copters; the same results either way. (Not ``prange``: numba's
    parfor lowering fails on a record of records such as :class:`~finkensim.swarm.state.Models`.)

    Parameters
    ----------
    state : SwarmState
        B environments (``memory=None``): the world steps, the IMU bias and the sonars' held readings advance, in
        place.
    run : RunSpec
        Seed, environments, step, ``n_steps`` (0: sense only, 1: step then sense), enabled sensors.
    cmd_body : ndarray, shape (B, N, 2)
        Body-frame velocity commands, m/s.
    obs : ControlReadings
        The readings, written.
    models : Models
        The world's and sensors' models.
    grid : EngineGrid
        The batch's copter-copter cell grid.
    """
    B, N = state.world.pos.shape[0], state.world.pos.shape[1]
    run_ranges(control_range, B, state, run, cmd_body, obs, models, grid, parallel=B * N >= PARALLEL_MIN_COPTERS)


#: batches with fewer copters in total than this run on the calling thread alone
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
        run = run_spec(ws, n_steps, sim.dt, (sim.enabled["sonar"], False, sim.enabled["ranging"], sim.enabled["imu"]),
                       NO_RANGING_ROWS, sim.lags, N + sim.beacons.shape[0])
        cmd = np.ascontiguousarray(cmd_body, dtype=np.float64) if cmd_body is not None else np.zeros((B, N, 2))
        if cmd.shape != (B, N, 2):
            raise ValueError(f"cmd_body has shape {cmd.shape}: expected (B, N, 2) = ({B}, {N}, 2)")
        if sim.lags.any():  # the latency ring buffer must be the one this sim's init made
            sim._check_delay(state.behaviour.sensor_delay, B, N)
        control_step(state.for_kernels(), run, cmd, obs, sim.models(), self._grid_buffers(B, N))
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
        return state._replace(world=ws._replace(step=ws.step + 1)), obs
