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

import numpy as np
from numba import njit, prange

from ..arena import Arena, walls_step_env
from ..config import Config
from ..flightlog import FlightLog
from ..kernels.geometry import nearest_body_distance_env, point_segment_distance
from ..kernels.rng import STREAM_POSE_NOISE, STREAM_SONAR_SCHEDULE, counter_key, normal, uniform
from ..sensors.ultrasonic import HIT_COPTER, HIT_NONE, HIT_WALL, cast_ray

SCHEDULE_ALL = 0  # every emitter can be heard (simultaneous firing)
SCHEDULE_ROUND_ROBIN = 1
SCHEDULE_RANDOM_OFFSET = 2


class GapInputError(ValueError):
    """Logs and config that cannot be diagnosed together; the message says which and why."""


@dataclass
class Flight:
    """One logged flight prepared for replay.

    pos (T, N, 2) m, yaw (T, N) rad, yaw_unwrapped (T, N) rad, t (T,) s; theta_unit (T, S_p) rad:
    plate angles of bending walls (config wall parameters, bending on) driven by the logged
    copters; samples (K,) indices of the time samples used (strided, skipping the first few so
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
    samples: np.ndarray
    sonar_yaw: np.ndarray | None = None
    sonar_offset: float = 0.0
    extras: dict = field(default_factory=dict)

    @property
    def n_copters(self) -> int:
        return self.pos.shape[1]


@njit(cache=True)
def _replay_walls(pos, t, seg_a, seg_b, radius, hp, lever, theta_out):
    """Plate angles (T, S) of walls driven by logged positions pos (T, N, 2), as in a simulation:
    sample k holds the plates after responding to the positions of samples 1 … k."""
    T = pos.shape[0]
    S = seg_a.shape[0]
    theta = np.zeros(S)
    omega = np.zeros(S)
    integ = np.zeros(S)
    dist = np.empty(S)
    for k in range(T):
        if k > 0:
            nearest_body_distance_env(seg_a, seg_b, pos[k], radius, dist)
            walls_step_env(theta, omega, integ, dist, hp, lever, t[k] - t[k - 1])
        for s in range(S):
            theta_out[k, s] = theta[s]


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
            raise GapInputError(f"{name}: the log has {t.size} samples; expected at least 5 to replay it")
        dts = np.diff(t)
        dt = float(np.median(dts))
        pos = np.ascontiguousarray(log.pose[:, :, :2], dtype=float)
        yaw = np.ascontiguousarray(log.pose[:, :, 2], dtype=float)
        theta = np.empty((t.size, arena.n_plates))
        _replay_walls(pos, t, arena.seg_a, arena.seg_b, radius, arena.hinge, arena.lever, theta)
        sx = cfg.gap.tracking_sigma_xy if cfg.gap.tracking_sigma_xy >= 0 else float(meta.get("tracking_sigma_xy", 0.0) or 0.0)
        sy = cfg.gap.tracking_sigma_yaw if cfg.gap.tracking_sigma_yaw >= 0 else float(meta.get("tracking_sigma_yaw", 0.0) or 0.0)
        first = 10  # history for finite differences and smoothing windows
        if t.size <= first + 1:
            raise GapInputError(f"{name}: the log has {t.size} samples; expected more than {first + 1}")
        stride = max(1, int(np.ceil((t.size - first) / cfg.gap.max_samples_per_flight)))
        samples = np.arange(first, t.size, stride, dtype=np.int64)
        f = Flight(name=name, index=i, log=log, t=t, dt=dt, pos=pos, yaw=yaw,
                   yaw_unwrapped=np.unwrap(yaw, axis=0), arena=arena, radius=radius, sigma_xy=sx, sigma_yaw=sy,
                   theta_unit=theta, samples=samples)
        if log.ultrasonic is not None:
            f.sonar_yaw = np.ascontiguousarray(log.ultrasonic_yaw, dtype=float)
            f.sonar_offset = float(log.ultrasonic_offset)
        flights.append(f)
    return flights


# --------------------------------------------------------------------------------------- pose draws

@njit(cache=True, inline="always")
def _pose_draw(pos, yaw, k, n, m, sigma_xy, sigma_yaw, seed, flight_id):
    """Draw m of copter n's true pose at sample k: logged pose + tracking noise (x, y, yaw)."""
    if sigma_xy == 0.0 and sigma_yaw == 0.0:
        return pos[k, n, 0], pos[k, n, 1], yaw[k, n]
    key = counter_key(seed, flight_id, k, n, STREAM_POSE_NOISE)
    return (pos[k, n, 0] + sigma_xy * normal(key, 3 * m), pos[k, n, 1] + sigma_xy * normal(key, 3 * m + 1),
            yaw[k, n] + sigma_yaw * normal(key, 3 * m + 2))


# --------------------------------------------------------------------------------------- sonar

@njit(cache=True, parallel=True)
def sonar_draws(pos, yaw, theta, gain, plate_a, plate_b, normal_, lever, width, length, mount_yaw, offset,
                radius, max_range, ray_angles, cos_xtalk, schedule, n_slots, times, sigma_xy, sigma_yaw,
                seed, flight_id, M, out_dist, out_kind, out_xtalk):
    """Ideal sonar readings and cross-talk paths for M pose draws at each time in ``times``.

    pos (T, N, 2), yaw (T, N), theta (T, S_p) plate angles (scaled by ``gain`` in sin θ);
    mount_yaw (S,) rad; ray_angles (R,) rad around each sonar heading (nearest echo wins).
    Writes out_dist (K, N, S, M) m (max_range when no echo), out_kind (K, N, S, M) (HIT_*),
    out_xtalk (K, N, S, M): the shortest emitter→receiver path (m) of another copter's sonar that
    lies in the receiver's cone (cos ≥ cos_xtalk) and points at it, within 2·max_range, among
    emitters firing in the receiver's slot (``schedule``); inf if none.
    """
    K = times.shape[0]
    N = pos.shape[1]
    S = mount_yaw.shape[0]
    P = plate_a.shape[0]
    R = ray_angles.shape[0]
    for i in prange(K * M):
        ti = i // M
        m = i % M
        k = times[ti]
        pb_ = np.empty((N, 2))
        yb = np.empty(N)
        for n in range(N):
            x, y, w = _pose_draw(pos, yaw, k, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            pb_[n, 0] = x
            pb_[n, 1] = y
            yb[n] = w
        pa = np.empty((P, 2))
        pbb = np.empty((P, 2))
        for s in range(P):
            sh = lever * gain * np.sin(theta[k, s])
            if sh > lever:
                sh = lever
            pa[s, 0] = plate_a[s, 0] + sh * normal_[s, 0]
            pa[s, 1] = plate_a[s, 1] + sh * normal_[s, 1]
            pbb[s, 0] = plate_b[s, 0] + sh * normal_[s, 0]
            pbb[s, 1] = plate_b[s, 1] + sh * normal_[s, 1]
        slots = np.zeros(N, dtype=np.int64)
        if schedule == SCHEDULE_ROUND_ROBIN:
            for n in range(N):
                slots[n] = n % n_slots
        elif schedule == SCHEDULE_RANDOM_OFFSET:
            for n in range(N):
                u = uniform(counter_key(seed, flight_id, k, n, STREAM_SONAR_SCHEDULE), m)
                slots[n] = min(int(u * n_slots), n_slots - 1)
        buf = np.empty((N, S, 4))
        for n in range(N):
            for s in range(S):
                psi = yb[n] + mount_yaw[s]
                c = np.cos(psi)
                sn = np.sin(psi)
                buf[n, s, 0] = pb_[n, 0] + offset * c
                buf[n, s, 1] = pb_[n, 1] + offset * sn
                buf[n, s, 2] = c
                buf[n, s, 3] = sn
        for n in range(N):
            for s in range(S):
                ox = buf[n, s, 0]
                oy = buf[n, s, 1]
                best = np.inf
                bkind = HIT_NONE
                for r in range(R):
                    if ray_angles[r] == 0.0:
                        dx = buf[n, s, 2]
                        dy = buf[n, s, 3]
                    else:
                        a = yb[n] + mount_yaw[s] + ray_angles[r]
                        dx = np.cos(a)
                        dy = np.sin(a)
                    t_, hk = cast_ray(ox, oy, dx, dy, n, pb_, radius, pa, pbb, width, length)
                    if t_ < best:
                        best = t_
                        bkind = hk
                if best > max_range:
                    out_dist[ti, n, s, m] = max_range
                    out_kind[ti, n, s, m] = HIT_NONE
                else:
                    out_dist[ti, n, s, m] = best
                    out_kind[ti, n, s, m] = bkind
                # cross-talk: nearest emitter sonar of another copter in mutual view
                ux = buf[n, s, 2]
                uy = buf[n, s, 3]
                lim = 2.0 * max_range
                bl = np.inf
                for q in range(N):
                    if q == n or slots[q] != slots[n]:
                        continue
                    for j in range(S):
                        wx = buf[q, j, 0] - ox
                        wy = buf[q, j, 1] - oy
                        L = np.sqrt(wx * wx + wy * wy)
                        if L <= 0.0 or L > lim or L >= bl:
                            continue
                        if ux * wx + uy * wy >= cos_xtalk * L and -(buf[q, j, 2] * wx + buf[q, j, 3] * wy) >= cos_xtalk * L:
                            bl = L
                out_xtalk[ti, n, s, m] = bl


@njit(cache=True, parallel=True)
def sonar_features(pos, yaw, theta, plate_a, plate_b, normal_, lever, width, length, mount_yaw, offset, radius,
                   max_range, cos_cone, times, sigma_xy, sigma_yaw, out):
    """Context features of every sonar reading at the logged poses → out (K, N, S, 8):

    0 true_range (m), 1 hit_type (0 none, 1 wall, 2 copter), 2 incidence (deg, ray vs wall
    normal; NaN unless a wall hit), 3 hit_to_copter (m, wall hit point to nearest copter centre;
    NaN unless a wall hit), 4 neighbor_in_beam (0/1: another copter centre inside the cone
    within max_range), 5 plate_shift (m, displacement lever·sin θ of the plate at the hit, unit
    bending walls), 6 wall_distance (m, copter centre to nearest wall line), 7 ambiguity (in units
    of the pose noise: how far the ray is from grazing another copter's rim, or the hit from the
    range limit, divided by σ_xy + σ_ψ·distance; inf without noise). Readings with a small
    ambiguity have an ideal value that flips under tracking noise.
    """
    K = times.shape[0]
    N = pos.shape[1]
    S = mount_yaw.shape[0]
    P = plate_a.shape[0]
    for ti in prange(K):
        k = times[ti]
        pa = np.empty((P, 2))
        pbb = np.empty((P, 2))
        for s in range(P):
            sh = lever * np.sin(theta[k, s])
            pa[s, 0] = plate_a[s, 0] + sh * normal_[s, 0]
            pa[s, 1] = plate_a[s, 1] + sh * normal_[s, 1]
            pbb[s, 0] = plate_b[s, 0] + sh * normal_[s, 0]
            pbb[s, 1] = plate_b[s, 1] + sh * normal_[s, 1]
        P2 = pos[k]
        for n in range(N):
            wd = min(min(P2[n, 0], width - P2[n, 0]), min(P2[n, 1], length - P2[n, 1]))
            for s in range(S):
                psi = yaw[k, n] + mount_yaw[s]
                dx = np.cos(psi)
                dy = np.sin(psi)
                ox = P2[n, 0] + offset * dx
                oy = P2[n, 1] + offset * dy
                t_, hk = cast_ray(ox, oy, dx, dy, n, P2, radius, pa, pbb, width, length)
                out[ti, n, s, 6] = wd
                if t_ > max_range:
                    out[ti, n, s, 0] = max_range
                    out[ti, n, s, 1] = HIT_NONE
                else:
                    out[ti, n, s, 0] = t_
                    out[ti, n, s, 1] = hk
                out[ti, n, s, 2] = np.nan
                out[ti, n, s, 3] = np.nan
                out[ti, n, s, 5] = np.nan
                if hk == HIT_WALL and t_ <= max_range:
                    hx = ox + t_ * dx
                    hy = oy + t_ * dy
                    # the wall line the ray meets (nearest of the four) gives the normal
                    dl = min(min(hx, width - hx), min(hy, length - hy))
                    if dl == hx or dl == width - hx:
                        out[ti, n, s, 2] = np.degrees(np.arccos(min(1.0, abs(dx))))
                    else:
                        out[ti, n, s, 2] = np.degrees(np.arccos(min(1.0, abs(dy))))
                    best = np.inf
                    for q in range(N):
                        ddx = P2[q, 0] - hx
                        ddy = P2[q, 1] - hy
                        best = min(best, np.sqrt(ddx * ddx + ddy * ddy))
                    out[ti, n, s, 3] = best
                    bs = 0.0
                    bd = np.inf
                    for p in range(P):
                        d = point_segment_distance(hx, hy, pa[p, 0], pa[p, 1], pbb[p, 0], pbb[p, 1])
                        if d < bd:
                            bd = d
                            bs = lever * np.sin(theta[k, p])
                    out[ti, n, s, 5] = bs
                inb = 0.0
                amb = np.inf
                for q in range(N):
                    if q == n:
                        continue
                    wx = P2[q, 0] - ox
                    wy = P2[q, 1] - oy
                    L = np.sqrt(wx * wx + wy * wy)
                    if 0.0 < L <= max_range and dx * wx + dy * wy >= cos_cone * L:
                        inb = 1.0
                    along = dx * wx + dy * wy
                    if along > 0.0 and along < min(t_, max_range) + radius:
                        perp = abs(dx * wy - dy * wx)
                        sc = sigma_xy * 1.4142 + sigma_yaw * along
                        if sc > 0.0:
                            amb = min(amb, abs(perp - radius) / sc)
                sc = sigma_xy * 1.4142 + sigma_yaw * t_
                if sc > 0.0 and np.isfinite(t_):
                    amb = min(amb, abs(t_ - max_range) / sc)
                out[ti, n, s, 4] = inb
                out[ti, n, s, 7] = amb


# --------------------------------------------------------------------------------------- ranging

@njit(cache=True, parallel=True)
def ranging_draws(pos, yaw, times, sigma_xy, seed, flight_id, M, out):
    """True copter distances for M pose draws: out (K, N, N, M) m (diagonal 0)."""
    K = times.shape[0]
    N = pos.shape[1]
    for i in prange(K * M):
        ti = i // M
        m = i % M
        k = times[ti]
        P = np.empty((N, 2))
        for n in range(N):
            x, y, w = _pose_draw(pos, yaw, k, n, m, sigma_xy, 0.0, seed, flight_id)
            P[n, 0] = x
            P[n, 1] = y
        for a in range(N):
            out[ti, a, a, m] = 0.0
            for b in range(a + 1, N):
                dx = P[a, 0] - P[b, 0]
                dy = P[a, 1] - P[b, 1]
                d = np.sqrt(dx * dx + dy * dy)
                out[ti, a, b, m] = d
                out[ti, b, a, m] = d


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
def imu_window_draws(pos, yaw_unwrapped, t, times, h, sigma_xy, sigma_yaw, seed, flight_id, M, out):
    """Window-integrated ideal IMU values for M pose draws: out (K, N, 3, M) =
    (Δv_x, Δv_y) m/s world frame and Δψ rad over the h steps ending at each time in ``times``.

    Δv = v_k − v_{k−h} with v_j = (p_j − p_{j−1}) / (t_j − t_{j−1}) is exactly Σ a_j dt_j of the
    simulator's recorded accelerations, and Δψ = ψ_k − ψ_{k−h} is Σ ω_j dt_j: integrating the IMU
    instead of differentiating the poses twice avoids amplifying tracking noise by 1/dt².
    """
    K = times.shape[0]
    N = pos.shape[1]
    for i in prange(K * M):
        ti = i // M
        m = i % M
        k = times[ti]
        k0 = k - h
        for n in range(N):
            x1, y1, w1 = _pose_draw(pos, yaw_unwrapped, k, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            x0, y0, _ = _pose_draw(pos, yaw_unwrapped, k - 1, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            a1, b1, w0 = _pose_draw(pos, yaw_unwrapped, k0, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            a0, b0, _ = _pose_draw(pos, yaw_unwrapped, k0 - 1, n, m, sigma_xy, sigma_yaw, seed, flight_id)
            d1 = t[k] - t[k - 1]
            d0 = t[k0] - t[k0 - 1]
            out[ti, n, 0, m] = (x1 - x0) / d1 - (a1 - a0) / d0
            out[ti, n, 1, m] = (y1 - y0) / d1 - (b1 - b0) / d0
            out[ti, n, 2, m] = w1 - w0
