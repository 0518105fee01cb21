"""The compiled closed loop: T steps of sense → behave → step for B environments in one numba kernel.

:func:`swarm_rollout` splits the environments over numba's threads (:func:`swarm_env` on each share, a ``nogil``
kernel: :mod:`finkensim.kernels.threads`) with the T loop inside, work buffers allocated once per environment, no
Python per step. The loop body calls non-inlined twins
of the per-environment kernels (the same Python functions compiled as functions): identical results,
and a cold compilation of ≈ 20 s instead of about a minute with everything inlined.

Arguments are flat NamedTuple records: :class:`~finkensim.world.WorldArrays` (world state),
:class:`~finkensim.swarm.state.MemoryArrays` (IMU bias, behaviour memory),
:class:`~finkensim.swarm.state.RunSpec` (seed, steps, behaviour, enabled sensors),
:class:`~finkensim.swarm.state.Recording` (outputs), and the model records
(:class:`~finkensim.copters.CopterParams`, :class:`~finkensim.arena.HingeParams`,
:class:`~finkensim.arena.WallGeometry`, :class:`~finkensim.sensors.ultrasonic.SonarModel`,
``RangingModel.params``, :class:`~finkensim.sensors.imu.ImuModel`,
:class:`~finkensim.behaviours.random_walk.RandomWalkParams`,
:class:`~finkensim.behaviours.attraction.AttractionParams`,
:class:`~finkensim.behaviours.wall_check.WallCheckParams`).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..behaviours.attraction import attraction_env, body_to_world_env
from ..behaviours.random_walk import random_walk_env
from ..behaviours.wall_check import WALL_CHECK_NONE, dead_reckon_env, wall_check_env
from ..sensors.imu import imu_env
from ..sensors.latency import LAG_IMU, LAG_RANGING, LAG_SONAR, delay_columns, delay_env
from ..sensors.ranging_kernels import ranging_grid_env
from ..sensors.sonar_hold import hold_env
from ..sensors.ultrasonic import N_SONARS, displaced_plates_env, down_env, ultrasonic_env
from ..kernels.cellgrid import env_grid
from ..kernels.threads import run_ranges
from ..kernels.twin import INTERNAL, twin
from ..arena import shift_plates_env
from ..world import step_env
from .state import KIND_ATTRACTION, KIND_RANDOM_WALK

__all__ = ["swarm_env", "swarm_rollout", "sonar_work_buffers", "PARALLEL_MIN_COPTER_STEPS"]


# the per-environment kernels as called functions (finkensim.kernels.twin); control.py calls them too
plates_twin = twin(displaced_plates_env)
sonar_twin = twin(ultrasonic_env)
hold_twin = twin(hold_env)
down_twin = twin(down_env)
ranging_twin = twin(ranging_grid_env)
imu_twin = twin(imu_env)
dead_reckon_twin = twin(dead_reckon_env)
wall_check_twin = twin(wall_check_env)
attraction_twin = twin(attraction_env)
body_to_world_twin = twin(body_to_world_env)
random_walk_twin = twin(random_walk_env)
step_twin = twin(step_env)
shift_twin = twin(shift_plates_env)
delay_twin = twin(delay_env)


@njit(cache=True, **INTERNAL)
def sonar_work_buffers(N, S):
    """The scratch arrays of one environment's sensing: plate ends pa, pb (S, 2), sonar_buf (N, 4, 4), dist (N, 4),
    hit_kind (N, 4), hit (N, 4, 2), slot (N,) (the work tuple of
    :func:`~finkensim.sensors.ultrasonic.ultrasonic_env`)."""
    return (np.empty((S, 2)), np.empty((S, 2)), np.empty((N, N_SONARS, 4)), np.empty((N, N_SONARS)),
            np.empty((N, N_SONARS), dtype=np.int64), np.empty((N, N_SONARS, 2)), np.zeros(N, dtype=np.int64))


@njit(cache=True, **INTERNAL)
def _record_state(t, b, w, rec):
    """The state of environment b before step t → rec (pose, vel, acc, yaw_rate, theta) where recorded."""
    N = w.pos.shape[1]
    # explicit loops: slice assignments would pull in numba's broadcast-error machinery (slow to compile)
    if rec.pose.shape[0] > 0:
        for n in range(N):
            rec.pose[t, b, n, 0] = w.pos[b, n, 0]
            rec.pose[t, b, n, 1] = w.pos[b, n, 1]
            rec.pose[t, b, n, 2] = w.yaw[b, n]
    if rec.vel.shape[0] > 0:
        for n in range(N):
            rec.vel[t, b, n, 0] = w.vel[b, n, 0]
            rec.vel[t, b, n, 1] = w.vel[b, n, 1]
    if rec.acc.shape[0] > 0:
        for n in range(N):
            rec.acc[t, b, n, 0] = w.acc[b, n, 0]
            rec.acc[t, b, n, 1] = w.acc[b, n, 1]
    if rec.yaw_rate.shape[0] > 0:
        for n in range(N):
            rec.yaw_rate[t, b, n] = w.yaw_rate[b, n]
    if rec.theta.shape[0] > 0:
        for s in range(w.theta.shape[1]):
            rec.theta[t, b, s] = w.theta[b, s]


@njit(cache=True, **INTERNAL)
def _record_step(t, b, rec, son, dist, hit_kind, wall_b, down, rng, imu_a, imu_g, cmd_v, cmd_w):
    """What environment b sensed and commanded at step t → rec, where recorded. son, dist (N, 4) m,
    hit_kind (N, 4), wall_b (N, 4) bool, down (N,) m, rng (N, N + M) m, imu_a (N, 2), imu_g (N,), cmd_v
    (N, 2) m/s, cmd_w (N,) rad/s."""
    for n in range(son.shape[0]):
        for j in range(N_SONARS):
            if rec.sonar.shape[0] > 0:
                rec.sonar[t, b, n, j] = son[n, j]
            if rec.sonar_ideal.shape[0] > 0:
                rec.sonar_ideal[t, b, n, j] = dist[n, j]
            if rec.sonar_hit.shape[0] > 0:
                rec.sonar_hit[t, b, n, j] = hit_kind[n, j]
            if rec.wall.shape[0] > 0:
                rec.wall[t, b, n, j] = wall_b[n, j]
        if rec.sonar_down.shape[0] > 0:
            rec.sonar_down[t, b, n] = down[n]
        if rec.ranging.shape[0] > 0:
            for j in range(rng.shape[1]):
                rec.ranging[t, b, n, j] = rng[n, j]
        if rec.imu_acc.shape[0] > 0:
            rec.imu_acc[t, b, n, 0] = imu_a[n, 0]
            rec.imu_acc[t, b, n, 1] = imu_a[n, 1]
        if rec.imu_gyro.shape[0] > 0:
            rec.imu_gyro[t, b, n] = imu_g[n]
        if rec.cmd_vel.shape[0] > 0:
            rec.cmd_vel[t, b, n, 0] = cmd_v[n, 0]
            rec.cmd_vel[t, b, n, 1] = cmd_v[n, 1]
        if rec.cmd_yaw_rate.shape[0] > 0:
            rec.cmd_yaw_rate[t, b, n] = cmd_w[n]


@njit(cache=True, nogil=True, no_cfunc_wrapper=True)  # called from Python only: no C callback wrapper
def swarm_env(span, w, mem, run, rec, cp, hp, geo, sp, rp, beacons, ip, rw, ap, wp, grid):
    """``run.n_steps`` steps of the closed loop for environments span[0] … span[1] − 1, one after another, in place
    (one thread's share of :func:`swarm_rollout`; releases the GIL). Each step k: 1. sense (sonars on the plates
    displaced by their current angles, down sonar, ranging, IMU + dead reckoning), 2. behave (wall check, then the
    built-in controller ``run.kind``), 3. :func:`~finkensim.world.step_env`. beacons (M, 2) m; grid: the
    copter-copter cell grid of the batch (:class:`~finkensim.kernels.cellgrid.EngineGrid`).

    The environment loop is here, not in a caller: numba links every callee's code into its caller and optimizes it
    again, so each level of calls above the engine costs seconds of cold compile."""
    N = w.pos.shape[1]
    S = geo.plate_a.shape[0]
    R = N + beacons.shape[0]
    seed = run.seed
    # the wall check may look up each copter's ranging columns in range on the grid when the ranging ran on it
    # (not with a ranging latency: the delayed rows are not those of the current positions' grid)
    near_on = run.do_ranging and grid.on and wp.ranging_max_range == rp.max_range and run.lags[LAG_RANGING] == 0
    # then the wall check reads only the columns in range, so unless the readings are recorded the rest of each
    # ranging row need not be written at every step
    fill = rec.ranging.shape[0] > 0 or not near_on
    for b in range(span[0], span[1]):
        env = run.env_ids[b]
        pos = w.pos[b]
        yaw = w.yaw[b]
        # work buffers, once per environment
        pa, pb, sonar_buf, dist, hit_kind, hit, slot = sonar_work_buffers(N, S)
        son = np.full((N, N_SONARS), sp.max_range)
        alt = np.full(N, sp.altitude)
        down = np.empty(N)
        # the N × (N + M) ranging rows only when something reads them (the ranging itself, or a wall check, which
        # reads zeros with the ranging off): 800 MB per environment at N = 10 000. With the ranging on, every entry
        # read is written first at each step (all of them, or those in range: see `fill` above), so the rows need no
        # zeroing, and they are the caller's buffer, kept between rollouts (fresh pages cost the operating system's
        # zeroing of all of them on first touch: ≈ 0.2 s per call at N = 10 000, the work of three steps)
        if run.do_ranging:
            rng = run.ranging_rows[b]
        else:
            rng = np.zeros((N, R)) if run.do_sonar and wp.mode != WALL_CHECK_NONE else np.zeros((N, 0))
        imu_a = np.zeros((N, 2))
        imu_g = np.zeros(N)
        fail_buf = np.zeros((N, N_SONARS), dtype=np.bool_)
        cmd_body = np.zeros((N, 2))
        cmd_v = np.zeros((N, 2))
        cmd_w = np.zeros(N)
        dist_buf = np.empty(geo.seg_a.shape[0])
        gap_buf = np.empty(N)
        grid_b = env_grid(grid, b)
        lags = run.lags
        delay_cols = delay_columns(lags, R)[0]
        delay = mem.sensor_delay[b]
        for t in range(run.n_steps):
            k = run.step0 + t
            _record_state(t, b, w, rec)
            # 1. sense
            if run.do_sonar:
                plates_twin(w.theta[b], geo.plate_a, geo.plate_b, geo.normal, geo.lever, pa, pb)
                if w.bulge.shape[1] > 0:  # the curtain bulge (walls.model) on top of the hinge
                    shift_twin(w.bulge[b], geo.normal, pa, pb)
                sonar_twin(pos, yaw, pa, pb, geo.width, geo.length, sp, seed, env, k,
                           (sonar_buf, dist, hit_kind, hit, slot), son, grid, grid_b)
                if sp.update_hz > 0.0:
                    hold_twin(son, mem.sonar_held[b], k, run.dt, sp.update_hz, sp.update_phase)
                if lags[LAG_SONAR] > 0:
                    delay_twin(son, delay, delay_cols[LAG_SONAR], k, lags[LAG_SONAR])
            if run.do_down:
                down_twin(alt, sp, seed, env, k, down)
            if run.do_ranging:
                ranging_twin(pos, beacons, seed, env, k, rp, rng, grid, grid_b, fill)
                if lags[LAG_RANGING] > 0:
                    delay_twin(rng, delay, delay_cols[LAG_RANGING], k, lags[LAG_RANGING])
            if run.do_imu:
                imu_twin(w.acc[b], yaw, w.yaw_rate[b], mem.bias[b], ip, seed, env, k, imu_a, imu_g)
                if lags[LAG_IMU] > 0:
                    delay_twin(imu_a, delay, delay_cols[LAG_IMU], k, lags[LAG_IMU])
                    delay_twin(imu_g.reshape((N, 1)), delay, delay_cols[LAG_IMU] + 2, k, lags[LAG_IMU])
                dead_reckon_twin(imu_a, imu_g, wp.dt, mem.dr_pos[b], mem.dr_vel[b], mem.dr_yaw[b])
            # 2. behave
            if run.do_sonar:
                wall_check_twin(son, rng, wp, fail_buf, mem.fail_count[b], mem.wall[b], mem.anchor[b], mem.dr_pos[b],
                               mem.dr_yaw[b], mem.wall_onsets[b], mem.wall_readings[b], (pos, grid, grid_b, near_on))
            if run.kind == KIND_ATTRACTION:
                attraction_twin(son, mem.wall[b], seed, env, k, ap, cmd_body, cmd_w)
                body_to_world_twin(yaw, cmd_body, cmd_v)
            elif run.kind == KIND_RANDOM_WALK:
                random_walk_twin(pos, seed, env, k, rw, cmd_v, cmd_w)
            _record_step(t, b, rec, son, dist, hit_kind, mem.wall[b], down, rng, imu_a, imu_g, cmd_v, cmd_w)
            # 3. step
            step_twin(w, b, cmd_v, cmd_w, cp, hp, geo, run.dt, dist_buf, gap_buf, grid, grid_b)


#: rollouts of fewer copter-steps (B · N · T) than this run on the calling thread alone: handing a share to another
#: thread costs ≈ 0.15 ms (:mod:`finkensim.kernels.threads`), the work of ≈ 100 copter-steps of the full workload
PARALLEL_MIN_COPTER_STEPS = 1024


def swarm_rollout(w, mem, run, rec, cp, hp, geo, sp, rp, beacons, ip, rw, ap, wp, grid):
    """``run.n_steps`` steps of the closed loop for the B environments of ``w``/``mem``, in place: the environments
    split over numba's threads (:func:`~finkensim.kernels.threads.run_ranges`) when the call has at least
    :data:`PARALLEL_MIN_COPTER_STEPS` copter-steps, the T loop inside each (:func:`swarm_env`); the same results
    either way. ``rec`` arrays are filled when their leading dimension is n_steps (else 0)."""
    B, N = w.pos.shape[0], w.pos.shape[1]
    run_ranges(swarm_env, B, w, mem, run, rec, cp, hp, geo, sp, rp, beacons, ip, rw, ap, wp, grid,
               parallel=B * N * run.n_steps >= PARALLEL_MIN_COPTER_STEPS)
