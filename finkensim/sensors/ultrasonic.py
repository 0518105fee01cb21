"""Ultrasonic sensors: four horizontal sonars (front, left, back, right) and one facing down.

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

**Compiled use.** :func:`displaced_plates_env`, :func:`ideal_env`, :func:`fire_slots_env`,
:func:`ultrasonic_env` and :func:`down_env` are ``inline="always"`` per-environment kernels taking
only arrays, numbers and the :class:`SonarModel` NamedTuple, so a compiled rollout can call them in
its own loop (allocate the work buffers once per environment). The batched functions here call
non-inlined twins of the same Python functions (identical results; much shorter compilation of the
parallel loops).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..config import Config, ConfigError, SonarConfig
from ..kernels.geometry import ray_circle, ray_segment
from ..kernels.rng import STREAM_SONAR, STREAM_SONAR_SCHEDULE, counter_key, normal, uniform

__all__ = [
    "ERROR_NONE", "ERROR_GAUSSIAN", "ERROR_RAYLEIGH", "ERROR_SEED",
    "CROSSTALK_OFF", "CROSSTALK_CONSTANT", "CROSSTALK_GEOMETRIC",
    "SCHEDULE_SIMULTANEOUS", "SCHEDULE_ROUND_ROBIN", "SCHEDULE_RANDOM_OFFSET",
    "HIT_NONE", "HIT_WALL", "HIT_COPTER", "N_SONARS", "DOWN_SONAR",
    "SonarModel", "WallGeometry", "wall_geometry",
    "displaced_plates_env", "cast_ray", "cast_ray_culled", "plate_bands", "ideal_env", "fire_slots_env", "ultrasonic_env", "down_env",
    "ideal_ultrasonic", "ultrasonic_readings", "down_readings", "fire_slots",
    "ultrasonic_from_state", "ultrasonic_from_trajectory", "rayleigh_std",
]

ERROR_NONE = 0
ERROR_GAUSSIAN = 1
ERROR_RAYLEIGH = 2
ERROR_SEED = 3
ERROR_CODES = {"none": ERROR_NONE, "gaussian": ERROR_GAUSSIAN, "rayleigh": ERROR_RAYLEIGH, "seed": ERROR_SEED}

CROSSTALK_OFF = 0
CROSSTALK_CONSTANT = 1
CROSSTALK_GEOMETRIC = 2
CROSSTALK_CODES = {"off": CROSSTALK_OFF, "constant": CROSSTALK_CONSTANT, "geometric": CROSSTALK_GEOMETRIC}

SCHEDULE_SIMULTANEOUS = 0
SCHEDULE_ROUND_ROBIN = 1
SCHEDULE_RANDOM_OFFSET = 2
SCHEDULE_CODES = {"simultaneous": SCHEDULE_SIMULTANEOUS, "round_robin": SCHEDULE_ROUND_ROBIN,
                  "random_offset": SCHEDULE_RANDOM_OFFSET}

HIT_NONE = 0
HIT_WALL = 1
HIT_COPTER = 2

N_SONARS = 4  # horizontal: front, left, back, right
DOWN_SONAR = 4  # index of the down sonar in the random-number layout

RAYLEIGH_STD_FACTOR = math.sqrt((4.0 - math.pi) / 2.0)


def rayleigh_std(sigma: float) -> float:
    """Standard deviation of Rayleigh(σ): sqrt((4 − π)/2)·σ ≈ 0.655σ (m)."""
    return RAYLEIGH_STD_FACTOR * float(sigma)


class SonarModel(NamedTuple):
    """Sonar parameters in SI units, as passed to the kernels (arrays, ints, floats, bools only).

    mount_yaw (4,) rad: mounting yaw of front, left, back, right relative to the heading.
    offset m: sonar distance from the copter centre. min_range, max_range m: reading clamp; no echo
    within max_range reads max_range. error, crosstalk, schedule: integer codes (``ERROR_*``,
    ``CROSSTALK_*``, ``SCHEDULE_*``). sigma m: Rayleigh scale or Gaussian std. rayleigh_sign: ±1 (or
    any value in [−1, 1]) multiplying (R − s) in the ``rayleigh`` model. rayleigh_s m: s, the Rayleigh
    std. crosstalk_probability: constant model's per-reading probability. half_angle rad,
    cos_half_angle: sonar cone. n_slots: slots of the round-robin / random-offset schedules.
    crosstalk_jitter m: std of the cross-talk reading's jitter. ray_angles (R,) rad: ray directions
    relative to the sonar heading (``[0]`` for ``beam = "ray"``, ``linspace(−h, h, beam_rays)`` for
    ``"cone"``). radius m: copter body radius (echo circles). altitude m: flight height (down sonar).
    enabled, down_enabled: whether the caller should produce horizontal / down readings (the
    functions here always compute).
    """

    mount_yaw: np.ndarray
    offset: float
    min_range: float
    max_range: float
    error: int
    sigma: float
    rayleigh_sign: float
    rayleigh_s: float
    crosstalk: int
    crosstalk_probability: float
    half_angle: float
    cos_half_angle: float
    schedule: int
    n_slots: int
    crosstalk_jitter: float
    ray_angles: np.ndarray
    radius: float
    altitude: float
    enabled: bool
    down_enabled: bool

    @classmethod
    def from_config(cls, cfg: Config | SonarConfig, radius: float | None = None,
                    altitude: float | None = None) -> "SonarModel":
        """Build from a whole :class:`~finkensim.config.Config` (uses ``sonar``, ``copters.radius`` and
        ``arena.altitude``) or from a ``SonarConfig`` plus ``radius`` and ``altitude`` (m)."""
        if isinstance(cfg, SonarConfig):
            sc = cfg
            if radius is None or altitude is None:
                raise ConfigError("SonarModel.from_config(SonarConfig): radius and altitude (m) are required "
                                  "(or pass the whole Config)")
        else:
            sc = cfg.sonar
            radius = cfg.copters.radius if radius is None else radius
            altitude = cfg.arena.altitude if altitude is None else altitude
        if sc.min_range > sc.max_range:
            raise ConfigError(f"sonar.min_range = {sc.min_range!r}: expected <= sonar.max_range = {sc.max_range!r} m")
        h = math.radians(sc.cone_half_angle_deg)
        if sc.beam == "cone" and sc.beam_rays > 1:
            rays = np.linspace(-h, h, sc.beam_rays)
        else:
            rays = np.zeros(1)
        return cls(
            mount_yaw=np.ascontiguousarray(np.radians(np.asarray(sc.yaw_deg, dtype=np.float64))),
            offset=float(sc.offset),
            min_range=float(sc.min_range),
            max_range=float(sc.max_range),
            error=int(ERROR_CODES[sc.error]),
            sigma=float(sc.sigma),
            rayleigh_sign=float(sc.rayleigh_sign),
            rayleigh_s=rayleigh_std(sc.sigma),
            crosstalk=int(CROSSTALK_CODES[sc.crosstalk]),
            crosstalk_probability=float(sc.crosstalk_probability),
            half_angle=float(h),
            cos_half_angle=float(math.cos(h)),
            schedule=int(SCHEDULE_CODES[sc.schedule]),
            n_slots=int(sc.n_slots),
            crosstalk_jitter=float(sc.crosstalk_jitter),
            ray_angles=np.ascontiguousarray(rays, dtype=np.float64),
            radius=float(radius),
            altitude=float(altitude),
            enabled=bool(sc.enabled),
            down_enabled=bool(sc.down_enabled),
        )

    @property
    def n_rays(self) -> int:
        return int(self.ray_angles.shape[0])


class WallGeometry(NamedTuple):
    """The arena as the sonar kernels need it: plate_a, plate_b, normal (S, 2) m; lever m; width, length m."""

    plate_a: np.ndarray
    plate_b: np.ndarray
    normal: np.ndarray
    lever: float
    width: float
    length: float


def wall_geometry(arena) -> WallGeometry:
    """:class:`WallGeometry` of an :class:`~finkensim.arena.Arena` (or a WallGeometry, returned as is)."""
    if isinstance(arena, WallGeometry):
        return arena
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    return WallGeometry(f(arena.plate_a), f(arena.plate_b), f(arena.normal), float(arena.lever),
                        float(arena.width), float(arena.length))


# ---------------------------------------------------------------------------------------------
# per-environment kernels (inline, for compiled rollouts)


@njit(cache=True, inline="always")
def displaced_plates_env(theta_b, plate_a, plate_b, normal, lever, pa_out, pb_out):
    """Plate surfaces at flight height for one environment: theta_b (S,) rad → pa_out, pb_out (S, 2) m.

    Each plate is shifted along its inward normal by lever · sin θ (as ``Arena.plate_surfaces``).
    """
    for s in range(theta_b.shape[0]):
        sh = lever * np.sin(theta_b[s])
        pa_out[s, 0] = plate_a[s, 0] + sh * normal[s, 0]
        pa_out[s, 1] = plate_a[s, 1] + sh * normal[s, 1]
        pb_out[s, 0] = plate_b[s, 0] + sh * normal[s, 0]
        pb_out[s, 1] = plate_b[s, 1] + sh * normal[s, 1]


@njit(cache=True, inline="always")
def box_exit(ox, oy, dx, dy, width, length):
    """Distance along the unit ray O + t·D to the boundary of [0, W] × [0, L] (≥ 0; the net backstop)."""
    t = np.inf
    if dx > 0.0:
        t = min(t, (width - ox) / dx)
    elif dx < 0.0:
        t = min(t, -ox / dx)
    if dy > 0.0:
        t = min(t, (length - oy) / dy)
    elif dy < 0.0:
        t = min(t, -oy / dy)
    return max(t, 0.0)


@njit(cache=True, inline="always")
def cast_ray(ox, oy, dx, dy, self_n, pos_b, radius, pa, pb, width, length):
    """Nearest hit of one unit ray for one environment: (t m, hit kind HIT_WALL / HIT_COPTER).

    Plates pa, pb (S, 2) first, then the boundary, then every copter circle except ``self_n``;
    a tie keeps the earlier object.
    """
    best = np.inf
    kind = HIT_NONE
    for s in range(pa.shape[0]):
        t = ray_segment(ox, oy, dx, dy, pa[s, 0], pa[s, 1], pb[s, 0], pb[s, 1])
        if t < best:
            best = t
            kind = HIT_WALL
    t = box_exit(ox, oy, dx, dy, width, length)
    if t < best:
        best = t
        kind = HIT_WALL
    for m in range(pos_b.shape[0]):
        if m == self_n:
            continue
        t = ray_circle(ox, oy, dx, dy, pos_b[m, 0], pos_b[m, 1], radius)
        if t < best:
            best = t
            kind = HIT_COPTER
    return best, kind


# ---------------------------------------------------------------------------------------------
# culled raycast: only the plates a ray can reach
#
# Walls are straight, axis-aligned rows of plates (:class:`~finkensim.arena.Arena`: south, east, north,
# west, n = S/4 plates each, plate k of a wall inside pitch cell k along the wall). A displaced plate
# stays on a line parallel to its wall, so every plate of wall w lies in the band between the smallest
# and the largest of the wall's plate lines (computed from the displaced plates themselves, per
# environment: :func:`plate_bands`). A ray from inside the rectangle ends at the net after t_box
# (:func:`box_exit`), and a plate changes the result only if its computed hit distance is < t_box (a
# plate at exactly t_box gives the same distance and the same kind as the net). So for each wall the
# ray's stretch t ∈ [0, t_box] inside that wall's band (widened by eps) gives an interval along the wall
# (widened by eps), and only the plates whose pitch cells overlap it are tested, in increasing index
# order like the full search. Equal to :func:`cast_ray` bit for bit:
#
# - the plates are axis-aligned (checked: both ends share the wall-normal coordinate exactly), so in
#   ray_segment den = −fl(dy·ex) (south/north; dx·ey for east/west) has no cancellation: a computed
#   hit with t ≤ t_box and s ∈ [0, 1] lies within a few ulps · (arena size) of the true intersection,
#   far inside eps = 1e-9 · (1 + W + L) m;
# - each plate's own extent is checked to lie within its pitch cell [k·pitch − eps, (k + 1)·pitch + eps]
#   along its wall, so a hit anywhere in the ray's interval [u0 − eps, u1 + eps] can only be on plates
#   floor((u0 − 2 eps)/pitch) … floor((u1 + 2 eps)/pitch) (the second eps covers the rounding of the
#   cell bounds and of the division, both ≪ eps);
# - the plates left out have computed distance > t_box (or miss), so the minimum, its first occurrence
#   in index order (ties, signed zeros) and the kind (plates and net are both HIT_WALL) are unchanged;
#   the copter circles are then tested exactly as in cast_ray.
# When the layout does not match (any other plate arrangement, NaN) or the sonar is not strictly inside
# the rectangle or the direction is not finite, :func:`cast_ray_culled` runs the full search.


@njit(cache=True, inline="always")
def _cull_eps(width, length):
    """Safety margin (m) of the culled raycast: 1e-9 · (1 + W + L), ~10⁶ times the rounding it covers."""
    return 1e-9 * (1.0 + width + length)


@njit(cache=True, inline="always")
def _wall_band(pa, pb, s0, n, ci, sign, origin, pitch, eps):
    """(ok, lo, hi) for the n plates s0 … s0 + n − 1 of one wall: ci = index of the wall-normal coordinate
    (1: south/north, 0: east/west), along-wall coordinate u = origin + sign · (other coordinate)."""
    ui = 1 - ci
    lo = np.inf
    hi = -np.inf
    for k in range(n):
        s = s0 + k
        c = pa[s, ci]
        ua = origin + sign * pa[s, ui]
        ub = origin + sign * pb[s, ui]
        if not (pb[s, ci] == c and abs(c) < np.inf and abs(ua) < np.inf and abs(ub) < np.inf):
            return False, lo, hi
        u0 = ua if ua < ub else ub
        u1 = ub if ua < ub else ua
        if not (u0 >= k * pitch - eps and u1 <= (k + 1) * pitch + eps):
            return False, lo, hi
        if c < lo:
            lo = c
        if c > hi:
            hi = c
    return True, lo, hi


@njit(cache=True)
def plate_bands(pa, pb, width, length):
    """Per-environment input of :func:`cast_ray_culled` from the displaced plates pa, pb (S, 2) m.

    Returns (ok, lo_s, hi_s, lo_e, hi_e, lo_n, hi_n, lo_w, hi_w): ok says whether the plates follow the
    :class:`~finkensim.arena.Arena` layout (then culling is exact); lo/hi are the smallest and largest
    wall-normal coordinate (y for south/north, x for east/west, m) of each wall's plates.
    """
    S = pa.shape[0]
    n = S // 4
    ok = n > 0 and 4 * n == S and 0.0 < width < np.inf and 0.0 < length < np.inf
    lo_s = hi_s = lo_e = hi_e = lo_n = hi_n = lo_w = hi_w = 0.0
    eps = _cull_eps(width, length)
    for w in range(4 if ok else 0):  # south, east, north, west (one call site: short compile)
        ci = 1 if w % 2 == 0 else 0
        sign = 1.0 if w < 2 else -1.0
        side = width if ci == 1 else length
        ok_w, lo, hi = _wall_band(pa, pb, w * n, n, ci, sign, 0.0 if w < 2 else side, side / n, eps)
        ok = ok and ok_w
        if w == 0:
            lo_s, hi_s = lo, hi
        elif w == 1:
            lo_e, hi_e = lo, hi
        elif w == 2:
            lo_n, hi_n = lo, hi
        else:
            lo_w, hi_w = lo, hi
    return ok, lo_s, hi_s, lo_e, hi_e, lo_n, hi_n, lo_w, hi_w


@njit(cache=True, inline="always")
def _band_plates(ox, oy, dx, dy, pa, pb, s0, n, ci, sign, origin, inv_pitch, lo, hi, t_end, eps, inv_dx, inv_dy,
                 best):
    """Nearest hit (min with ``best``) among the plates of one wall the ray can reach for t ∈ [0, t_end]."""
    if ci == 1:
        oc, dc, ou, du, inv = oy, dy, ox, dx, inv_dy
    else:
        oc, dc, ou, du, inv = ox, dx, oy, dy, inv_dx
    if inv == 0.0:  # parallel to the wall (or |d| < 1e-200: moves < eps along the normal before t_end)
        if oc < lo - eps or oc > hi + eps:
            return best
        t0 = 0.0
        t1 = t_end
    else:
        ta = (lo - eps - oc) * inv
        tb = (hi + eps - oc) * inv
        t0 = max(0.0, min(ta, tb))
        t1 = min(t_end, max(ta, tb))
        if not (t0 <= t1):
            return best
    ua = origin + sign * (ou + t0 * du)
    ub = origin + sign * (ou + t1 * du)
    f0 = math.floor((min(ua, ub) - 2.0 * eps) * inv_pitch)
    f1 = math.floor((max(ua, ub) + 2.0 * eps) * inv_pitch)
    if f1 < 0.0 or f0 > n - 1.0:
        return best
    k0 = 0 if f0 < 0.0 else int(f0)
    k1 = n - 1 if f1 > n - 1.0 else int(f1)
    for s in range(s0 + k0, s0 + k1 + 1):
        t = ray_segment(ox, oy, dx, dy, pa[s, 0], pa[s, 1], pb[s, 0], pb[s, 1])
        if t < best:
            best = t
    return best


# the full search as a called function: the rare fallback of cast_ray_culled, not inlined there
_cast_ray_fn = njit(cache=True)(cast_ray.py_func)


@njit(cache=True, inline="always")
def cast_ray_culled(ox, oy, dx, dy, self_n, pos_b, radius, pa, pb, width, length, bands):
    """:func:`cast_ray` testing only the plates the ray can reach before the net (same result, bit for bit).

    ``bands`` = :func:`plate_bands` (pa, pb, width, length), computed once per environment and step.
    (Kept small for numba's IR-level inlining — one band test in a loop over the walls, one fallback call
    site — and :func:`plate_bands` is not inlined: each inlined copy costs seconds of cold compile time.)
    """
    ok, lo_s, hi_s, lo_e, hi_e, lo_n, hi_n, lo_w, hi_w = bands
    # a unit direction (the culling margins assume |d| = 1) from strictly inside the rectangle
    fast = (ok and 0.0 < ox < width and 0.0 < oy < length and abs(dx) < np.inf and abs(dy) < np.inf
            and abs(dx) + abs(dy) > 0.5)
    t_box = box_exit(ox, oy, dx, dy, width, length) if fast else np.inf
    if not (t_box < np.inf):
        return _cast_ray_fn(ox, oy, dx, dy, self_n, pos_b, radius, pa, pb, width, length)
    n = pa.shape[0] // 4
    eps = _cull_eps(width, length)
    t_end = t_box + eps
    inv_w = n / width
    inv_l = n / length
    # the band crossings only select plates (the distances come from ray_segment), so 1/d is fine here;
    # 0 marks a ray (numerically) parallel to the wall
    inv_dx = 1.0 / dx if abs(dx) >= 1e-200 else 0.0
    inv_dy = 1.0 / dy if abs(dy) >= 1e-200 else 0.0
    best = np.inf
    for w in range(4):  # south, east, north, west: plates in increasing index order
        if w == 0:
            ci, sign, origin, inv_p, lo, hi = 1, 1.0, 0.0, inv_w, lo_s, hi_s
        elif w == 1:
            ci, sign, origin, inv_p, lo, hi = 0, 1.0, 0.0, inv_l, lo_e, hi_e
        elif w == 2:
            ci, sign, origin, inv_p, lo, hi = 1, -1.0, width, inv_w, lo_n, hi_n
        else:
            ci, sign, origin, inv_p, lo, hi = 0, -1.0, length, inv_l, lo_w, hi_w
        best = _band_plates(ox, oy, dx, dy, pa, pb, w * n, n, ci, sign, origin, inv_p, lo, hi, t_end, eps, inv_dx,
                            inv_dy, best)
    kind = HIT_WALL  # a plate or the net (t_box is finite)
    if t_box < best:
        best = t_box
    for m in range(pos_b.shape[0]):
        if m == self_n:
            continue
        t = ray_circle(ox, oy, dx, dy, pos_b[m, 0], pos_b[m, 1], radius)
        if t < best:
            best = t
            kind = HIT_COPTER
    return best, kind


@njit(cache=True, inline="always")
def sonar_poses_env(pos_b, yaw_b, sp, sonar_buf):
    """Sonar origins and headings of one environment → sonar_buf (N, 4, 4): (x m, y m, cos ψ, sin ψ)."""
    for n in range(pos_b.shape[0]):
        for k in range(N_SONARS):
            psi = yaw_b[n] + sp.mount_yaw[k]
            c = np.cos(psi)
            s = np.sin(psi)
            sonar_buf[n, k, 0] = pos_b[n, 0] + sp.offset * c
            sonar_buf[n, k, 1] = pos_b[n, 1] + sp.offset * s
            sonar_buf[n, k, 2] = c
            sonar_buf[n, k, 3] = s


@njit(cache=True, inline="always")
def ideal_env(pos_b, yaw_b, pa, pb, width, length, sp, sonar_buf, dist, kind, hit):
    """Ideal horizontal readings of one environment.

    pos_b (N, 2) m, yaw_b (N,) rad, pa/pb (S, 2) m displaced plate surfaces
    (:func:`displaced_plates_env`), width/length m. Writes sonar_buf (N, 4, 4) (see
    :func:`sonar_poses_env`), dist (N, 4) m (max_range when no echo), kind (N, 4) int (HIT_*),
    hit (N, 4, 2) m (nearest hit point, also beyond range). Each ray is cast with :func:`cast_ray_culled`
    (only the plates it can reach; the same result as :func:`cast_ray` bit for bit).
    """
    sonar_poses_env(pos_b, yaw_b, sp, sonar_buf)
    bands = plate_bands(pa, pb, width, length)
    R = sp.ray_angles.shape[0]
    for n in range(pos_b.shape[0]):
        for k in range(N_SONARS):
            ox = sonar_buf[n, k, 0]
            oy = sonar_buf[n, k, 1]
            psi = yaw_b[n] + sp.mount_yaw[k]
            best = np.inf
            bkind = HIT_NONE
            hx = np.nan
            hy = np.nan
            for r in range(R):
                if R == 1 and sp.ray_angles[0] == 0.0:
                    dx = sonar_buf[n, k, 2]
                    dy = sonar_buf[n, k, 3]
                else:
                    a = psi + sp.ray_angles[r]
                    dx = np.cos(a)
                    dy = np.sin(a)
                t, hk = cast_ray_culled(ox, oy, dx, dy, n, pos_b, sp.radius, pa, pb, width, length, bands)
                if t < best:
                    best = t
                    bkind = hk
                    hx = ox + t * dx
                    hy = oy + t * dy
            if best > sp.max_range:
                dist[n, k] = sp.max_range
                kind[n, k] = HIT_NONE
                if not np.isfinite(best):
                    hx = ox + sp.max_range * sonar_buf[n, k, 2]
                    hy = oy + sp.max_range * sonar_buf[n, k, 3]
            else:
                dist[n, k] = best
                kind[n, k] = bkind
            hit[n, k, 0] = hx
            hit[n, k, 1] = hy


@njit(cache=True, inline="always")
def fire_slot(seed, env_id, step, n, sp):
    """Firing slot (0 … n_slots − 1) of copter n at this step."""
    if sp.schedule == SCHEDULE_ROUND_ROBIN:
        return n % sp.n_slots
    if sp.schedule == SCHEDULE_RANDOM_OFFSET:
        u = uniform(counter_key(seed, env_id, step, n, STREAM_SONAR_SCHEDULE), 0)
        return min(int(u * sp.n_slots), sp.n_slots - 1)
    return 0


@njit(cache=True, inline="always")
def fire_slots_env(seed, env_id, step, sp, slot):
    """Firing slots of every copter of one environment → slot (N,) int64."""
    for n in range(slot.shape[0]):
        slot[n] = fire_slot(seed, env_id, step, n, sp)


@njit(cache=True, inline="always")
def crosstalk_path(n, k, sonar_buf, slot, sp):
    """Shortest emitter→receiver path (m) heard by sonar (n, k) under geometric cross-talk; inf if none."""
    rx = sonar_buf[n, k, 0]
    ry = sonar_buf[n, k, 1]
    ux = sonar_buf[n, k, 2]
    uy = sonar_buf[n, k, 3]
    lim = 2.0 * sp.max_range
    ch = sp.cos_half_angle
    best = np.inf
    # Squared-length pre-tests, each only rejecting emitters the exact test below rejects too, so the
    # result is that of the plain loop (L = sqrt(wx² + wy²) per emitter, then the four comparisons) bit
    # for bit, with the sqrt left for emitters that pass: fl∘sqrt is monotonic, so L² > q with
    # fl(sqrt(q)) > x implies L > x, and q = x²·(1 + 1e-12) is such a bound for x > 0 (the margin is
    # ~10³ times the rounding of the squares; used for x > 1e-100, so x² does not underflow). With
    # cos(half angle) > 0 a negative dot product d fails its cone test, and for d ≥ 0, d² < ch²·L²·(1 − 1e-12)
    # implies d < fl(ch·fl(sqrt(L²))) (used for ch > 1e-50 and 1e-200 < L² < 1e200: no underflow or
    # overflow; a d² that underflows is < 1e-308 while ch·L > 1e-150).
    if lim > 1e-100:
        lim2 = lim * lim * (1.0 + 1e-12)
    elif lim <= 0.0:
        lim2 = -1.0  # every L > lim (and L2 = NaN fails every test anyway)
    else:
        lim2 = np.inf  # tiny or NaN: no pre-test
    best2 = np.inf
    ch2 = ch * ch * (1.0 - 1e-12)
    square_cone = ch > 1e-50
    for m in range(sonar_buf.shape[0]):
        if m == n or slot[m] != slot[n]:
            continue
        for j in range(N_SONARS):
            wx = sonar_buf[m, j, 0] - rx
            wy = sonar_buf[m, j, 1] - ry
            L2 = wx * wx + wy * wy
            d_rx = ux * wx + uy * wy
            d_em = -(sonar_buf[m, j, 2] * wx + sonar_buf[m, j, 3] * wy)
            # evaluated without short-circuits (bitwise | and &): one well-predicted branch per emitter
            skip = (L2 > lim2) | (L2 > best2)  # L > lim or L > best
            if square_cone:
                c2 = ch2 * L2
                outside = (d_rx < 0.0) | (d_em < 0.0) | (d_rx * d_rx < c2) | (d_em * d_em < c2)  # d < ch·L
                skip = skip | ((L2 > 1e-200) & (L2 < 1e200) & outside)
            if skip:
                continue
            L = np.sqrt(L2)
            if L <= 0.0 or L > lim or L >= best:
                continue
            if d_rx >= ch * L and d_em >= ch * L:
                best = L
                best2 = L * L * (1.0 + 1e-12) if L > 1e-100 else np.inf
    return best


@njit(cache=True, inline="always")
def echo_reading(d, echo, key, k, sp):
    """Echo reading (m, unclamped) of sonar k for true distance d; ``echo`` False → max_range exactly."""
    if not echo:
        return sp.max_range
    if sp.error == ERROR_NONE:
        return d
    if sp.error == ERROR_GAUSSIAN:
        return d + sp.sigma * normal(key, 4 * k + 1)
    u = uniform(key, 8 * k + 1)
    R = np.sqrt(-2.0 * sp.sigma * sp.sigma * np.log(u))
    if sp.error == ERROR_SEED:
        return d + (R - sp.rayleigh_s)
    return d + sp.rayleigh_sign * (R - sp.rayleigh_s)


@njit(cache=True, inline="always")
def clamp_reading(y, sp):
    return min(sp.max_range, max(sp.min_range, y))


@njit(cache=True, inline="always")
def ultrasonic_env(pos_b, yaw_b, pa, pb, width, length, sp, seed, env_id, step,
                   sonar_buf, dist, kind, hit, slot, out):
    """Measured horizontal readings of one environment → out (N, 4) m, in [min_range, max_range].

    Same geometry arguments and work buffers as :func:`ideal_env` (their ideal values are left in
    dist/kind/hit), plus slot (N,) int64 work buffer; seed, env_id, step key the random numbers.
    """
    ideal_env(pos_b, yaw_b, pa, pb, width, length, sp, sonar_buf, dist, kind, hit)
    N = pos_b.shape[0]
    if sp.crosstalk == CROSSTALK_GEOMETRIC:
        fire_slots_env(seed, env_id, step, sp, slot)
    for n in range(N):
        key = counter_key(seed, env_id, step, n, STREAM_SONAR)
        for k in range(N_SONARS):
            d = dist[n, k]
            y = echo_reading(d, kind[n, k] != HIT_NONE, key, k, sp)
            if sp.crosstalk == CROSSTALK_CONSTANT:
                if uniform(key, 8 * k) < sp.crosstalk_probability:
                    y = 0.5 * d
            elif sp.crosstalk == CROSSTALK_GEOMETRIC:
                L = crosstalk_path(n, k, sonar_buf, slot, sp)
                if L < np.inf:
                    c = 0.5 * L
                    if sp.crosstalk_jitter > 0.0:
                        c += sp.crosstalk_jitter * normal(key, 4 * k + 2)
                    if c < y:
                        y = c
            out[n, k] = clamp_reading(y, sp)


@njit(cache=True, inline="always")
def down_env(alt_b, sp, seed, env_id, step, out):
    """Down-sonar readings of one environment: true altitude alt_b (N,) m → out (N,) m (clamped)."""
    for n in range(alt_b.shape[0]):
        key = counter_key(seed, env_id, step, n, STREAM_SONAR)
        d = alt_b[n]
        out[n] = clamp_reading(echo_reading(d, d <= sp.max_range, key, DOWN_SONAR, sp), sp)


# ---------------------------------------------------------------------------------------------
# batched kernels

# Batched kernels call non-inlined twins of the per-environment kernels: the same code, compiled once
# as a function (its helpers inlined into it) instead of being inlined into every prange body, which
# keeps numba's parallel-loop compilation short.
_ideal_env_fn = njit(cache=True)(ideal_env.py_func)
_ultrasonic_env_fn = njit(cache=True)(ultrasonic_env.py_func)
_down_env_fn = njit(cache=True)(down_env.py_func)


@njit(cache=True, parallel=True)
def _ideal_batch(pos, yaw, theta, plate_a, plate_b, normal_, lever, width, length, sp, dist, kind, hit):
    B, N, _ = pos.shape
    S = plate_a.shape[0]
    for b in prange(B):
        pa = np.empty((S, 2))
        pb = np.empty((S, 2))
        sonar_buf = np.empty((N, N_SONARS, 4))
        displaced_plates_env(theta[b], plate_a, plate_b, normal_, lever, pa, pb)
        _ideal_env_fn(pos[b], yaw[b], pa, pb, width, length, sp, sonar_buf, dist[b], kind[b], hit[b])


@njit(cache=True, parallel=True)
def _readings_batch(pos, yaw, theta, plate_a, plate_b, normal_, lever, width, length, sp, seed, env_ids,
                    steps, dist, kind, hit, out):
    """Rows b of pos/yaw/theta with their own env_ids[b] and steps[b] (so T×B trajectories flatten)."""
    B, N, _ = pos.shape
    S = plate_a.shape[0]
    for b in prange(B):
        pa = np.empty((S, 2))
        pb = np.empty((S, 2))
        sonar_buf = np.empty((N, N_SONARS, 4))
        slot = np.zeros(N, dtype=np.int64)
        displaced_plates_env(theta[b], plate_a, plate_b, normal_, lever, pa, pb)
        _ultrasonic_env_fn(pos[b], yaw[b], pa, pb, width, length, sp, seed, env_ids[b], steps[b], sonar_buf,
                       dist[b], kind[b], hit[b], slot, out[b])


@njit(cache=True, parallel=True)
def _down_batch(alt, sp, seed, env_ids, steps, out):
    for b in prange(alt.shape[0]):
        _down_env_fn(alt[b], sp, seed, env_ids[b], steps[b], out[b])


@njit(cache=True, parallel=True)
def _slots_batch(sp, seed, env_ids, step, out):
    for b in prange(out.shape[0]):
        fire_slots_env(seed, env_ids[b], step, sp, out[b])


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


def ideal_ultrasonic(pos, yaw, theta, arena, params: SonarModel):
    """Ideal horizontal sonar readings (no error, no cross-talk, not clamped to min_range).

    Args:
        pos (B, N, 2) m copter centres; yaw (B, N) rad; theta (B, S) rad plate angles;
        arena: :class:`~finkensim.arena.Arena` (or :class:`WallGeometry`); params: :class:`SonarModel`.
    Returns:
        dist (B, N, 4) m: distance from each sonar to its nearest hit, max_range if none within range;
        hit_type (B, N, 4) int64: 0 none (no echo within range), 1 wall (plate or net), 2 copter;
        hit_xy (B, N, 4, 2) m: the nearest hit point (also when beyond range, where hit_type is 0).
    Sonar order: front, left, back, right.
    """
    sp = _check_model(params)
    g = wall_geometry(arena)
    pos, yaw, theta = _check_geometry(pos, yaw, theta, g)
    B, N, _ = pos.shape
    dist = np.empty((B, N, N_SONARS))
    kind = np.empty((B, N, N_SONARS), dtype=np.int64)
    hit = np.empty((B, N, N_SONARS, 2))
    _ideal_batch(pos, yaw, theta, g.plate_a, g.plate_b, g.normal, g.lever, g.width, g.length, sp, dist, kind, hit)
    return dist, kind, hit


def ultrasonic_readings(pos, yaw, theta, arena, params: SonarModel, seed: int, env_ids, step: int,
                        return_ideal: bool = False):
    """Measured horizontal sonar readings of B environments at world step ``step``.

    Args: as :func:`ideal_ultrasonic`, plus seed, env_ids (B,) global environment indices and step
    (``WorldState.step``), which key the random numbers.
    Returns:
        readings (B, N, 4) m in [min_range, max_range] (front, left, back, right); with
        ``return_ideal=True`` the tuple (readings, dist, hit_type, hit_xy) of :func:`ideal_ultrasonic`.
    """
    sp = _check_model(params)
    g = wall_geometry(arena)
    pos, yaw, theta = _check_geometry(pos, yaw, theta, g)
    B, N, _ = pos.shape
    env_ids = _check_env_ids(env_ids, B)
    steps = np.full(B, int(step), dtype=np.int64)
    dist = np.empty((B, N, N_SONARS))
    kind = np.empty((B, N, N_SONARS), dtype=np.int64)
    hit = np.empty((B, N, N_SONARS, 2))
    out = np.empty((B, N, N_SONARS))
    _readings_batch(pos, yaw, theta, g.plate_a, g.plate_b, g.normal, g.lever, g.width, g.length, sp, int(seed),
                    env_ids, steps, dist, kind, hit, out)
    if return_ideal:
        return out, dist, kind, hit
    return out


def down_readings(pos, params: SonarModel, seed: int, env_ids, step: int, altitude=None):
    """Down-sonar readings (B, N) m: the altitude with the error model, no cross-talk, clamped.

    pos (B, N, 2) m gives the shape (B, N); ``altitude`` (m, scalar or (B, N)) defaults to
    ``params.altitude``. Random numbers: sonar index 4 of each copter's STREAM_SONAR cell.
    """
    sp = _check_model(params)
    pos = np.asarray(pos)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ConfigError(f"pos has shape {pos.shape}: expected (B, N, 2) m")
    B, N, _ = pos.shape
    alt = sp.altitude if altitude is None else altitude
    alt = np.ascontiguousarray(np.broadcast_to(np.asarray(alt, dtype=np.float64), (B, N)))
    env_ids = _check_env_ids(env_ids, B)
    out = np.empty((B, N))
    _down_batch(alt, sp, int(seed), env_ids, np.full(B, int(step), dtype=np.int64), out)
    return out


def fire_slots(params: SonarModel, seed: int, env_ids, step: int, n_copters: int):
    """Firing slot of every copter, (B, N) int64 in [0, n_slots) (0 for ``simultaneous``)."""
    sp = _check_model(params)
    env_ids = np.ascontiguousarray(env_ids, dtype=np.int64).reshape(-1)
    out = np.empty((env_ids.size, int(n_copters)), dtype=np.int64)
    _slots_batch(sp, int(seed), env_ids, int(step), out)
    return out


def ultrasonic_from_state(state, arena, params: SonarModel, return_ideal: bool = False):
    """:func:`ultrasonic_readings` of a :class:`~finkensim.world.WorldState` (its pos, yaw, theta, seed,
    env_ids and step)."""
    return ultrasonic_readings(state.pos, state.yaw, state.theta, arena, params, state.seed, state.env_ids,
                               state.step, return_ideal=return_ideal)


def ultrasonic_from_trajectory(traj, arena, params: SonarModel, seed: int, env_ids, step0: int,
                               return_ideal: bool = False):
    """Readings along a recorded :class:`~finkensim.world.Trajectory` (pose (T, B, N, 3), theta (T, B, S)).

    Sample t uses the random numbers of step ``step0 + t``, so this equals calling
    :func:`ultrasonic_readings` on each recorded state. Returns readings (T, B, N, 4) m (and, with
    ``return_ideal``, dist (T, B, N, 4), hit_type (T, B, N, 4), hit_xy (T, B, N, 4, 2)).
    """
    sp = _check_model(params)
    g = wall_geometry(arena)
    pose = np.asarray(traj.pose, dtype=np.float64)
    if pose.ndim != 4 or pose.shape[3] != 3:
        raise ConfigError(f"traj.pose has shape {pose.shape}: expected (T, B, N, 3)")
    T, B, N, _ = pose.shape
    S = g.plate_a.shape[0]
    theta = np.asarray(traj.theta, dtype=np.float64)
    if theta.shape != (T, B, S):
        raise ConfigError(f"traj.theta has shape {theta.shape}: expected (T, B, S) = ({T}, {B}, {S})")
    env_ids = _check_env_ids(env_ids, B)
    pos = np.ascontiguousarray(pose[..., :2].reshape(T * B, N, 2))
    yaw = np.ascontiguousarray(pose[..., 2].reshape(T * B, N))
    th = np.ascontiguousarray(theta.reshape(T * B, S))
    ids = np.ascontiguousarray(np.tile(env_ids, T))
    steps = np.ascontiguousarray(np.repeat(int(step0) + np.arange(T, dtype=np.int64), B))
    dist = np.empty((T * B, N, N_SONARS))
    kind = np.empty((T * B, N, N_SONARS), dtype=np.int64)
    hit = np.empty((T * B, N, N_SONARS, 2))
    out = np.empty((T * B, N, N_SONARS))
    _readings_batch(pos, yaw, th, g.plate_a, g.plate_b, g.normal, g.lever, g.width, g.length, sp, int(seed),
                    ids, steps, dist, kind, hit, out)
    out = out.reshape(T, B, N, N_SONARS)
    if return_ideal:
        return (out, dist.reshape(T, B, N, N_SONARS), kind.reshape(T, B, N, N_SONARS),
                hit.reshape(T, B, N, N_SONARS, 2))
    return out
