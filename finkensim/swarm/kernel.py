"""The compiled closed loop: T steps of sense → behave → step for B environments in one numba kernel.

:func:`swarm_rollout` splits the environments over numba's threads (the behaviour's :func:`engine_for` on each
share, a ``nogil`` kernel: :mod:`finkensim.kernels.threads`) with the T loop inside, work buffers allocated once per
environment, no Python per step. The loop body calls outlined copies of the per-environment kernels (the same
Python functions compiled as functions, :mod:`finkensim.kernels.outline`): identical results, and a cold compilation
of ≈ 20 s instead of about a minute with everything inlined.

The kernels take a handful of NamedTuple records: :class:`~finkensim.swarm.state.SwarmState` (the world state,
IMU bias and behaviour memory), :class:`~finkensim.swarm.state.RunSpec`
(seed, steps, enabled sensors), :class:`~finkensim.swarm.state.SwarmRecord` (outputs) and
:class:`~finkensim.swarm.state.Models` (every model, the behaviour's parameters included).

**One loop per behaviour.** The behaviour is a registered plug-in (:mod:`finkensim.behaviours.registry`) whose
``commands`` kernel the loop calls at every step. :func:`engine_for` compiles the loop's code (:func:`_swarm_env`)
once per behaviour with that kernel bound as a global, named ``swarm_env_<name>``: numba inlines and optimises the
call like any callee (a dispatcher passed as an *argument* would work too, but numba's on-disk cache never hits
for it — the argument's type holds the dispatcher object, new in each process — so every process would compile the
loop again and add an entry to the cache index). Built-in behaviours' loops are cached on disk; a user's behaviour
(``cached=False``) compiles in each process.
"""
from __future__ import annotations

import types

import numpy as np
from numba import njit

from ..behaviours.attraction import body_to_world_env
from ..behaviours.registry import BehaviourInput
from ..behaviours.wall_check import WALL_CHECK_NONE, dead_reckon_env, wall_check_env
from ..sensors.latency import LAG_RANGING
from ..kernels.cellgrid import env_grid
from ..kernels.threads import run_ranges
from ..kernels.outline import INTERNAL, outlined
from ..world import step_env
from .sense import sense_buffers, sense_env

__all__ = ["engine_for", "swarm_rollout", "PARALLEL_MIN_COPTER_STEPS", "dead_reckon_outlined", "wall_check_outlined",
           "body_to_world_outlined", "step_outlined"]


# the per-environment kernels of behave and step as called functions (finkensim.kernels.outline); control.py calls
# some of them too
dead_reckon_outlined = outlined(dead_reckon_env)
wall_check_outlined = outlined(wall_check_env)
body_to_world_outlined = outlined(body_to_world_env)
step_outlined = outlined(step_env)


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
def _record_step(t, b, rec, buf, wall_b, cmd_v, cmd_w):
    """What environment b sensed and commanded at step t → rec, where recorded. buf: its
    :class:`~finkensim.swarm.sense.SenseBuffers`; wall_b (N, 4) bool; cmd_v (N, 2) m/s; cmd_w (N,) rad/s."""
    for n in range(buf.sonar.shape[0]):
        for j in range(buf.sonar.shape[1]):
            if rec.sonar.shape[0] > 0:
                rec.sonar[t, b, n, j] = buf.sonar[n, j]
            if rec.sonar_ideal.shape[0] > 0:
                rec.sonar_ideal[t, b, n, j] = buf.sonar_ideal[n, j]
            if rec.sonar_hit.shape[0] > 0:
                rec.sonar_hit[t, b, n, j] = buf.sonar_hit[n, j]
            if rec.wall.shape[0] > 0:
                rec.wall[t, b, n, j] = wall_b[n, j]
        if rec.sonar_down.shape[0] > 0:
            rec.sonar_down[t, b, n] = buf.sonar_down[n]
        if rec.ranging.shape[0] > 0:
            for j in range(buf.ranging.shape[1]):
                rec.ranging[t, b, n, j] = buf.ranging[n, j]
        if rec.imu_acc.shape[0] > 0:
            rec.imu_acc[t, b, n, 0] = buf.imu_acc[n, 0]
            rec.imu_acc[t, b, n, 1] = buf.imu_acc[n, 1]
        if rec.imu_gyro.shape[0] > 0:
            rec.imu_gyro[t, b, n] = buf.imu_gyro[n]
        if rec.cmd_vel.shape[0] > 0:
            rec.cmd_vel[t, b, n, 0] = cmd_v[n, 0]
            rec.cmd_vel[t, b, n, 1] = cmd_v[n, 1]
        if rec.cmd_yaw_rate.shape[0] > 0:
            rec.cmd_yaw_rate[t, b, n] = cmd_w[n]


#: placeholders of the globals :func:`engine_for` binds in each behaviour's copy of :func:`_swarm_env`
behaviour_commands = None
BODY_FRAME = False


def _swarm_env(span, state, run, rec, models, params, grid):
    """``run.n_steps`` steps of the closed loop for environments span[0] … span[1] − 1, one after another, in place
    (one thread's share of :func:`swarm_rollout`; releases the GIL). Each step k: 1. sense
    (:func:`~finkensim.swarm.sense.sense_env`), 2. behave (dead reckoning, the wall check, then the behaviour's
    ``behaviour_commands``, rotated to the world frame when ``BODY_FRAME``), 3. :func:`~finkensim.world.step_env`.
    grid: the copter-copter cell grid of the batch (:class:`~finkensim.kernels.cellgrid.EngineGrid`); params: the behaviour's parameter record.

    The template of :func:`engine_for` (never compiled itself). The environment loop is here, not in a caller:
    numba links every callee's code into its caller and optimizes it again, so each level of calls above the engine
    costs seconds of cold compile."""
    world = state.world
    memory = state.behaviour
    N = world.pos.shape[1]
    R = N + models.beacons.shape[0]
    wall_check = models.wall_check
    seed = run.seed
    # the wall check may look up each copter's ranging columns in range on the grid when the ranging ran on it
    # (not with a ranging latency: the delayed rows are not those of the current positions' grid)
    near_on = run.do_ranging and grid.on and wall_check.ranging_max_range == models.ranging.max_range \
        and run.lags[LAG_RANGING] == 0
    # then the wall check reads only the columns in range, so unless the readings are recorded the rest of each
    # ranging row need not be written at every step
    fill = rec.ranging.shape[0] > 0 or not near_on
    for b in range(span[0], span[1]):
        env = run.env_ids[b]
        pos = world.pos[b]
        yaw = world.yaw[b]
        # the N × (N + M) ranging rows only when something reads them (the ranging itself, or a wall check, which
        # reads zeros with the ranging off): 800 MB per environment at N = 10 000. With the ranging on, every entry
        # read is written first at each step (all of them, or those in range: see `fill` above), so the rows need no
        # zeroing, and they are the caller's buffer, kept between rollouts (fresh pages cost the operating system's
        # zeroing of all of them on first touch: ≈ 0.2 s per call at N = 10 000, the work of three steps)
        if run.do_ranging:
            ranging = run.ranging_rows[b]
        else:
            ranging = np.zeros((N, R)) if run.do_sonar and wall_check.mode != WALL_CHECK_NONE else np.zeros((N, 0))
        # work buffers, once per environment
        buf = sense_buffers(np.full((N, 4), models.sonar.max_range), ranging, np.zeros((N, 2)), np.zeros(N), models,
                            fill)
        fail_buf = np.zeros((N, 4), dtype=np.bool_)
        cmd_body = np.zeros((N, 2))
        cmd_v = np.zeros((N, 2))
        cmd_w = np.zeros(N)
        dist_buf = np.empty(models.geometry.seg_a.shape[0])
        gap_buf = np.empty(N)
        cells = env_grid(grid, b)
        for t in range(run.n_steps):
            k = run.step0 + t
            _record_state(t, b, world, rec)
            # 1. sense
            sense_env(b, k, state, run, models, buf, grid, cells)
            # 2. behave
            if run.do_imu:
                dead_reckon_outlined(buf.imu_acc, buf.imu_gyro, wall_check.dt, memory.dr_pos[b], memory.dr_vel[b],
                                 memory.dr_yaw[b])
            if run.do_sonar:
                wall_check_outlined(buf.sonar, ranging, wall_check, fail_buf, memory, b, (pos, grid, cells, near_on))
            inputs = BehaviourInput(pos, yaw, buf.sonar, memory.wall[b], buf.sonar_down, ranging, buf.imu_acc,
                                    buf.imu_gyro, seed, env, k, run.dt)
            if BODY_FRAME:
                behaviour_commands(inputs, params, memory.commands[b], cmd_body, cmd_w)
                body_to_world_outlined(yaw, cmd_body, cmd_v)
            else:
                behaviour_commands(inputs, params, memory.commands[b], cmd_v, cmd_w)
            _record_step(t, b, rec, buf, memory.wall[b], cmd_v, cmd_w)
            # 3. step
            step_outlined(world, b, cmd_v, cmd_w, (models.copter, models.hinge, models.geometry), run.dt,
                      (dist_buf, gap_buf), grid, cells)


_ENGINES: dict = {}


def engine_for(behaviour):
    """The compiled closed loop of ``behaviour`` (a :class:`~finkensim.behaviours.registry.Behaviour`): a copy of
    :func:`_swarm_env` named ``swarm_env_<name>`` with ``behaviour_commands`` bound to its ``commands`` kernel,
    ``@njit(nogil=True)``, cached on disk when ``behaviour.cached`` (module doc). One per behaviour and process.

    Parameters
    ----------
    behaviour : Behaviour
        The registered plug-in.

    Returns
    -------
    numba dispatcher
        ``engine(span, state, run, rec, models, params, grid)`` (as :func:`_swarm_env`; params: the
        behaviour's parameter record).
    """
    key = (behaviour.name, id(behaviour.commands), behaviour.frame, behaviour.cached)
    engine = _ENGINES.get(key)
    if engine is None:
        f = _swarm_env
        name = f"swarm_env_{behaviour.name}"
        # its commands as a called function without Python wrappers (which the loop would link in and optimise again)
        commands = outlined(behaviour.commands, cache=behaviour.cached)
        scope = dict(f.__globals__, behaviour_commands=commands, BODY_FRAME=behaviour.frame == "body")
        g = types.FunctionType(f.__code__, scope, name, f.__defaults__, f.__closure__)
        g.__qualname__ = name
        g.__module__ = f.__module__
        g.__doc__ = f.__doc__
        # called from Python only: no C callback wrapper
        engine = _ENGINES[key] = njit(cache=behaviour.cached, nogil=True, no_cfunc_wrapper=True)(g)
    return engine


#: rollouts of fewer copter-steps (B · N · T) than this run on the calling thread alone: handing a share to another
#: thread costs ≈ 0.15 ms (:mod:`finkensim.kernels.threads`), the work of ≈ 100 copter-steps of the full workload
PARALLEL_MIN_COPTER_STEPS = 1024


def swarm_rollout(state, run, rec, models, grid, behaviour, params):
    """``run.n_steps`` steps of the closed loop for the B environments of ``world``/``memory``, in place.

    The environments split over numba's threads (:func:`~finkensim.kernels.threads.run_ranges`) when the call has
    at least :data:`PARALLEL_MIN_COPTER_STEPS` copter-steps, the T loop inside each (:func:`engine_for`); the same
    results either way.

    Parameters
    ----------
    state : SwarmState
        World, IMU bias and behaviour memory of B environments (``memory=None``: ``SwarmState.for_kernels``),
        changed in place.
    run : RunSpec
        Seed, environments, steps, enabled sensors.
    rec : SwarmRecord
        Output arrays, filled when their leading dimension is ``run.n_steps`` (else 0).
    models : Models
        Every model of the world and the sensors.
    grid : EngineGrid
        The batch's copter-copter cell grid.
    behaviour : Behaviour
        The registered behaviour to fly.
    params : NamedTuple
        Its parameter record (``behaviour.params(cfg)``).
    """
    B, N = state.world.pos.shape[0], state.world.pos.shape[1]
    run_ranges(engine_for(behaviour), B, state, run, rec, models, params, grid,
               parallel=B * N * run.n_steps >= PARALLEL_MIN_COPTER_STEPS)
