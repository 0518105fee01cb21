"""Replay logged flights through the simulator's geometry: walls, ideal sensor values, features.

Geometry comes from each log (arena size, sonar mounting yaw and offset, copter radius), models
from the config. The walls respond to the *logged* copters: the hinge model of
:mod:`finkensim.arena` is driven by the logged positions, exactly as in a simulation, giving
the plate angles θ(t) of each flight.

The logged poses carry tracking noise (σ_xy, σ_ψ). The true pose is therefore uncertain, and
so is every ideal reading. Predictive draws m = 0 … M−1 use pose realisations
``logged + σ·ξ`` keyed by (seed, flight, time index, copter, m): every sensor sees the same
realisation in draw m, and refits reuse the same numbers (common random numbers).

All kernels here are general in the number of sonars S (any mounting yaws), copters N and
plates; times are indices into the log.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ...arena import Arena
from ...config import Config
from ...flightlog import FlightLog, heights
from ...flightlog.messages import plural
from ...world import walls_from_positions
from ...kernels.geometry import point_segment_distance
from ...kernels.raycast import HIT_NONE, plate_bands
from ...sensors.sonar_kernels import (crosstalk_path, fire_slots_env, shifted_plates_env, sonar_hit,
                                     sonar_pose, sonar_poses_env, sonar_spread, store_ideal)
from ...sensors.ranging_radio import tag_distance_draws
from ...sensors.sonar_model import CROSSTALK_GEOMETRIC, SonarModel, WallGeometry, sonar_scalars, wall_geometry
from .bulge import bulge_displacement, hinge_replay
from .params import hinge_key
from .inputs import GapInputError
from ...sensors.tracking import PoseNoise, draw_poses_from, pose_draw, pose_normal_table


@dataclass
class Flight:
    """One logged flight prepared for replay.

    pos (T, N, 2) m, yaw (T, N) rad, yaw_unwrapped (T, N) rad, t (T,) s; z (T, N) m heights (the log's ``z``
    extra; zeros for a planar log, so ranging distances are horizontal there); theta_unit (T, S_p) rad:
    plate angles of bending walls (config wall parameters, bending on) driven by the logged
    copters; plate_distance (T, S_p) m: each plate's distance to the nearest logged copter body; samples (K,) indices of the time samples used (strided, skipping the first few so
    that finite differences have history).
    """

    name: str
    index: int
    log: FlightLog
    t: np.ndarray
    dt: float
    pos: np.ndarray
    yaw: np.ndarray
    yaw_unwrapped: np.ndarray
    arena: Arena
    radius: float
    sigma_xy: float
    sigma_yaw: float
    theta_unit: np.ndarray
    plate_distance: np.ndarray
    samples: np.ndarray
    sonar_yaw: np.ndarray | None = None
    sonar_offset: float = 0.0
    extras: dict = field(default_factory=dict)
    z: np.ndarray | None = None
    hinge: tuple = ()
    _hinged: dict = field(default_factory=dict, repr=False)

    @property
    def n_copters(self) -> int:
        return self.pos.shape[1]

    @property
    def poses(self) -> "ReplayPoses":
        """The flight as the sonar kernels see it: logged poses and replayed plate angles, no extra bulge."""
        return self.poses_with_bulge(0.0, 1.0)

    def hinged(self, walls_hinge: tuple = ()) -> tuple[np.ndarray, WallGeometry]:
        """(plate angles (T, S_p) rad, walls) of the hinge walls ``walls_hinge`` driven by the logged copters
        (:func:`~finkensim.gap.model.bulge.hinge_replay`, the last 8 kept); () or the prepared key: the prepared."""
        key = tuple(float(v) for v in walls_hinge)
        if not key or key == tuple(self.hinge):
            return self.theta_unit, self.walls
        if key not in self._hinged:
            self._hinged = {key: hinge_replay(self.arena, self.pos, self.t, self.radius, key), **dict(list(self._hinged.items())[:7])}
        return self._hinged[key]

    def poses_with_bulge(self, amplitude: float, reach: float, response: float = 0.0,
                         shape: float = 2.0, hinge: float = 0.0,
                         times: np.ndarray | None = None, walls_hinge: tuple = ()) -> "ReplayPoses":
        """:attr:`poses` with every plate displaced toward the arena by ``amplitude · exp(−(d/reach)^shape)`` m,
        d its distance to the nearest copter body, followed with time constant ``response`` s (the
        ``wall_bulge`` effect; amplitude m, reach m > 0, shape > 0; hinge: the weight of the walls' own law,
        :func:`~finkensim.gap.model.bulge.bulge_target`).

        ``times`` (K,) int64 log indices: only the displacement at these samples is wanted (the others are zero,
        never read), so a bulge that follows at once (``response`` 0, each sample's own) is computed at them only
        — the same numbers there, without (T, S_p) arrays of a long log for each evaluation of a fit. A bulge with a
        response time needs every earlier sample and is computed at all of them. ``walls_hinge``: :meth:`hinged`."""
        theta = self.hinged(walls_hinge)[0] if walls_hinge else self.theta_unit
        if times is None or response != 0.0 or amplitude == 0.0:
            return ReplayPoses(self.pos, self.yaw, theta,
                               bulge_displacement(self.plate_distance, amplitude, reach, response, self.t, shape,
                                                  hinge))
        bulge = np.zeros_like(self.plate_distance)  # untouched pages of zeros cost no memory
        bulge[times] = bulge_displacement(self.plate_distance[times], amplitude, reach, 0.0, None, shape, hinge)
        return ReplayPoses(self.pos, self.yaw, theta, bulge)

    @property
    def walls(self) -> WallGeometry:
        """The log's arena as the sonar kernels see it."""
        return wall_geometry(self.arena)

    def sonar_model(self, sp: SonarModel) -> SonarModel:
        """``sp`` with the geometry this log records: sonar mounting yaws and offset, copter radius."""
        return sp._replace(mount_yaw=np.ascontiguousarray(self.sonar_yaw, dtype=np.float64),
                           offset=float(self.sonar_offset), radius=float(self.radius))

    def noise(self, sigma_xy: float, sigma_yaw: float, seed: int) -> "PoseNoise":
        """The :class:`PoseNoise` of this flight's pose draws."""
        return PoseNoise(float(sigma_xy), float(sigma_yaw), int(seed), int(self.index))


def synchronous_pairs(ranging: np.ndarray) -> np.ndarray:
    """(N, N) bool: the pairs of a ranging log (T, N, N) m read at every sample: the most common interval between
    a pair's finite readings is one sample (random dropouts leave it so: P(1) = 1 − p is the largest for any p).
    A pair read at its own slower rate (a radio link every 2.5 s in a 100 Hz log) is not. A pair with fewer than
    two readings follows the majority of the other pairs (a pair that always dropped out in a synchronous log)."""
    N = ranging.shape[1]
    sync = np.zeros((N, N), dtype=bool)
    known = np.zeros((N, N), dtype=bool)
    for a in range(N):
        for b in range(N):
            if a == b:
                continue
            k = np.flatnonzero(np.isfinite(ranging[:, a, b]))
            if k.size >= 2:
                steps, counts = np.unique(np.diff(k), return_counts=True)
                sync[a, b] = steps[np.argmax(counts)] == 1
                known[a, b] = True
    off = ~np.eye(N, dtype=bool)
    majority = bool(sync[known].mean() >= 0.5) if known.any() else True
    sync[off & ~known] = majority
    return sync


def prepare_flights(logs: list[FlightLog], names: list[str], cfg: Config) -> list[Flight]:
    """Prepare each log for replay (geometry from the log, walls from the config, sample stride)."""
    flights = []
    for i, (log, name) in enumerate(zip(logs, names)):
        meta = log.meta or {}
        radius = float(meta.get("copter_radius", cfg.copters.radius))
        altitude = float(meta.get("altitude", cfg.arena.altitude))
        width, length = float(log.arena[0]), float(log.arena[1])
        cfg_f = cfg.replace({"arena.width": width, "arena.length": length, "arena.altitude": altitude,
                             "copters.radius": radius, "walls.bending": True})
        arena = Arena.from_config(cfg_f.arena, cfg_f.walls)
        t = np.asarray(log.t, dtype=float)
        if t.size < 5:
            raise GapInputError(f"{name}: the log has {plural(t.size, 'sample')}; expected at least 5 to replay it")
        dts = np.diff(t)
        dt = float(np.median(dts))
        pos = np.ascontiguousarray(log.pose[:, :, :2], dtype=float)
        yaw = np.ascontiguousarray(log.pose[:, :, 2], dtype=float)
        theta = np.empty((t.size, arena.n_plates))
        plate_distance = np.empty((t.size, arena.n_plates))
        walls_from_positions(pos, t, arena.seg_a, arena.seg_b, radius, arena.hinge, arena.lever, theta, plate_distance)
        sx = cfg.gap.tracking_sigma_xy if cfg.gap.tracking_sigma_xy >= 0 else float(meta.get("tracking_sigma_xy", 0.0) or 0.0)
        sy = cfg.gap.tracking_sigma_yaw if cfg.gap.tracking_sigma_yaw >= 0 else float(meta.get("tracking_sigma_yaw", 0.0) or 0.0)
        first = 10  # history for finite differences and smoothing windows
        if t.size <= first + 1:
            raise GapInputError(f"{name}: the log has {plural(t.size, 'sample')}; expected more than {first + 1}")
        stride = max(1, int(np.ceil((t.size - first) / cfg.gap.max_samples_per_flight)))
        samples = np.arange(first, t.size, stride, dtype=np.int64)
        if stride > 1 and log.ranging is not None:  # a pair read at its own slow rate keeps every reading
            r = np.asarray(log.ranging)
            slow = ~synchronous_pairs(r) & ~np.eye(r.shape[1], dtype=bool)
            extra = np.flatnonzero(np.isfinite(r[:, slow]).any(axis=1)) if slow.any() else np.zeros(0, np.int64)
            samples = np.union1d(samples, extra[extra >= first]).astype(np.int64)
        z = heights(log)
        z = np.zeros(pos.shape[:2]) if z is None else np.ascontiguousarray(z)
        f = Flight(name=name, index=i, log=log, t=t, dt=dt, pos=pos, yaw=yaw,
                   yaw_unwrapped=np.unwrap(yaw, axis=0), arena=arena, radius=radius, sigma_xy=sx, sigma_yaw=sy,
                   theta_unit=theta, plate_distance=plate_distance, samples=samples, z=z, hinge=hinge_key(cfg_f.walls) if arena.hinge.bending else ())
        if log.ultrasonic is not None:
            f.sonar_yaw = np.ascontiguousarray(log.ultrasonic_yaw, dtype=float)
            f.sonar_offset = float(log.ultrasonic_offset)
        flights.append(f)
    return flights


# --------------------------------------------------------------------------------------- sonar

class ReplayPoses(NamedTuple):
    """A logged flight as the sonar kernels see it: pos (T, N, 2) m, yaw (T, N) rad, theta (T, S_p) rad plate
    angles of the replayed walls, bulge (T, S_p) m an extra displacement of each plate toward the arena
    (the ``wall_bulge`` effect; zeros without it). The walls themselves are a :class:`~finkensim.sensors.sonar_model.WallGeometry`
    passed beside it (numba's parallel loops cannot take a record nested in a record)."""

    pos: np.ndarray
    yaw: np.ndarray
    theta: np.ndarray
    bulge: np.ndarray


@njit(cache=True)
def _sonar_draws_at(poses, geometry, sonar, gain, k, noise, z, ti, need, out):
    """The M = z.shape[1] pose draws at sample k into row ti of the outputs out = (out_dist, out_kind, out_xtalk), for
    the rays with need[ti, n, s] (the others get NaN, HIT_NONE, inf): the plates (which no pose draw moves) are placed
    once, the work arrays allocated once."""
    out_dist, out_kind, out_xtalk = out
    M = z.shape[1]
    N = poses.pos.shape[1]
    mount_yaw = sonar.mount_yaw
    rays = sonar.ray_angles
    scalars = sonar_scalars(sonar)  # the per-ray calls take the scalars and the arrays apart (see SonarScalars)
    geometric = scalars.crosstalk & CROSSTALK_GEOMETRIC  # only geometric cross-talk reads the paths
    spread = sonar_spread(scalars)
    S = mount_yaw.shape[0]
    P = geometry.plate_a.shape[0]
    pos_m = np.empty((N, 2))
    yaw_m = np.empty(N)
    pa = np.empty((P, 2))
    pb = np.empty((P, 2))
    slots = np.zeros(N, dtype=np.int64)
    buf = np.empty((N, S, 4))
    dist = np.empty((N, S))
    kind = np.empty((N, S), dtype=np.int64)
    hit = np.empty((N, S, 2))
    all_ = np.empty(0, dtype=np.int64)  # "every copter" for the ray and cross-talk searches
    scratch = np.empty(N, dtype=np.int64)  # crosstalk_path's
    shifted_plates_env(poses.theta[k], geometry.plate_a, geometry.plate_b, geometry.normal, geometry.lever, gain, pa, pb)
    for p in range(P):
        b = poses.bulge[k, p]
        pa[p, 0] += b * geometry.normal[p, 0]
        pa[p, 1] += b * geometry.normal[p, 1]
        pb[p, 0] += b * geometry.normal[p, 0]
        pb[p, 1] += b * geometry.normal[p, 1]
    bands = plate_bands(pa, pb, geometry.width, geometry.length)
    walls = (pa, pb, geometry.width, geometry.length)
    for m in range(M):
        draw_poses_from(poses.pos, poses.yaw, k, z[ti, m], noise.sigma_xy, noise.sigma_yaw, pos_m, yaw_m)
        sonar_poses_env(pos_m, yaw_m, sonar, buf)
        if geometric:
            fire_slots_env(noise.seed, noise.flight_id, k, scalars, slots, m)
        for n in range(N):
            for s in range(S):
                if not need[ti, n, s]:
                    out_dist[ti, n, s, m] = np.nan
                    out_kind[ti, n, s, m] = HIT_NONE
                    out_xtalk[ti, n, s, m] = np.inf
                    continue
                pose = sonar_pose(buf, n, s)
                echo = sonar_hit(n, pose, yaw_m[n] + mount_yaw[s], pos_m, walls, scalars, rays, bands, all_, -1)
                store_ideal(n, s, echo, scalars.max_range, pose, dist, kind, hit)
                out_dist[ti, n, s, m] = dist[n, s]
                out_kind[ti, n, s, m] = kind[n, s]
                out_xtalk[ti, n, s, m] = crosstalk_path(n, s, buf, slots, scalars, all_, -1, spread, scratch) if geometric else np.inf


def sonar_draws(poses, geometry, sonar, gain, times, noise, M, need, out_dist, out_kind, out_xtalk, z=None):
    """Ideal sonar readings and cross-talk paths for M pose draws at each time in ``times``, computed
    with the simulator's own kernels (:mod:`finkensim.sensors.sonar_kernels`).

    poses: :class:`ReplayPoses`; geometry: the :class:`~finkensim.sensors.sonar_model.WallGeometry`; sonar: the
    :class:`~finkensim.sensors.sonar_model.SonarModel` (mounting, offset and radius from the log; its beam
    rays, range, cone and schedule); gain scales the plate displacement
    (:func:`~finkensim.sensors.sonar_kernels.shifted_plates_env`); noise: :class:`PoseNoise`; z: the pose draws'
    normals, :func:`pose_normal_table` (times, N, M, noise.seed, noise.flight_id) (computed here if None).
    Writes out_dist (K, N, S, M) m (max_range when no echo), out_kind (K, N, S, M) (HIT_*), out_xtalk
    (K, N, S, M) m: the shortest emitter → receiver path heard under geometric cross-talk
    (:func:`~finkensim.sensors.sonar_kernels.crosstalk_path`) among the copters firing in the receiver's
    slot — the slots of draw m use uniform m of each copter's schedule cell, so the ensemble spreads over
    the schedules a random-offset sonar may have used; inf if none, and everywhere when ``sonar`` models no geometric
    cross-talk (nothing reads the paths then). Only the rays with need (K, N, S) bool are
    cast (a fit scores a subset of the readings); the others read NaN, HIT_NONE and inf.
    """
    if z is None:
        z = np.empty((times.shape[0], M, poses.pos.shape[1], 3))
        pose_normal_table(times, poses.pos.shape[1], M, noise.seed, noise.flight_id, z)
    if z.shape != (times.shape[0], M, poses.pos.shape[1], 3):
        raise ValueError(f"pose normals z {z.shape}: expected (K, M, N, 3) = {(times.shape[0], M, poses.pos.shape[1], 3)}")
    _sonar_draws(poses, geometry, sonar, gain, times, noise, z, need, (out_dist, out_kind, out_xtalk))


@njit(cache=True, parallel=True)
def _sonar_draws(poses, geometry, sonar, gain, times, noise, z, need, out):
    """The loop of :func:`sonar_draws` over its times (M = z.shape[1] draws; out = (out_dist, out_kind,
    out_xtalk))."""
    for ti in prange(times.shape[0]):
        _sonar_draws_at(poses, geometry, sonar, gain, times[ti], noise, z, ti, need, out)


# --------------------------------------------------------------------------------------- ranging

def ranging_draws(pos, z, yaw, times, noise, M, out):
    """True copter distances for M pose draws: out (K, N, N, M) m (diagonal 0), 3-D with the heights z (T, N) m
    (zeros: horizontal distances, bit for bit). noise: :class:`PoseNoise` (ranging has no direction: pass
    sigma_yaw = 0; heights are not perturbed). The radio's kernel
    :func:`~finkensim.sensors.ranging_radio.tag_distance_draws` without tag offsets (one loop for both)."""
    tag_distance_draws(pos, z, yaw, times, noise, M, None, out)


@njit(cache=True, parallel=True)
def ranging_clearance(pos, times, out):
    """Line-of-sight clearance: out (K, N, N) m, the smallest distance from a third copter's centre
    to the segment between copters a and b (inf with fewer than three copters)."""
    K = times.shape[0]
    N = pos.shape[1]
    for ti in prange(K):
        k = times[ti]
        for a in range(N):
            out[ti, a, a] = np.inf
            for b in range(a + 1, N):
                best = np.inf
                for c in range(N):
                    if c == a or c == b:
                        continue
                    d = point_segment_distance(pos[k, c, 0], pos[k, c, 1], pos[k, a, 0], pos[k, a, 1],
                                               pos[k, b, 0], pos[k, b, 1])
                    best = min(best, d)
                out[ti, a, b] = best
                out[ti, b, a] = best


# --------------------------------------------------------------------------------------- imu

@njit(cache=True, parallel=True)
def imu_window_draws(pos, yaw_unwrapped, t, times, h, b, noise, M, need, out):
    """Window-integrated ideal IMU values for M pose draws: out (K, N, 3, M) =
    (Δv_x, Δv_y) m/s world frame and Δψ rad over the h steps ending at each time in ``times``
    (each time ≥ h + b).

    Δv = v̄_k − v̄_{k−h}, with v̄_j = (p_j − p_{j−b}) / (t_j − t_{j−b}) the mean velocity over a baseline of b
    steps. On a uniform time base it is exactly Σ w_j a_j dt_j of the simulator's recorded accelerations with
    trapezoid weights w (a box of h convolved with a box of b, divided by b; b = 1: the plain window sum),
    and Δψ = ψ_k − ψ_{k−h} is Σ ω_j dt_j: integrating the IMU instead of differentiating the poses twice
    avoids amplifying tracking noise by 1/dt², and the baseline divides the velocities' tracking noise by b.
    noise: :class:`PoseNoise`. Only copters with need (K, N) bool are computed; the others read NaN.
    """
    K = times.shape[0]
    N = pos.shape[1]
    sigma_xy, sigma_yaw, seed, flight_id = noise
    for i in prange(K * M):
        ti = i // M
        m = i % M
        k = times[ti]
        k0 = k - h
        d1 = t[k] - t[k - b]
        d0 = t[k0] - t[k0 - b]
        for n in range(N):
            if not need[ti, n]:
                out[ti, n, 0, m] = np.nan
                out[ti, n, 1, m] = np.nan
                out[ti, n, 2, m] = np.nan
                continue
            x1, y1, w1 = pose_draw(pos, yaw_unwrapped, k, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            x0, y0, _ = pose_draw(pos, yaw_unwrapped, k - b, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            a1, b1, w0 = pose_draw(pos, yaw_unwrapped, k0, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            a0, b0, _ = pose_draw(pos, yaw_unwrapped, k0 - b, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            out[ti, n, 0, m] = (x1 - x0) / d1 - (a1 - a0) / d0
            out[ti, n, 1, m] = (y1 - y0) / d1 - (b1 - b0) / d0
            out[ti, n, 2, m] = w1 - w0


def expected_ranging(f) -> np.ndarray:
    """(T, N, N) bool: where flight f's log expected a ranging reading, so that a NaN there is a dropout and
    elsewhere "no reading" (``spec/flightlog.md``: NaN = no reading). An imported recording marks it in the extra
    ``ranging_expected`` (a reading, a value or a lost one, was recorded there); without the extra, every reading
    and every sample of a pair read synchronously (:func:`synchronous_pairs`, e.g. a simulated log), and nothing of a pair read at its
    own slower rate: a NaN that nobody expected is never a dropout."""
    e = f.log.extras.get("ranging_expected") if f.log.extras else None
    shape = f.log.ranging.shape
    if e is None:
        r = np.asarray(f.log.ranging)
        return synchronous_pairs(r)[None] | np.isfinite(r)
    e = np.asarray(e)
    if e.shape != shape or e.dtype != np.bool_:
        raise GapInputError(f"{f.name}: extra array ranging_expected has shape {e.shape} and dtype {e.dtype}; "
                            f"expected bool of the ranging shape {shape}")
    return e
