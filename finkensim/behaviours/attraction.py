"""The original FINken attraction–repulsion controller, on the copter's own sonar readings.

Copter n treats each horizontal sonar reading r_j (sonar j = front, left, back, right, mounted at
yaw m_j relative to the heading) as an object at p_j = r_j · (cos m_j, sin m_j) in its **body frame**
(x forward, y left) and moves by::

    Δ = w_c · Σ_j p_j · (a·[j not a wall] − b · exp(−|p_j|² / c))  +  w_t · a · target

- a reading at ``max_range`` (no echo) is no object and contributes nothing;
- a reading judged to be a wall by the plausibility check (:mod:`finkensim.behaviours.wall_check`)
  is dropped from attraction and kept for repulsion (only its −b·exp term counts);
- ``target`` is a random body-frame offset of length ``target_distance`` in direction 2π·u, u the
  uniform 0 of ``counter_key(seed, env_id, step // redraw_steps, n, STREAM_BEHAVIOUR)``: redrawn every
  ``redraw_steps`` steps, a function of (seed, environment, epoch, copter) only.

The command is v_body = gain · Δ, scaled down to |v_body| ≤ max_speed, and yaw rate 0. The behaviour
knows nothing of its world pose: turning v_body into the world-frame command the copter model takes
is the flight controller's job (:func:`body_to_world`, done by :class:`finkensim.swarm.SwarmSim`).

Equilibrium of two copters facing each other with ideal sonars in open space: each sees the other at
reading r with Δ ∝ r (a − b e^{−r²/c}) = 0, i.e. r* = sqrt(c · ln(b / a)) (1.4420 m for a = 1, b = 4,
c = 1.5 m²). The sonar measures from the sonar to the other copter's rim, so the copters' centres
settle at d* = r* + radius + offset (1.5920 m with radius 0.15 m, offset 0). The equilibrium is stable:
the swarm term's slope there is 2·a·ln(b/a) > 0 (pulls together beyond r*, pushes apart inside).

Shapes: sonar (B, N, 4) m, wall (B, N, 4) bool; commands (B, N, 2) m/s body frame and (B, N) rad/s.
:func:`attraction_env` is the ``inline="always"`` per-environment kernel for compiled rollouts;
:func:`attraction_repulsion` the batched wrapper. NumPy reference: ``tests/naive/behaviours.py``.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..config import Config, ConfigError
from ..kernels.rng import STREAM_BEHAVIOUR, counter_key, uniform

__all__ = ["AttractionParams", "attraction_env", "attraction_repulsion", "body_to_world_env", "body_to_world",
           "settle_reading", "settle_distance", "random_target_env"]


class AttractionParams(NamedTuple):
    """Attraction–repulsion parameters in SI units, as passed to the kernels.

    a, b, c (m²): the law p (a − b exp(−|p|²/c)); w_c, w_t: weights of the swarm and target terms;
    target_distance m: length of the random target offset; redraw_steps: steps between targets;
    gain 1/s: velocity = gain · Δ; max_speed m/s: speed limit of the command; max_range m: a sonar
    reading ≥ this is "no echo"; mount_cos, mount_sin (4,): cos/sin of the sonar mounting yaws.
    """

    a: float
    b: float
    c: float
    w_c: float
    w_t: float
    target_distance: float
    redraw_steps: int
    gain: float
    max_speed: float
    max_range: float
    mount_cos: np.ndarray
    mount_sin: np.ndarray

    @classmethod
    def from_config(cls, cfg: Config) -> "AttractionParams":
        """From ``cfg.behaviour`` (a, b, c, weights, target, gain), ``cfg.copters.max_speed`` and the sonar
        mounting / range (``cfg.sonar``)."""
        be, so = cfg.behaviour, cfg.sonar
        yaw = np.radians(np.asarray(so.yaw_deg, dtype=np.float64))
        return cls(float(be.ar_a), float(be.ar_b), float(be.ar_c), float(be.w_c), float(be.w_t),
                   float(be.target_distance), int(be.redraw_steps), float(be.gain), float(cfg.copters.max_speed),
                   float(so.max_range), np.ascontiguousarray(np.cos(yaw)), np.ascontiguousarray(np.sin(yaw)))


def settle_reading(a: float = 1.0, b: float = 4.0, c: float = 1.5) -> float:
    """Sonar reading (m) at which one object's attraction and repulsion cancel: sqrt(c ln(b/a))."""
    if not (a > 0 and b > a and c > 0):
        raise ConfigError(f"settle_reading(a={a}, b={b}, c={c}): needs 0 < a < b and c > 0 for an equilibrium")
    return math.sqrt(c * math.log(b / a))


def settle_distance(cfg: Config) -> float:
    """Centre distance (m) at which two facing copters with ideal sonars settle: r* + radius + offset."""
    be = cfg.behaviour
    return settle_reading(be.ar_a, be.ar_b, be.ar_c) + cfg.copters.radius + cfg.sonar.offset


@njit(cache=True, inline="always")
def random_target_env(seed, env_id, step, n, redraw_steps, target_distance):
    """Body-frame random target offset (x, y) m of copter n at this step (redrawn every ``redraw_steps`` steps,
    at ``target_distance`` m; the fields of :class:`AttractionParams`)."""
    key = counter_key(seed, env_id, step // redraw_steps, n, STREAM_BEHAVIOUR)
    phi = 2.0 * np.pi * uniform(key, 0)
    return target_distance * np.cos(phi), target_distance * np.sin(phi)


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def attraction_env(sonar_b, wall_b, seed, env_id, step, attraction, cmd_v, cmd_w):
    """Commands of one environment. sonar_b (N, 4) m, wall_b (N, 4) bool → cmd_v (N, 2) m/s body frame,
    cmd_w (N,) rad/s (always 0)."""
    inv_c = 1.0 / attraction.c
    # the arrays taken out of the record once: reading them from it inside the loop, or passing the record to an
    # inlined function there, costs atomic reference counting on every use
    mount_cos = attraction.mount_cos
    mount_sin = attraction.mount_sin
    for n in range(sonar_b.shape[0]):
        dx = 0.0
        dy = 0.0
        for k in range(sonar_b.shape[1]):
            r = sonar_b[n, k]
            if r >= attraction.max_range:
                continue  # no echo: no object
            px = r * mount_cos[k]
            py = r * mount_sin[k]
            f = -attraction.b * np.exp(-(px * px + py * py) * inv_c)
            if not wall_b[n, k]:
                f += attraction.a
            dx += px * f
            dy += py * f
        tx, ty = random_target_env(seed, env_id, step, n, attraction.redraw_steps, attraction.target_distance)
        vx = attraction.gain * (attraction.w_c * dx + attraction.w_t * attraction.a * tx)
        vy = attraction.gain * (attraction.w_c * dy + attraction.w_t * attraction.a * ty)
        speed = np.sqrt(vx * vx + vy * vy)
        if speed > attraction.max_speed:
            s = attraction.max_speed / speed
            vx *= s
            vy *= s
        cmd_v[n, 0] = vx
        cmd_v[n, 1] = vy
        cmd_w[n] = 0.0


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def body_to_world_env(yaw_b, v_body, v_world):
    """Rotate body-frame vectors (N, 2) by the heading yaw_b (N,) rad into the world frame (N, 2)."""
    for n in range(yaw_b.shape[0]):
        c = np.cos(yaw_b[n])
        s = np.sin(yaw_b[n])
        x = v_body[n, 0]
        y = v_body[n, 1]
        v_world[n, 0] = c * x - s * y
        v_world[n, 1] = s * x + c * y


@njit(cache=True, parallel=True)
def _attraction_batch(sonar, wall, seed, env_ids, step, attraction, cmd_v, cmd_w):
    for b in prange(sonar.shape[0]):
        attraction_env(sonar[b], wall[b], seed, env_ids[b], step, attraction, cmd_v[b], cmd_w[b])


@njit(cache=True, parallel=True)
def _body_to_world_batch(yaw, v_body, v_world):
    for b in prange(yaw.shape[0]):
        body_to_world_env(yaw[b], v_body[b], v_world[b])


def attraction_repulsion(sonar, seed: int, env_ids, step: int, params: AttractionParams, wall=None):
    """Batched attraction–repulsion: (cmd_vel_body (B, N, 2) m/s, cmd_yaw_rate (B, N) rad/s).

    sonar (B, N, 4) m horizontal readings (front, left, back, right); wall (B, N, 4) bool, readings
    judged to be walls (default: none); seed, env_ids (B,), step key the random targets.
    """
    if not isinstance(params, AttractionParams):
        raise ConfigError(f"params: expected AttractionParams (AttractionParams.from_config(cfg)), got "
                          f"{type(params).__name__}")
    sonar = np.ascontiguousarray(sonar, dtype=np.float64)
    if sonar.ndim != 3 or sonar.shape[2] != params.mount_cos.shape[0]:
        raise ConfigError(f"sonar has shape {sonar.shape}: expected (B, N, {params.mount_cos.shape[0]}) m")
    B, N, K = sonar.shape
    wall = np.zeros((B, N, K), dtype=np.bool_) if wall is None else np.ascontiguousarray(wall, dtype=np.bool_)
    if wall.shape != sonar.shape:
        raise ConfigError(f"wall has shape {wall.shape}: expected {sonar.shape} like sonar")
    env_ids = np.ascontiguousarray(env_ids, dtype=np.int64).reshape(-1)
    if env_ids.size != B:
        raise ConfigError(f"env_ids has shape {env_ids.shape}: expected ({B},) environment indices")
    cmd_v = np.empty((B, N, 2))
    cmd_w = np.empty((B, N))
    _attraction_batch(sonar, wall, int(seed), env_ids, int(step), params, cmd_v, cmd_w)
    return cmd_v, cmd_w


def body_to_world(yaw, v_body):
    """Body-frame vectors (B, N, 2) rotated by the headings yaw (B, N) rad into the world frame."""
    v_body = np.ascontiguousarray(v_body, dtype=np.float64)
    yaw = np.ascontiguousarray(yaw, dtype=np.float64)
    if v_body.ndim != 3 or v_body.shape[2] != 2 or yaw.shape != v_body.shape[:2]:
        raise ConfigError(f"v_body {v_body.shape} / yaw {yaw.shape}: expected (B, N, 2) and (B, N)")
    out = np.empty_like(v_body)
    _body_to_world_batch(yaw, v_body, out)
    return out
