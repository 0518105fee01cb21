"""Sonars (ultrasonic range sensors): four horizontal ones (front, left, back, right) and one facing down.

**Geometry.** Sonar k of copter n (k = 0 front, 1 left, 2 back, 3 right) points along the heading
ψ = yaw[n] + mount_yaw[k] (``sonar.yaw_deg``, default 0°, 90°, 180°, −90°) and sits at
``centre + offset · (cos ψ, sin ψ)``. Readings are measured from the sonar. Its ray (or, with
``beam = "cone"``, each of ``beam_rays`` rays spread evenly across ±``cone_half_angle``) meets:

- the displaced wall plates: plate s is the segment ``plate_a[s], plate_b[s]`` shifted along its
  inward normal by ``lever · sin θ[s]`` (:meth:`finkensim.arena.Arena.plate_surfaces`), so a plate
  pulled into the arena shortens the reading by exactly that displacement;
- the rigid arena boundary (the net) at x = 0, x = W, y = 0, y = L, a backstop between and behind
  the plates, so a ray never escapes the arena (computed as the exit of the ray from the rectangle;
  a sonar mounted outside the rectangle sees the net at distance 0);
- every *other* copter's circle (``copters.radius``); a copter never sees its own body.

The ideal reading is the distance to the nearest of these hits (over all rays of the beam). No hit
within ``max_range`` (no echo) → ``max_range``. ``hit_type`` says what was hit (0 none / beyond
range, 1 wall: plate or net, 2 copter) and ``hit_xy`` where (the point of the nearest hit, even if it
lies beyond ``max_range``; only then is ``hit_type`` 0). Ideal distances are *not* clamped to
``min_range`` (for analysis); measured readings are.

**Error model of an echo** (``sonar.error``), true distance d (an echo within range):

``rayleigh`` (default)
    d + sign · (R − s), R ~ Rayleigh(σ) by inversion R = sqrt(−2σ² ln u), s = sqrt((4 − π)/2)·σ
    the Rayleigh standard deviation, sign = ``rayleigh_sign`` (default −1: E[R − s] ≈ +0.598σ, so
    readings run short, as the report says).
``seed``
    The report's rule: d + (R − s), same R and s, sign always +1 (``rayleigh_sign`` ignored).
``gaussian``
    d + N(0, σ²).
``none``
    d.

No echo reads exactly ``max_range`` (a time-out is not a noisy measurement; the original script's
0.2 m for a missing echo is not reproduced).

**Cross-talk** (``sonar.crosstalk``), independent of the error model:

``geometric`` (default)
    Receiver sonar (n, k) hears emitter sonar (m, j) of another copter m ≠ n when (1) the emitter
    lies inside the receiver's cone (angle between the receiver heading and the direction to the
    emitter ≤ ``cone_half_angle``), (2) the receiver lies inside the emitter's cone, (3) copters n
    and m fire in the same slot of the firing schedule, and (4) the path is short enough to arrive
    within the listening window, |e − r| ≤ 2·max_range. The receiver times that one-way path as a
    round trip: the cross-talk reading is |e − r|/2 + N(0, crosstalk_jitter²), from the nearest such
    emitter. The first arrival wins: the reading is min(echo reading, cross-talk reading).
``constant``
    The report's stand-in: with probability ``crosstalk_probability`` (0.68) the reading is replaced
    by d/2 (no error term; d = max_range when there is no echo). This is what ``profile = "seed"``
    uses together with ``error = "seed"``.
``off``
    No cross-talk.

Finally every reading is clamped to [min_range, max_range].

**Firing schedule** (``sonar.schedule``; all four sonars of a copter fire together):
``simultaneous`` → every copter in slot 0; ``round_robin`` → copter n in slot n mod n_slots;
``random_offset`` → slot ⌊u·n_slots⌋ with u the uniform 0 of
``counter_key(seed, env_id, step, n, STREAM_SONAR_SCHEDULE)``.

**Down sonar.** Reads the altitude (``arena.altitude``, or a per-copter array) with the same error
model, no cross-talk, and the same no-echo rule and clamp (an altitude above ``max_range`` reads
``max_range``). Separate output (:func:`down_readings`).

**Random numbers.** All draws of copter n at a step come from
``key = counter_key(seed, env_id, step, n, STREAM_SONAR)``; sonar k (0–3 horizontal, 4 down) uses
``uniform(key, 8k)`` (constant cross-talk coin), ``uniform(key, 8k + 1)`` (Rayleigh u),
``normal(key, 4k + 1)`` (Gaussian error; uniforms 8k + 2, 8k + 3) and ``normal(key, 4k + 2)``
(cross-talk jitter; uniforms 8k + 4, 8k + 5). A reading is thus a function of (seed, env_id, step,
copter, sonar) and the geometry only — never of batch size, thread count or call order.

**Units and shapes.** Metres, radians, leading environment axis B, N copters, S plates:
pos (B, N, 2) m, yaw (B, N) rad, theta (B, S) rad, env_ids (B,) int; horizontal outputs (B, N, 4)
in sonar order front, left, back, right.

**Where the code lives.** The model record :class:`SonarModel` is in
:mod:`finkensim.sensors.sonar_model`; the per-environment kernels (:func:`displaced_plates_env`,
:func:`ideal_env`, :func:`fire_slots_env`, :func:`crosstalk_path`, :func:`measured_reading`,
:func:`sonar_env`, :func:`down_env`) in :mod:`finkensim.sensors.sonar_kernels`; ray casting in
:mod:`finkensim.kernels.raycast`. They are ``inline="always"`` numba functions of arrays, numbers and
the :class:`SonarModel` NamedTuple, so compiled loops (the swarm rollout, the gap replay) call the very
same code with their own work buffers. This module holds the batched Python API; its parallel loops call
outlined copies of the same Python functions (identical results; much shorter compilation).

**Fields beyond the config.** :class:`SonarModel` also has ``range_scale`` (1), ``bias`` (0 m) and
``crosstalk_hear_probability`` (1): an echo reads range_scale · (d + error) + bias, and a
receiver in geometric cross-talk position hears the emitter with that probability (uniform
``8k + 6`` of the cell, drawn only below 1). The defaults change nothing; the gap diagnosis fits them.
``crosstalk`` is a bit set (1 constant, 2 geometric, 3 both).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..arena import shift_plates_env
from ..config import ConfigError
from ..kernels.cellgrid import NO_GRID, no_grid_buffers
from ..kernels.raycast import HIT_COPTER, HIT_NONE, HIT_WALL, cast_ray, cast_ray_culled, plate_bands
from ..kernels.outline import outlined
from .sonar_kernels import (crosstalk_path, displaced_plates_env, down_env, echo_reading, fire_slot, fire_slots_env,
                            ideal_env, measured_reading, shifted_plates_env, sonar_hit, sonar_poses_env,
                            sonar_env)
from .sonar_model import (CROSSTALK_CONSTANT, CROSSTALK_GEOMETRIC, CROSSTALK_OFF, DOWN_SONAR, ERROR_GAUSSIAN,
                          ERROR_NONE, ERROR_RAYLEIGH, ERROR_SEED, N_SONARS, SCHEDULE_RANDOM_OFFSET,
                          SCHEDULE_ROUND_ROBIN, SCHEDULE_SIMULTANEOUS, SonarModel, WallGeometry, rayleigh_std,
                          wall_geometry)

__all__ = [
    "ERROR_NONE", "ERROR_GAUSSIAN", "ERROR_RAYLEIGH", "ERROR_SEED",
    "CROSSTALK_OFF", "CROSSTALK_CONSTANT", "CROSSTALK_GEOMETRIC",
    "SCHEDULE_SIMULTANEOUS", "SCHEDULE_ROUND_ROBIN", "SCHEDULE_RANDOM_OFFSET",
    "HIT_NONE", "HIT_WALL", "HIT_COPTER", "N_SONARS", "DOWN_SONAR",
    "SonarModel", "WallGeometry", "wall_geometry",
    "displaced_plates_env", "shifted_plates_env", "sonar_poses_env", "sonar_hit", "cast_ray", "cast_ray_culled",
    "plate_bands", "ideal_env", "fire_slot", "fire_slots_env", "crosstalk_path", "echo_reading", "measured_reading",
    "sonar_env", "down_env",
    "ideal_sonar", "sonar_readings", "down_readings", "fire_slots",
    "sonar_from_state", "sonar_from_trajectory", "rayleigh_std",
]

# ---------------------------------------------------------------------------------------------
# batched kernels

# Batched kernels call outlined copies of the per-environment kernels (finkensim.kernels.outline): the same code,
# compiled once as a function (its helpers inlined into it) instead of being inlined into every prange body, which
# keeps numba's parallel-loop compilation short.
_ideal_env_fn = outlined(ideal_env)
_sonar_env_fn = outlined(sonar_env)
_down_env_fn = outlined(down_env)


@njit(cache=True, parallel=True)
def _batch(pos, yaw, theta, bulge, geometry, sonar, counters, ideal, out):
    """Rows b of pos/yaw/theta with their own env_ids[b] and steps[b] of counters = (seed, env_ids (B,), steps (B,))
    (so T×B trajectories flatten), the plates moved by bulge (B, S) m along their normals
    (:func:`~finkensim.arena.shift_plates_env`; (B, 0): not); geometry: :class:`WallGeometry`. Ideal values into ideal =
    (dist, kind, hit); also the readings into out (B, N, S) m unless it is empty ((0, N, S): ideal values only).
    Every copter is tested against every ray (no cell grid: the reference the engine's grid is compared with)."""
    B, N, _ = pos.shape
    S = geometry.plate_a.shape[0]
    seed, env_ids, steps = counters
    dist, kind, hit = ideal
    measure = out.shape[0] > 0
    for b in prange(B):
        pa = np.empty((S, 2))
        pb = np.empty((S, 2))
        sonar_buf = np.empty((N, sonar.mount_yaw.shape[0], 4))
        off = NO_GRID
        no = no_grid_buffers()
        displaced_plates_env(theta[b], geometry.plate_a, geometry.plate_b, geometry.normal, geometry.lever, pa, pb)
        if bulge.shape[1] > 0:
            shift_plates_env(bulge[b], geometry.normal, pa, pb)
        if measure:
            _sonar_env_fn(pos[b], yaw[b], (pa, pb, geometry.width, geometry.length), sonar, (seed, env_ids[b], steps[b]),
                               (sonar_buf, dist[b], kind[b], hit[b], np.zeros(N, dtype=np.int64)), out[b], off, no)
        else:
            _ideal_env_fn(pos[b], yaw[b], (pa, pb, geometry.width, geometry.length), sonar, (sonar_buf, dist[b], kind[b], hit[b]), off,
                          no)


@njit(cache=True, parallel=True)
def _down_batch(alt, sonar, seed, env_ids, steps, out):
    for b in prange(alt.shape[0]):
        _down_env_fn(alt[b], sonar, seed, env_ids[b], steps[b], out[b])


@njit(cache=True, parallel=True)
def _slots_batch(sonar, seed, env_ids, step, out):
    for b in prange(out.shape[0]):
        fire_slots_env(seed, env_ids[b], step, sonar, out[b], 0)


# ---------------------------------------------------------------------------------------------
# Python API


def _check_model(params):
    if not isinstance(params, SonarModel):
        raise ConfigError(f"params: expected a SonarModel (SonarModel.from_config(cfg)), got {type(params).__name__}")
    return params


def _check_env_ids(env_ids, B):
    env_ids = np.ascontiguousarray(env_ids, dtype=np.int64)
    if env_ids.ndim == 0:
        env_ids = env_ids.reshape(1)
    if env_ids.ndim != 1 or env_ids.size != B:
        raise ConfigError(f"env_ids has shape {env_ids.shape}: expected ({B},) global environment indices")
    return env_ids


def _check_geometry(pos, yaw, theta, geom):
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ConfigError(f"pos has shape {pos.shape}: expected (B, N, 2) m")
    B, N, _ = pos.shape
    yaw = np.ascontiguousarray(yaw, dtype=np.float64)
    if yaw.shape != (B, N):
        raise ConfigError(f"yaw has shape {yaw.shape}: expected (B, N) = ({B}, {N}) rad")
    S = geom.plate_a.shape[0]
    theta = np.ascontiguousarray(theta, dtype=np.float64)
    if theta.shape != (B, S):
        raise ConfigError(f"theta has shape {theta.shape}: expected (B, S) = ({B}, {S}) rad")
    return pos, yaw, theta


def ideal_sonar(pos, yaw, theta, arena, params: SonarModel):
    """Ideal horizontal sonar readings (no error, no cross-talk, not clamped to min_range).

    Args:
        pos: (B, N, 2) copter centres, m.
        yaw: (B, N) headings, rad.
        theta: (B, S) plate hinge angles, rad.
        arena: :class:`~finkensim.arena.Arena` (or :class:`WallGeometry`).
        params: :class:`SonarModel`.

    Returns:
        (dist, hit_type, hit_xy): dist (B, N, 4) m, the distance from each sonar to its nearest hit, max_range
        if none within range; hit_type (B, N, 4) int64, 0 none (no echo within range), 1 wall (plate or net),
        2 copter; hit_xy (B, N, 4, 2) m, the nearest hit point (also when beyond range, where hit_type is 0).
        Sonar order: front, left, back, right.
    """
    sonar = _check_model(params)
    geometry = wall_geometry(arena)
    pos, yaw, theta = _check_geometry(pos, yaw, theta, geometry)
    B, N, _ = pos.shape
    S_ = sonar.n_sonars
    dist = np.empty((B, N, S_))
    kind = np.empty((B, N, S_), dtype=np.int64)
    hit = np.empty((B, N, S_, 2))
    none = np.zeros(B, dtype=np.int64)
    _batch(pos, yaw, theta, np.zeros((B, 0)), geometry, sonar, (0, none, none), (dist, kind, hit), np.empty((0, N, S_)))
    return dist, kind, hit


def sonar_readings(pos, yaw, theta, arena, params: SonarModel, seed: int, env_ids, step: int,
                        return_ideal: bool = False, bulge=None):
    """Measured horizontal sonar readings of B environments at world step ``step``.

    Arguments as :func:`ideal_sonar`, plus seed, env_ids (B,) global environment indices and step
    (``WorldState.step``), which key the random numbers; ``bulge`` (B, S) m: the plates' curtain bulge
    (``WorldState.bulge``, walls.model), None for none.

    Returns:
        readings (B, N, 4) m in [min_range, max_range] (front, left, back, right); with
        ``return_ideal=True`` the tuple (readings, dist, hit_type, hit_xy) of :func:`ideal_sonar`.
    """
    sonar = _check_model(params)
    geometry = wall_geometry(arena)
    pos, yaw, theta = _check_geometry(pos, yaw, theta, geometry)
    B, N, _ = pos.shape
    env_ids = _check_env_ids(env_ids, B)
    steps = np.full(B, int(step), dtype=np.int64)
    S_ = sonar.n_sonars
    dist = np.empty((B, N, S_))
    kind = np.empty((B, N, S_), dtype=np.int64)
    hit = np.empty((B, N, S_, 2))
    out = np.empty((B, N, S_))
    shift = np.zeros((B, 0)) if bulge is None else np.ascontiguousarray(bulge, dtype=np.float64).reshape(B, -1)
    _batch(pos, yaw, theta, shift, geometry, sonar, (int(seed), env_ids, steps), (dist, kind, hit), out)
    if return_ideal:
        return out, dist, kind, hit
    return out


def down_readings(pos, params: SonarModel, seed: int, env_ids, step: int, altitude=None):
    """Down-sonar readings (B, N) m: the altitude with the error model, no cross-talk, clamped.

    pos (B, N, 2) m gives the shape (B, N); ``altitude`` (m, scalar or (B, N)) defaults to
    ``params.altitude``. Random numbers: sonar index 4 of each copter's STREAM_SONAR cell.
    """
    sonar = _check_model(params)
    pos = np.asarray(pos)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ConfigError(f"pos has shape {pos.shape}: expected (B, N, 2) m")
    B, N, _ = pos.shape
    alt = sonar.altitude if altitude is None else altitude
    alt = np.ascontiguousarray(np.broadcast_to(np.asarray(alt, dtype=np.float64), (B, N)))
    env_ids = _check_env_ids(env_ids, B)
    out = np.empty((B, N))
    _down_batch(alt, sonar, int(seed), env_ids, np.full(B, int(step), dtype=np.int64), out)
    return out


def fire_slots(params: SonarModel, seed: int, env_ids, step: int, n_copters: int):
    """Firing slot of every copter, (B, N) int64 in [0, n_slots) (0 for ``simultaneous``)."""
    sonar = _check_model(params)
    env_ids = np.ascontiguousarray(env_ids, dtype=np.int64).reshape(-1)
    out = np.empty((env_ids.size, int(n_copters)), dtype=np.int64)
    _slots_batch(sonar, int(seed), env_ids, int(step), out)
    return out


def sonar_from_state(state, arena, params: SonarModel, return_ideal: bool = False):
    """:func:`sonar_readings` of a :class:`~finkensim.world.WorldState` (its pos, yaw, theta, seed,
    env_ids, step and bulge)."""
    return sonar_readings(state.pos, state.yaw, state.theta, arena, params, state.seed, state.env_ids,
                               state.step, return_ideal=return_ideal, bulge=state.bulge)


def sonar_from_trajectory(traj, arena, params: SonarModel, seed: int, env_ids, step0: int,
                               return_ideal: bool = False):
    """Readings along a recorded :class:`~finkensim.world.Trajectory` (pose (T, B, N, 3), theta (T, B, S)).

    Sample t uses the random numbers of step ``step0 + t``, so this equals calling
    :func:`sonar_readings` on each recorded state. Returns readings (T, B, N, 4) m (and, with
    ``return_ideal``, dist (T, B, N, 4), hit_type (T, B, N, 4), hit_xy (T, B, N, 4, 2)).
    """
    sonar = _check_model(params)
    geometry = wall_geometry(arena)
    pose = np.asarray(traj.pose, dtype=np.float64)
    if pose.ndim != 4 or pose.shape[3] != 3:
        raise ConfigError(f"traj.pose has shape {pose.shape}: expected (T, B, N, 3)")
    T, B, N, _ = pose.shape
    S = geometry.plate_a.shape[0]
    theta = np.asarray(traj.theta, dtype=np.float64)
    if theta.shape != (T, B, S):
        raise ConfigError(f"traj.theta has shape {theta.shape}: expected (T, B, S) = ({T}, {B}, {S})")
    env_ids = _check_env_ids(env_ids, B)
    pos = np.ascontiguousarray(pose[..., :2].reshape(T * B, N, 2))
    yaw = np.ascontiguousarray(pose[..., 2].reshape(T * B, N))
    th = np.ascontiguousarray(theta.reshape(T * B, S))
    ids = np.ascontiguousarray(np.tile(env_ids, T))
    steps = np.ascontiguousarray(np.repeat(int(step0) + np.arange(T, dtype=np.int64), B))
    S_ = sonar.n_sonars
    dist = np.empty((T * B, N, S_))
    kind = np.empty((T * B, N, S_), dtype=np.int64)
    hit = np.empty((T * B, N, S_, 2))
    out = np.empty((T * B, N, S_))
    _batch(pos, yaw, th, np.zeros((T * B, 0)), geometry, sonar, (int(seed), ids, steps), (dist, kind, hit), out)
    out = out.reshape(T, B, N, S_)
    if return_ideal:
        return (out, dist.reshape(T, B, N, S_), kind.reshape(T, B, N, S_),
                hit.reshape(T, B, N, S_, 2))
    return out
