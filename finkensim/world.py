"""The batched world: state as arrays with a leading environment axis, pure ``init``/``step``.

``World(cfg)`` holds what never changes during a run (arena geometry, model parameters).
``WorldState`` holds what does, as arrays shaped ``(B, N, ...)`` for copters and ``(B, S)``
for wall plates (B environments, N copters, S plates). One code path serves B = 1 and
B = 10 000: every kernel loops over the environment axis with ``prange``, and all randomness
is keyed by (seed, env_id, step, copter, stream), so environment k of a batch is bit-identical
to a single run with ``env_ids=[k]``.

    world = World(load_config())
    state = world.init(n_envs=64, seed=1)
    state = world.step(state, cmd_vel, cmd_yaw_rate)       # pure: returns a new state
    final, traj = world.rollout(state, 1200, controller)   # controller(world, state) -> commands, per step

The world is physics only: it moves copters and plates given commands and knows no behaviour. The
compiled closed loop (sensors → behaviour → :func:`step_env`) is :class:`finkensim.swarm.SwarmSim`;
ready-made open-loop controllers for :meth:`World.rollout` are in :mod:`finkensim.behaviours.open_loop`.

Kernels take the state and the static model as flat NamedTuple records: :class:`WorldState` itself (one record
for Python and numba), :class:`~finkensim.copters.CopterParams` (body), :class:`~finkensim.arena.HingeParams`
(hinges) and :class:`~finkensim.arena.WallGeometry` (wall segments and plates).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
from numba import njit, prange

from .arena import Arena, HingeParams, bulge_step_env, initial_bulge, walls_step_env, wall_geometry
from .config import Config, ConfigError, load_config
from .copters import CopterParams, move_copter, update_contacts_env
from .kernels.cellgrid import engine_grid, env_grid, grid_params
from .kernels.geometry import nearest_body_distance_env, nearest_body_distance_within_env
from .kernels.rng import STREAM_INIT, counter_key, uniform
from .kernels.threads import run_ranges


@njit(cache=True)
def walls_from_positions(pos, t, seg_a, seg_b, radius, hinge, lever, theta_out, dist_out):
    """Plate angles theta_out (T, S) rad of walls driven by given (e.g. logged) copter positions pos (T, N, 2) m at
    times t (T,) s, as in a simulation (sample k holds the plates after responding to the positions of samples
    1 … k), and each plate's distance to the nearest copter body dist_out (T, S) m. The gap diagnosis replays logged
    flights with it; the importer's clock estimate too."""
    T = pos.shape[0]
    S = seg_a.shape[0]
    theta = np.zeros(S)
    omega = np.zeros(S)
    integ = np.zeros(S)
    dist = np.empty(S)
    for k in range(T):
        nearest_body_distance_env(seg_a, seg_b, pos[k], radius, dist)
        if k > 0:
            walls_step_env(theta, omega, integ, dist, hinge, lever, t[k] - t[k - 1])
        for s in range(S):
            theta_out[k, s] = theta[s]
            dist_out[k, s] = dist[s]



class WorldState(NamedTuple):
    """Everything that changes during a run, as one record for Python and the kernels (numba takes it as it is;
    kernels index environment b as ``w.pos[b]``). Arrays are owned by this state (never aliased); a changed copy
    is ``state._replace(step=...)``.

    Attributes:
        pos: (B, N, 2) copter positions, m.
        vel: (B, N, 2) velocities in the world frame, m/s.
        acc: (B, N, 2) the world-frame acceleration applied in the last step, m/s².
        yaw: (B, N) headings in [−π, π), rad.
        yaw_rate: (B, N) yaw rates, rad/s.
        theta: (B, S) plate hinge angles (positive into the arena), rad.
        omega: (B, S) plate angular velocities, rad/s.
        integ: (B, S) the hinge PID's integral, rad·s.
        in_wall: (B, N) bool, in contact with a wall now.
        in_collision: (B, N) bool, in contact with another copter now.
        wall_contacts: (B, N) int64, wall-contact onsets counted since init.
        collisions: (B, N) int64, collision onsets counted since init.
        step: steps taken since init (int).
        seed: the random seed (int).
        env_ids: (B,) int64 global environment indices.
    """

    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    yaw: np.ndarray
    yaw_rate: np.ndarray
    theta: np.ndarray
    omega: np.ndarray
    integ: np.ndarray
    in_wall: np.ndarray
    in_collision: np.ndarray
    wall_contacts: np.ndarray
    collisions: np.ndarray
    step: int
    seed: int
    env_ids: np.ndarray
    bulge: np.ndarray  # (B, S) m each plate's curtain bulge toward the arena ((B, 0): no bulge, walls.model)

    @property
    def n_envs(self) -> int:
        """B, the number of environments."""
        return self.pos.shape[0]

    @property
    def n_copters(self) -> int:
        """N, copters per environment."""
        return self.pos.shape[1]

    @property
    def pose(self) -> np.ndarray:
        """(B, N, 3): x, y, yaw."""
        return np.concatenate([self.pos, self.yaw[..., None]], axis=-1)

    def arrays(self) -> "WorldState":
        """The state itself: it is the kernels' record (for callers of the former paired ``WorldArrays``)."""
        return self

    def copy(self) -> "WorldState":
        """Copies of every array."""
        return WorldState(*(v.copy() if isinstance(v, np.ndarray) else v for v in self))

    def select(self, envs) -> "WorldState":
        """The sub-batch of environments ``envs`` (index array or slice), as an independent state."""
        return WorldState(*(np.ascontiguousarray(v[envs]) if isinstance(v, np.ndarray) else v for v in self))


@dataclass(frozen=True)
class Trajectory:
    """States recorded by :meth:`World.rollout` *before* each step: sample k is at time (step0 + k)·dt.

    pose (T, B, N, 3); vel, acc (T, B, N, 2); yaw_rate (T, B, N); theta (T, B, S); t (T,) s.
    """

    t: np.ndarray
    pose: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    yaw_rate: np.ndarray
    theta: np.ndarray


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def step_env(w, b, cmd_v, cmd_w, bodies, dt, work, grid, cells):
    """Advance environment b of the :class:`WorldState` ``w`` by dt s in place: copters move, contacts
    are counted, plates respond.

    cmd_v (N, 2) m/s world frame and cmd_w (N,) rad/s are environment b's commands; bodies = (copter
    :class:`~finkensim.copters.CopterParams`, hinge :class:`~finkensim.arena.HingeParams`, geometry
    :class:`~finkensim.arena.WallGeometry`); work = (dist_buf (S,), gap_buf (N,)): work buffers; grid (an
    :class:`~finkensim.kernels.cellgrid.EngineGrid`) and cells (this environment's buffers of it,
    :func:`~finkensim.kernels.cellgrid.env_grid`) serve the copter contacts. The plates need the
    nearest-body distance only below max(threshold, lever): farther, a plate is inactive and its
    contact cap is 90° whatever the distance, so dist_buf holds the exact distances below that and inf
    above (:func:`~finkensim.kernels.geometry.nearest_body_distance_within_env`).
    """
    copter, hinge, geometry = bodies
    dist_buf, gap_buf = work
    pos = w.pos[b]
    vel = w.vel[b]
    acc = w.acc[b]
    yaw = w.yaw[b]
    yaw_rate = w.yaw_rate[b]
    for n in range(pos.shape[0]):
        yaw[n], yaw_rate[n], gap_buf[n] = move_copter(
            pos[n], vel[n], yaw[n], yaw_rate[n], acc[n], cmd_v[n], cmd_w[n], copter, dt)
    update_contacts_env(pos, copter.radius, gap_buf, w.in_wall[b], w.wall_contacts[b], w.in_collision[b],
                        w.collisions[b], grid, cells)
    cutoff = max(hinge.threshold, geometry.lever, hinge.bulge_cutoff)  # the bulge's (0 without one) reaches farther
    nearest_body_distance_within_env(geometry.seg_a, geometry.seg_b, pos, copter.radius, cutoff, dist_buf)
    walls_step_env(w.theta[b], w.omega[b], w.integ[b], dist_buf, hinge, geometry.lever, dt)
    if w.bulge.shape[1] > 0:
        bulge_step_env(w.bulge[b], dist_buf, hinge, dt, False)


@njit(cache=True, parallel=True)
def _step_batch(w, cmd_v, cmd_w, copter, hinge, geometry, dt, grid):
    """One step of every environment of ``w`` (:class:`WorldState`) in place; cmd_v (B, N, 2), cmd_w (B, N);
    grid: the :class:`~finkensim.kernels.cellgrid.EngineGrid` of the batch."""
    for b in prange(w.pos.shape[0]):
        dist_buf = np.empty(geometry.seg_a.shape[0])
        gap_buf = np.empty(w.pos.shape[1])
        step_env(w, b, cmd_v[b], cmd_w[b], (copter, hinge, geometry), dt, (dist_buf, gap_buf), grid, env_grid(grid, b))


@njit(cache=True, nogil=True)
def _init_positions(span, seed, env_ids, n, width, length, radius, min_sep, pos, yaw):
    """Uniform random placement at least ``min_sep`` apart (relaxed by half after 2000 failed tries) of environments
    span[0] … span[1] − 1 (:func:`~finkensim.kernels.threads.run_ranges` splits them over threads: a ``prange`` here
    cost a second of cold compile for a kernel that runs once per ``init``)."""
    for b in range(span[0], span[1]):
        sep = min_sep
        for i in range(n):
            key = counter_key(seed, env_ids[b], 0, i, STREAM_INIT)
            attempt = 0
            while True:
                x = radius + (width - 2 * radius) * uniform(key, 2 * attempt + 1)
                y = radius + (length - 2 * radius) * uniform(key, 2 * attempt + 2)
                ok = True
                for j in range(i):
                    dx = x - pos[b, j, 0]
                    dy = y - pos[b, j, 1]
                    if dx * dx + dy * dy < sep * sep:
                        ok = False
                        break
                attempt += 1
                if ok:
                    break
                if attempt % 2000 == 0:
                    sep *= 0.5
            pos[b, i, 0] = x
            pos[b, i, 1] = y
            yaw[b, i] = 2.0 * np.pi * uniform(key, 0) - np.pi


class World:
    """Static part of a simulation (config, arena geometry, kernel parameters) and its pure functions.
    Physics only: commands in, new state out; no behaviour, no sensor.

    Parameters
    ----------
    cfg : Config, str, dict or None
        A :class:`~finkensim.config.Config`, a TOML path or text, a dict, or None for the defaults.

    Attributes
    ----------
    cfg : Config
        The validated configuration.
    arena : Arena
        The arena and its walls (:class:`~finkensim.arena.Arena`).
    copter_params : CopterParams
        The copters' kernel record (:class:`~finkensim.copters.CopterParams`).
    hinge_params : HingeParams
        The plates' hinge record (:class:`~finkensim.arena.HingeParams`).
    geometry : WallGeometry
        The plates' rest geometry (:class:`~finkensim.arena.WallGeometry`).
    dt : float
        World step, s.
    """

    def __init__(self, cfg: Config | str | dict | None = None):
        self.cfg = cfg if isinstance(cfg, Config) else load_config(cfg)
        c = self.cfg
        self.arena = Arena.from_config(c.arena, c.walls)
        self.copter_params = CopterParams.from_config(c.copters, c.arena)
        self.hinge_params: HingeParams = self.arena.hinge
        self.geometry = wall_geometry(self.arena)
        self.dt = c.simulation.dt
        #: the copter-copter cell grid (on from ``simulation.grid_min_copters`` copters per environment)
        self.grid = grid_params(c.copters.n, c.arena.width, c.arena.length, 2.0 * c.copters.radius,
                                c.simulation.grid_min_copters)

    @property
    def n_copters(self) -> int:
        """Copters per environment, N (``copters.n``)."""
        return self.cfg.copters.n

    def init(self, n_envs: int | None = None, seed: int | None = None, env_ids=None, positions=None,
             yaw=None) -> WorldState:
        """Initial state: copters at rest, placed at random (or at ``positions``), plates hanging.

        Parameters
        ----------
        n_envs : int, optional
            Number of environments B (default ``simulation.n_envs``; ignored when ``env_ids`` is given).
        seed : int, optional
            Random seed (default ``simulation.seed``).
        env_ids : array_like of int, shape (B,), optional
            Global environment indices that key the randomness (default ``arange(n_envs)``): environment k of
            a batch equals a lone run with ``env_ids=[k]``.
        positions : array_like, shape (B, N, 2), optional
            Copter centres, m, each inside the arena by at least a copter radius (default: random, at least
            ``copters.min_separation`` apart).
        yaw : array_like, shape (B, N), optional
            Headings, rad (default: random).

        Returns
        -------
        WorldState
            The state at step 0.

        Raises
        ------
        ConfigError
            A bad shape, a position outside the arena, or a copter that does not fit in the arena.
        """
        c = self.cfg
        seed = c.simulation.seed if seed is None else int(seed)
        if env_ids is None:
            n_envs = c.simulation.n_envs if n_envs is None else int(n_envs)
            env_ids = np.arange(n_envs, dtype=np.int64)
        env_ids = np.ascontiguousarray(env_ids, dtype=np.int64)
        if env_ids.ndim != 1 or env_ids.size == 0:
            raise ConfigError(f"env_ids has shape {env_ids.shape}: expected a non-empty 1-D array of environment indices")
        if n_envs is not None and n_envs != env_ids.size:
            raise ConfigError(f"n_envs = {n_envs} but env_ids has {env_ids.size} entries")
        B, N, S = env_ids.size, c.copters.n, self.arena.n_plates
        r = c.copters.radius
        if 2 * r >= min(c.arena.width, c.arena.length):
            raise ConfigError(f"copters.radius = {r}: a copter does not fit in the {c.arena.width} x {c.arena.length} m arena")
        pos = np.zeros((B, N, 2))
        yaw0 = np.zeros((B, N))
        run_ranges(_init_positions, env_ids.shape[0], seed, env_ids, N, c.arena.width, c.arena.length, r,
                   c.copters.min_separation, pos, yaw0)
        if N > 1 and positions is None:
            if N <= 200:  # dense pair distances, all environments at once
                d = np.sqrt(((pos[:, :, None, :] - pos[:, None, :, :]) ** 2).sum(-1))
                d[:, np.arange(N), np.arange(N)] = np.inf
                closest = float(d.min())
            else:  # a k-d tree per environment: the check holds for any N
                from scipy.spatial import cKDTree

                closest = min(float(cKDTree(p).query(p, k=2)[0][:, 1].min()) for p in pos)
            if closest < c.copters.min_separation:
                warnings.warn(f"copters.min_separation = {c.copters.min_separation} m could not be met for {N} "
                              f"copters in a {c.arena.width} x {c.arena.length} m arena; the closest start pair "
                              f"is {closest:.3f} m apart", RuntimeWarning, stacklevel=2)
        if positions is not None:
            positions = np.asarray(positions, dtype=float)
            if positions.shape != (B, N, 2):
                raise ConfigError(f"positions has shape {positions.shape}: expected (B, N, 2) = ({B}, {N}, 2)")
            lo = np.array([r, r])
            hi = np.array([c.arena.width - r, c.arena.length - r])
            if not np.all(np.isfinite(positions)) or np.any(positions < lo - 1e-12) or np.any(positions > hi + 1e-12):
                raise ConfigError(f"positions: every copter centre must lie in [{r}, {hi[0]}] x [{r}, {hi[1]}] m")
            pos = positions.copy()
        if yaw is not None:
            yaw = np.asarray(yaw, dtype=float)
            if yaw.shape != (B, N):
                raise ConfigError(f"yaw has shape {yaw.shape}: expected (B, N) = ({B}, {N})")
            yaw0 = yaw.copy()
        return WorldState(
            pos=pos, vel=np.zeros((B, N, 2)), acc=np.zeros((B, N, 2)), yaw=yaw0, yaw_rate=np.zeros((B, N)),
            theta=np.zeros((B, S)), omega=np.zeros((B, S)), integ=np.zeros((B, S)),
            in_wall=np.zeros((B, N), dtype=bool), in_collision=np.zeros((B, N), dtype=bool),
            wall_contacts=np.zeros((B, N), dtype=np.int64), collisions=np.zeros((B, N), dtype=np.int64),
            step=0, seed=seed, env_ids=env_ids, bulge=initial_bulge(self.geometry, self.hinge_params, pos, self.copter_params.radius),
        )

    def check_commands(self, state: WorldState, cmd_vel, cmd_yaw_rate) -> tuple[np.ndarray, np.ndarray]:
        """Validated C-contiguous float64 copies of the commands.

        Parameters
        ----------
        state : WorldState
            The state the commands are for (gives B and N).
        cmd_vel : array_like, broadcastable to (B, N, 2)
            Velocity commands in the world frame, m/s.
        cmd_yaw_rate : array_like, broadcastable to (B, N), or None
            Yaw-rate commands, rad/s (None → 0).

        Returns
        -------
        cmd_vel : ndarray, shape (B, N, 2)
        cmd_yaw_rate : ndarray, shape (B, N)

        Raises
        ------
        ConfigError
            A shape that does not broadcast, or a non-finite command; the message names the argument.
        """
        B, N = state.n_envs, state.n_copters

        def as_array(name, value, shape, unit):
            try:
                arr = np.array(np.broadcast_to(np.asarray(value, dtype=float), shape), dtype=np.float64, order="C")
            except (ValueError, TypeError):
                got = np.shape(value) if np.ndim(value) or np.isscalar(value) else type(value).__name__
                raise ConfigError(f"{name} has shape {got}: expected {shape} (B, N{', 2' if len(shape) == 3 else ''}) "
                                  f"{unit} or broadcastable to it") from None
            if not np.all(np.isfinite(arr)):
                raise ConfigError(f"{name} contains NaN or inf: expected finite commands in {unit}")
            return arr

        if np.ndim(cmd_vel) == 0 or np.shape(cmd_vel)[-1] != 2:
            raise ConfigError(f"cmd_vel has shape {np.shape(cmd_vel)}: expected (B, N, 2) = ({B}, {N}, 2) m/s "
                              "(a velocity vector per copter) or broadcastable to it")
        cmd_vel = as_array("cmd_vel", cmd_vel, (B, N, 2), "m/s")
        cmd_yaw_rate = as_array("cmd_yaw_rate", 0.0 if cmd_yaw_rate is None else cmd_yaw_rate, (B, N), "rad/s")
        return cmd_vel, cmd_yaw_rate

    def step(self, state: WorldState, cmd_vel, cmd_yaw_rate=None) -> WorldState:
        """One step of every environment: a new state; the input state is left untouched.

        Parameters
        ----------
        state : WorldState
            The current state (B environments of N copters).
        cmd_vel : array_like, broadcastable to (B, N, 2)
            Velocity commands in the world frame, m/s.
        cmd_yaw_rate : array_like, broadcastable to (B, N), optional
            Yaw-rate commands, rad/s (default 0).

        Returns
        -------
        WorldState
            The state one step (``dt``) later, with ``step`` advanced by one.
        """
        new = state.copy()
        self.step_inplace(new, cmd_vel, cmd_yaw_rate)
        return new._replace(step=state.step + 1)

    def step_inplace(self, state: WorldState, cmd_vel, cmd_yaw_rate=None) -> None:
        """Like :meth:`step` but mutates ``state``'s arrays (its ``step`` counter is not advanced).

        Parameters
        ----------
        state : WorldState
            The state to advance in place.
        cmd_vel : array_like, broadcastable to (B, N, 2)
            Velocity commands in the world frame, m/s.
        cmd_yaw_rate : array_like, broadcastable to (B, N), optional
            Yaw-rate commands, rad/s (default 0).
        """
        cmd_vel, cmd_yaw_rate = self.check_commands(state, cmd_vel, cmd_yaw_rate)
        _step_batch(state, cmd_vel, cmd_yaw_rate, self.copter_params, self.hinge_params, self.geometry,
                    self.dt, engine_grid(self.grid, state.n_envs, state.n_copters))

    def rollout(self, state: WorldState, n_steps: int, controller: Callable,
                record: bool = True) -> tuple[WorldState, Trajectory | None]:
        """Run ``n_steps`` steps under a Python controller; ``state`` is left unchanged.

        For behaviours compiled with the sensors into one kernel, use :class:`finkensim.swarm.SwarmSim`.

        Parameters
        ----------
        state : WorldState
            The initial state.
        n_steps : int
            Number of steps T (≥ 0).
        controller : callable
            ``controller(world, state) -> (cmd_vel, cmd_yaw_rate)`` with cmd_vel (B, N, 2) m/s and cmd_yaw_rate
            (B, N) rad/s or None, called once per step with the current state (e.g.
            :class:`~finkensim.behaviours.open_loop.RandomWalk`).
        record : bool
            Record the trajectory (default True).

        Returns
        -------
        final : WorldState
            The state after ``n_steps`` steps.
        trajectory : Trajectory or None
            The states recorded *before* each step (T samples), or None when ``record`` is False.
        """
        if not isinstance(n_steps, (int, np.integer)) or isinstance(n_steps, bool) or n_steps < 0:
            raise ConfigError(f"n_steps = {n_steps!r}: expected a non-negative integer")
        if not callable(controller):
            raise ConfigError(f"controller = {controller!r}: expected a callable f(world, state) -> (cmd_vel, "
                              "cmd_yaw_rate); see finkensim.behaviours.open_loop")
        new = state.copy()
        B, N, S, T = state.n_envs, state.n_copters, self.arena.n_plates, int(n_steps)
        shape_t = T if record else 0
        rec = dict(pose=np.empty((shape_t, B, N, 3)), vel=np.empty((shape_t, B, N, 2)),
                   acc=np.empty((shape_t, B, N, 2)), yaw_rate=np.empty((shape_t, B, N)),
                   theta=np.empty((shape_t, B, S)))
        for k in range(T):
            if record:
                rec["pose"][k] = new.pose
                rec["vel"][k], rec["acc"][k] = new.vel, new.acc
                rec["yaw_rate"][k], rec["theta"][k] = new.yaw_rate, new.theta
            cmd_v, cmd_w = controller(self, new)
            self.step_inplace(new, cmd_v, cmd_w)
            new = new._replace(step=new.step + 1)
        traj = None
        if record:
            traj = Trajectory(t=(state.step + np.arange(T)) * self.dt, **rec)
        return new, traj
