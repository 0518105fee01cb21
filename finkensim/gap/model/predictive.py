"""Predictive distributions of every logged reading: M draws per reading from the model.

Each sensor has a table (:class:`SonarTable`, :class:`RangingTable`, :class:`ImuTable`) of the real
readings with their identity (flight, time, copter, channel), context features, and a
``draws(params, rows)`` method returning the predictive ensemble (len(rows), M) of those readings under
a :class:`~finkensim.gap.model.params.ModelParams`. Ideal values come from the replay kernels (pose draws);
errors from the simulator's own sensor models, with counter-based random numbers keyed by the reading and
the draw index, so a refit with other parameters reuses the same numbers.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ...config import Config
from ...sensors.sonar_model import CROSSTALK_GEOMETRIC, ERROR_NONE, SCHEDULE_RANDOM_OFFSET, SonarModel
from . import replay as rp
from .sonar_context import sonar_features
from .features import append_identity, nearest_neighbor, range_rate_at, sonar_channel_names, speed, wall_distance
from ...sensors.sonar_hold import held_steps
from ...sensors.imu_correction import corrected_window_draws
from ...sensors.ranging_radio import antenna_key, dropout_probabilities, radio_draws, tag_distance_draws
from .params import ModelParams, gaussian_draws, lag_steps, sonar_echo_errors, sonar_reading_draws
from .cache import CACHE_BYTES, LRU, nbytes_of
from .imu_latency import imu_latency_turn, turn_windows

# --------------------------------------------------------------------------------------- tables

AMBIGUITY_SIGMAS = 3.0  # sonar readings closer than this (in pose-noise units) to a geometric flip are not scored
GEOMETRY_DRAWS = 8  # distinct pose draws per reading when the poses are noisy (reused cyclically across M)


def geometry_draws(sx: float, sy: float, M: int) -> int:
    """Pose draws needed: one when the logged poses are exact, else min(M, GEOMETRY_DRAWS)."""
    return 1 if (sx == 0.0 and sy == 0.0) else min(M, GEOMETRY_DRAWS)


def pose_sigmas(p: ModelParams, fl, M: int) -> tuple[float, float, int]:
    """(σ_xy m, σ_yaw rad, pose draws) of flight fl under p (``None`` sigmas: the flight's own)."""
    sx = fl.sigma_xy if p.sigma_xy is None else p.sigma_xy
    sy = fl.sigma_yaw if p.sigma_yaw is None else p.sigma_yaw
    return sx, sy, geometry_draws(sx, sy, M)


class RowSplit(NamedTuple):
    """The rows of one flight in a row set: sel (positions in the row set), u (sorted unique sample positions),
    pos (each row's index into u), copter, channel, and key (identifies the row set and the flight)."""

    sel: np.ndarray
    u: np.ndarray
    pos: np.ndarray
    copter: np.ndarray
    channel: np.ndarray
    key: tuple


@njit(cache=True, parallel=True)
def gather_draws(a, sel, pos, copter, channel, out):
    """out[sel[i], m] = a[pos[i], copter[i], channel[i], m % G] for every row i of one flight and draw m < M:
    a (K, N, X, G) per-sample ideal draws, sel/pos/copter/channel (n,) int64, out (n_rows, M)."""
    G = a.shape[3]
    M = out.shape[1]
    for i in prange(sel.shape[0]):
        row = sel[i]
        for g in range(min(G, M)):  # stepping m by G instead of an integer division per element
            v = a[pos[i], copter[i], channel[i], g]
            for m in range(g, M, G):
                out[row, m] = v


def _gather(tab, flights, rows, ideal_fn, M):
    """Per-row ideal draws, each (len(rows), M), from per-flight arrays computed on the needed samples.

    ideal_fn(fl, split) → tuple of arrays shaped (len(split.u), N, X, G) for the sorted unique sample positions
    split.u that the rows need (X the channel axis; :class:`RowSplit`). Draw m uses geometry column m % G. The
    rows' split by flight (``tab.splits``) and the gathered result (``tab.gathered``) are cached: a fit asks for
    the same rows many times, and for the same ideal arrays whenever its parameter leaves the geometry alone.
    """
    rk = _rows_key(rows)
    parts = []
    for fl in flights:
        key = ("split", rk, rows.size, fl.index)
        split = tab.splits.get(key)
        if split is None:
            sel = np.nonzero(tab.flight[rows] == fl.index)[0]
            r = rows[sel]
            u = np.unique(tab.sample[r])
            split = tab.splits.put(key, RowSplit(sel, u, np.searchsorted(u, tab.sample[r]), tab.copter[r],
                                                 tab.channel[r], key))
        if split.sel.size:
            parts.append((split, ideal_fn(fl, split)))
    # the cached value holds the ideal arrays themselves, so their ids cannot be reused while it lives
    key = ("gather", rk, rows.size, M) + tuple(id(a) for _, arrays in parts for a in arrays)
    hit = tab.gathered.get(key)
    if hit is not None:
        return hit[1], hit[2]
    outs = None
    period = np.ones(rows.size, dtype=np.int64)
    for split, arrays in parts:
        if outs is None:
            outs = [np.empty((rows.size, M), dtype=a.dtype) for a in arrays]
        for o, a in zip(outs, arrays):
            gather_draws(a, split.sel, split.pos, split.copter, split.channel, o)
        period[split.sel] = arrays[0].shape[-1]
    tab.gathered.put(key, ([arrays for _, arrays in parts], outs, period), nbytes_of((outs, period)))  # ideal: in cache
    return outs, period


def _rows_key(u: np.ndarray) -> int:
    return hash(u.tobytes())

@dataclass
class Table:
    """Readings of one sensor over all flights (flattened; rows = readings with a finite value).

    y (n,) real readings; flight, sample (index into the flight's ``samples``), time (index into
    the log), copter, channel (n,) ints; features: name → (n,) float; channel_names.
    """

    sensor: str
    y: np.ndarray
    flight: np.ndarray
    sample: np.ndarray
    time: np.ndarray
    copter: np.ndarray
    channel: np.ndarray
    features: dict
    channel_names: list
    seconds: np.ndarray = None  # time since the flight's start, s
    missing: np.ndarray | None = None  # ranging: (n_all,) bool for the dropout channel
    cache: LRU = field(default_factory=lambda: LRU(16, CACHE_BYTES), repr=False)  # ideal arrays per flight, parameters
    splits: LRU = field(default_factory=lambda: LRU(8), repr=False)  # rows split by flight
    gathered: LRU = field(default_factory=lambda: LRU(4, CACHE_BYTES), repr=False)  # per-row ideal draws
    normals: LRU = field(default_factory=lambda: LRU(4, CACHE_BYTES), repr=False)  # pose draws' normals per flight
    errors: LRU = field(default_factory=lambda: LRU(4, CACHE_BYTES), repr=False)  # sonar echo errors per rows, model
    # sonar: ideal arrays of rows other than the training rows (mark_training)
    evals: LRU = field(default_factory=lambda: LRU(4, CACHE_BYTES), repr=False)
    training: tuple | None = None

    def mark_training(self, rows: np.ndarray) -> None:
        """Keep the ideal arrays of rows other than ``rows`` (the training rows) in a cache of their own."""
        self.training = (_rows_key(rows), rows.size)

    @property
    def n(self) -> int:
        return self.y.shape[0]

    def needed(self, split: RowSplit, shape: tuple) -> np.ndarray:
        """Bool mask ``shape`` = (len(split.u), N[, X]) of the (sample, copter[, channel]) cells that the split's
        readings need (cached with the split): the replay computes only those."""
        key = ("need",) + split.key
        need = self.splits.get(key)
        if need is None:
            need = np.zeros(shape, dtype=bool)
            need[(split.pos, split.copter, split.channel)[:len(shape)]] = True
            self.splits.put(key, need)
        return need

class SonarTable(Table):
    """Ultrasonic readings; ideal draws depend on pose noise, wall gain, beam width and latency."""

    @classmethod
    def build(cls, flights, cfg: Config, seed: int):
        sonar = SonarModel.from_config(cfg)
        cols = {k: [] for k in ("y", "flight", "sample", "time", "copter", "channel", "sec")}
        feats = {k: [] for k in ("true_range", "hit_type", "incidence", "hit_to_copter", "neighbor_in_beam",
                                 "plate_shift", "wall_distance", "neighbor_distance", "speed", "range_rate")}
        names = None
        for f in flights:
            if f.log.ultrasonic is None:
                continue
            S = f.sonar_yaw.shape[0]
            names_f = sonar_channel_names(f.sonar_yaw)
            names = names or names_f
            K, N = f.samples.size, f.n_copters
            out = np.empty((K, N, S, 8))
            one_ray = f.sonar_model(sonar).with_beam(0.0, 1)
            sonar_features(f.poses, f.walls, one_ray, f.samples, f.sigma_xy, f.sigma_yaw, out)
            y = f.log.ultrasonic[f.samples].copy()  # (K, N, S)
            # readings whose ideal value flips under the tracking noise (grazing a rim, at the range
            # limit) are left out of every score alike: a small ensemble cannot represent them
            y[out[..., 7] < AMBIGUITY_SIGMAS] = np.nan
            nd = nearest_neighbor(f.pos[f.samples])  # (K, N)
            sp = speed(f)  # (K, N)
            rr = range_rate_at(out[..., 0], f)
            kk, nn, ss = np.meshgrid(np.arange(K), np.arange(N), np.arange(S), indexing="ij")
            ok = np.isfinite(y)
            append_identity(cols, f, y, ok, kk, nn, ss)
            for j, name in enumerate(("true_range", "hit_type", "incidence", "hit_to_copter", "neighbor_in_beam",
                                      "plate_shift", "wall_distance")):
                feats[name].append(out[..., j][ok])
            feats["neighbor_distance"].append(np.broadcast_to(nd[:, :, None], y.shape)[ok])
            feats["speed"].append(np.broadcast_to(sp[:, :, None], y.shape)[ok])
            feats["range_rate"].append(rr[ok])
        if names is None:
            return None
        cat = lambda v, dt=float: np.concatenate(v).astype(dt)  # noqa: E731
        t = cls(sensor="ultrasonic", y=cat(cols["y"]), flight=cat(cols["flight"], np.int64),
                   sample=cat(cols["sample"], np.int64), time=cat(cols["time"], np.int64),
                   copter=cat(cols["copter"], np.int64), channel=cat(cols["channel"], np.int64),
                   features={k: cat(v) for k, v in feats.items()}, channel_names=names, seconds=cat(cols["sec"]))
        return t

    def _ideal(self, p: ModelParams, seed: int, M: int, fl, split: RowSplit):
        """Ideal draws (dist, kind, xtalk), each (len(split.u), N, S, G), at the sample positions split.u of one
        flight; only the rays of the split's readings are cast (the others read NaN)."""
        sx, sy, G = pose_sigmas(p, fl, M)
        sp = p.sonar
        if sp.crosstalk & CROSSTALK_GEOMETRIC and sp.schedule == SCHEDULE_RANDOM_OFFSET:
            G = min(M, GEOMETRY_DRAWS)  # the firing schedule is random: exact poses still need several draws
        key = ("sonar", split.key, round(sx, 9), round(sy, 9), round(p.wall_gain, 6),
               round(p.bulge_amplitude, 9), round(p.bulge_reach, 9), round(p.bulge_response, 9), round(p.bulge_shape, 9),
               round(p.bulge_hinge, 9), tuple(round(float(v), 9) for v in p.walls_hinge), sp.ray_angles.tobytes(), lag_steps(p.latency_sonar, fl.dt), sp.schedule, sp.n_slots, sp.cos_half_angle, G,
               sp.max_range, bool(sp.crosstalk & CROSSTALK_GEOMETRIC), sp.update_hz, sp.update_phase)
        cache = self.evals if self.training not in (None, split.key[1:3]) else self.cache
        hit = cache.get(key)
        if hit is not None:
            return hit
        u = split.u
        measured = held_steps(fl.samples[u], fl.dt, sp.update_hz, sp.update_phase)  # sample-and-hold
        times = np.clip(measured - lag_steps(p.latency_sonar, fl.dt), 0, fl.t.size - 1)
        K, N, S = times.size, fl.n_copters, fl.sonar_yaw.shape[0]
        need = self.needed(split, (K, N, S))
        dist, kind, xt = np.empty((K, N, S, G)), np.empty((K, N, S, G), dtype=np.int8), np.empty((K, N, S, G))
        zkey = ("pose normals", split.key, times.tobytes(), G, seed)
        z = self.normals.get(zkey)
        if z is None:  # σ-free, so shared by every evaluation on these samples (σ, walls, beam, sonar model)
            z = self.normals.put(zkey, np.empty((K, G, N, 3)))
            rp.pose_normal_table(times, N, G, seed, fl.index, z)
        rp.sonar_draws(fl.poses_with_bulge(p.bulge_amplitude, p.bulge_reach, p.bulge_response, p.bulge_shape,
                                           p.bulge_hinge, times=times, walls_hinge=p.walls_hinge),
                       fl.hinged(p.walls_hinge)[1], fl.sonar_model(sp), p.wall_gain, times, fl.noise(sx, sy, seed), G, need, dist, kind, xt,
                       z=z)
        return cache.put(key, (dist, kind, xt))

    def draws(self, flights, p: ModelParams, rows: np.ndarray, seed: int, M: int) -> np.ndarray:
        """Predictive draws (len(rows), M) of the sonar readings ``rows`` under parameters p."""
        (dist, kind, xt), period = _gather(self, flights, rows, lambda fl, sp: self._ideal(p, seed, M, fl, sp), M)
        out = np.empty((rows.size, M))
        chan = self.copter[rows] * 64 + self.channel[rows]
        sp = p.sonar
        err = np.empty((0, M))
        if sp.error != ERROR_NONE:  # the errors of these rows' draws, shared by fits of other parameters
            ekey = ("echo errors", _rows_key(rows), rows.size, M, seed, sp.error, sp.sigma, sp.rayleigh_s, sp.rayleigh_sign)
            err = self.errors.get(ekey)
            if err is None:
                err = self.errors.put(ekey, np.empty((rows.size, M)))
                sonar_echo_errors(self.flight[rows], self.time[rows], chan, seed, sp, err)
        sonar_reading_draws(dist, kind, xt, self.flight[rows], self.time[rows], chan, seed, sp, err, out)
        return out, period


class RangingTable(Table):
    """Virtual-ranging readings; the dropout channel is scored separately from the values."""

    @classmethod
    def build(cls, flights, cfg: Config, seed: int):
        cols = {k: [] for k in ("y", "flight", "sample", "time", "copter", "channel", "sec", "miss", "clear", "tr",
                                "nd", "sp", "rr", "wd")}
        any_ = False
        for f in flights:
            if f.log.ranging is None:
                continue
            any_ = True
            K, N = f.samples.size, f.n_copters
            P = f.pos[f.samples]
            dz = f.z[f.samples][:, :, None] - f.z[f.samples][:, None, :]
            d = np.sqrt(((P[:, :, None, :] - P[:, None, :, :]) ** 2).sum(-1) + dz * dz)
            clear = np.empty((K, N, N))
            rp.ranging_clearance(f.pos, f.samples, clear)
            y = f.log.ranging[f.samples]
            kk, aa, bb = np.meshgrid(np.arange(K), np.arange(N), np.arange(N), indexing="ij")
            off = aa != bb
            miss = ~np.isfinite(y)
            sp = speed(f)
            tr = np.minimum(d, cfg.ranging.max_range)
            rr = range_rate_at(tr, f)
            nd = nearest_neighbor(P)
            wd = wall_distance(P, f.arena)
            sel = off & rp.expected_ranging(f)[f.samples]
            append_identity(cols, f, y, sel, kk, aa, bb)
            cols["miss"].append(miss[sel])
            cols["clear"].append(clear[sel])
            cols["tr"].append(tr[sel])
            cols["rr"].append(rr[sel])
            cols["nd"].append(np.broadcast_to(nd[:, :, None], y.shape)[sel])
            cols["sp"].append(np.broadcast_to(sp[:, :, None], y.shape)[sel])
            cols["wd"].append(np.broadcast_to(wd[:, :, None], y.shape)[sel])
        if not any_:
            return None
        c = {k: np.concatenate(v) for k, v in cols.items()}
        clear = np.where(np.isfinite(c["clear"]), c["clear"], 10.0)
        feats = {"true_range": c["tr"], "los_clearance": clear, "neighbor_distance": c["nd"], "speed": c["sp"],
                 "range_rate": c["rr"], "wall_distance": c["wd"]}
        t = cls(sensor="ranging", y=c["y"].astype(float), flight=c["flight"].astype(np.int64),
                sample=c["sample"].astype(np.int64), time=c["time"].astype(np.int64),
                copter=c["copter"].astype(np.int64), channel=c["channel"].astype(np.int64),
                features={k: v.astype(float) for k, v in feats.items()}, channel_names=["all"],
                seconds=c["sec"].astype(float), missing=c["miss"].astype(bool))
        return t

    def _ideal(self, p: ModelParams, seed: int, M: int, fl, u: np.ndarray):
        sx = fl.sigma_xy if p.sigma_xy is None else p.sigma_xy
        G = geometry_draws(sx, 0.0, M)
        radio = p.ranging.params
        key = ("ranging", fl.index, _rows_key(u), round(sx, 9), lag_steps(p.latency_ranging, fl.dt), G, antenna_key(radio))
        hit = self.cache.get(key)
        if hit is None:
            times = np.clip(fl.samples[u] - lag_steps(p.latency_ranging, fl.dt), 0, fl.t.size - 1)
            N = fl.n_copters
            out = np.empty((times.size, N, N, G))
            if radio.antenna_on:  # tag-to-tag distances (ranging_antenna_offset): the simulator's own kernel
                tag_distance_draws(fl.pos, fl.z, fl.yaw, times, fl.noise(sx, 0.0, seed), G, radio, out)
            else:
                rp.ranging_draws(fl.pos, fl.z, fl.yaw, times, fl.noise(sx, 0.0, seed), G, out)
            hit = self.cache.put(key, (out,))
        return hit

    def draws(self, flights, p: ModelParams, rows: np.ndarray, seed: int, M: int) -> np.ndarray:
        key = ("mix", id(rows), rows.size, p.sigma_xy, p.latency_ranging, p.ranging.noise_key(), seed, M,
               antenna_key(p.ranging.params))
        hit = self.cache.get(key)
        if hit is None:
            (x,), period = _gather(self, flights, rows, lambda fl, sp: self._ideal(p, seed, M, fl, sp.u), M)
            # one key per call; the flat index keeps draws aligned with rows and draws (common random numbers)
            y0 = p.ranging.sample(np.minimum(x, p.ranging.max_range).ravel(), seed=seed, env=0, step=0,
                                  copter=0).reshape(x.shape)
            hit = self.cache.put(key, (x, y0, period))
        x, y, period = hit
        if p.ranging.params.radio_on:  # the radio effects: the simulator's kernel (sensors.ranging_radio)
            return radio_draws(y, x, self.copter[rows], self.channel[rows], self.features["los_clearance"][rows],
                               seed, p.ranging.params), period
        y = np.where(x <= p.ranging.max_range, np.maximum(y, 0.0), p.ranging.max_range)
        return y, period

    def dropout_prob(self, p: ModelParams, rows: np.ndarray) -> np.ndarray:
        """Model probability (len(rows),) that a reading is missing."""
        radio = p.ranging.params
        if not radio.dropout_on:
            return np.zeros(rows.size)
        return dropout_probabilities(self.features["true_range"][rows], radio.dropout_a, radio.dropout_b)


def imu_steps(cfg: Config, dt: float) -> tuple[int, int]:
    """(h, b): the IMU window ``gap.imu_window`` and the velocity baseline ``gap.imu_velocity_baseline`` as
    whole samples of period dt s (each at least 1, b at most h)."""
    h = max(1, int(round(cfg.gap.imu_window / dt)))
    return h, min(h, max(1, int(round(cfg.gap.imu_velocity_baseline / dt))))


class ImuTable(Table):
    """IMU readings integrated over a window of h steps (about ``gap.imu_window`` s):
    channels 0, 1 = Δv_x, Δv_y (m/s, world frame: each body-frame sample rotated by the logged
    yaw), 2 = Δψ (rad). Comparing integrals instead of single samples keeps the pose-derived
    ideal free of smoothing bias and of 1/dt² noise amplification.

    Extra per-row arrays: ``bias_gain`` (n, 2) maps a body-frame accelerometer bias (b_x, b_y)
    onto the row's channel (Σ w_j R(ψ_j) dt_j row), ``window_s`` (n,) the window length in s and ``noise_s``
    (n,) Σ w_j² dt_j s (white-noise variance per unit density²). The accelerometer integrals carry trapezoid
    weights w_j (see :func:`~finkensim.gap.model.replay.imu_window_draws`) so that the pose side can use mean
    velocities over ``gap.imu_velocity_baseline`` instead of single-step differences of noisy poses.
    """

    window: int = 20
    baseline: int = 1
    bias_gain: np.ndarray = None
    window_s: np.ndarray = None
    noise_s: np.ndarray = None

    @classmethod
    def build(cls, flights, cfg: Config, seed: int):
        cols = {k: [] for k in ("y", "flight", "sample", "time", "copter", "channel", "sec", "sp", "wd", "am",
                                "g0", "g1", "ws", "ns")}
        any_ = False
        for f in flights:
            if f.log.imu_acc is None:
                continue
            any_ = True
            h, b = imu_steps(cfg, f.dt)
            samples = f.samples[f.samples >= h + b]
            if samples.size == 0:
                continue
            N = f.n_copters
            dts = np.diff(f.t, prepend=f.t[0])
            c, sn = np.cos(f.yaw), np.sin(f.yaw)
            ax, ay, g = f.log.imu_acc[..., 0], f.log.imu_acc[..., 1], f.log.imu_gyro
            csum = lambda a: np.cumsum(np.nan_to_num(a * dts[:, None], nan=0.0), axis=0)  # noqa: E731
            wx, wy, wg = csum(c * ax - sn * ay), csum(sn * ax + c * ay), csum(g)
            cc, ss = csum(c), csum(sn)
            nan_acc = np.cumsum(~np.isfinite(ax) | ~np.isfinite(ay), axis=0)
            nan_g = np.cumsum(~np.isfinite(g), axis=0)
            win = lambda a: a[samples] - a[samples - h]  # noqa: E731  (K, N) sums over (k-h, k]
            # Σ_{j=k-b+1..k} (W_j − W_{j−h}) / b: trapezoid weights matching mean velocities over b steps
            S = lambda a: np.cumsum(a, axis=0)  # noqa: E731
            trap = lambda a: (lambda c: (c[samples] - c[samples - b] - c[samples - h] + c[samples - h - b]) / b)(S(a))  # noqa: E731
            y = np.stack([trap(wx), trap(wy), win(wg)], axis=-1)
            # a window with a missing sample has no integral: NaN (excluded), never silently filled
            y[..., :2][nan_acc[samples] - nan_acc[samples - h - b] > 0] = np.nan
            y[..., 2][win(nan_g) > 0] = np.nan
            Cc, Cs = trap(cc), trap(ss)
            g0 = np.stack([Cc, Cs, np.zeros_like(Cc)], axis=-1)  # coefficient of b_x per channel
            g1 = np.stack([-Cs, Cc, np.zeros_like(Cc)], axis=-1)  # coefficient of b_y per channel
            ws = np.broadcast_to((f.t[samples] - f.t[samples - h])[:, None, None], y.shape)
            # Σ w_j² dt_j of white noise through the weights (uniform dt): the box's h for the gyro
            sq = (h - b + 1 + (b - 1) * (2 * b - 1) / (3 * b)) / h
            ns = ws * np.array([sq, sq, 1.0])
            pos_idx = np.searchsorted(f.samples, samples)
            kk, nn, ch = np.meshgrid(pos_idx, np.arange(N), np.arange(3), indexing="ij")
            ok = np.isfinite(y)
            sp = speed(f)[pos_idx]
            P = f.pos[samples]
            wd = wall_distance(P, f.arena)
            am = np.sqrt(y[..., 0] ** 2 + y[..., 1] ** 2) / ws[..., 0]
            append_identity(cols, f, y, ok, kk, nn, ch)
            cols["g0"].append(g0[ok])
            cols["g1"].append(g1[ok])
            cols["ws"].append(ws[ok])
            cols["ns"].append(ns[ok])
            for name, v in (("sp", sp), ("wd", wd), ("am", am)):
                cols[name].append(np.broadcast_to(v[:, :, None], y.shape)[ok])
        if not any_ or not cols["y"]:
            return None
        c = {k: np.concatenate(v) for k, v in cols.items()}
        feats = {"speed": c["sp"], "wall_distance": c["wd"], "acc_magnitude": c["am"],
                 "axis": c["channel"].astype(float)}
        t = cls(sensor="imu", y=c["y"].astype(float), flight=c["flight"].astype(np.int64),
                sample=c["sample"].astype(np.int64), time=c["time"].astype(np.int64),
                copter=c["copter"].astype(np.int64), channel=c["channel"].astype(np.int64),
                features={k: v.astype(float) for k, v in feats.items()}, channel_names=["all"],
                seconds=c["sec"].astype(float))
        t.bias_gain = np.stack([c["g0"], c["g1"]], axis=-1).astype(float)
        t.window_s = c["ws"].astype(float)
        t.noise_s = c["ns"].astype(float)
        t.window, t.baseline = imu_steps(cfg, flights[0].dt)
        return t

    def _ideal(self, p: ModelParams, seed: int, M: int, fl, split: RowSplit):
        """Window integrals (len(split.u), N, 3, G) at the sample positions split.u of one flight, for the copters
        of the split's readings (the others read NaN).

        Under an IMU latency of L ≠ 0 samples the windows end L samples earlier, and their velocity changes are
        turned by the yaw the copter turned during the lag (:mod:`~finkensim.gap.model.imu_latency`: the window's
        mean turn and its first-order change across the window): the log rotates each delayed body-frame reading
        with the yaw at its stamp, not at its measurement."""
        sx, sy, G = pose_sigmas(p, fl, M)
        h, b = self.window, self.baseline
        lag = lag_steps(p.latency_imu, fl.dt)
        key = ("imu", split.key, round(sx, 9), round(sy, 9), lag, G, h, b)
        hit = self.cache.get(key)
        if hit is None:
            times = np.clip(fl.samples[split.u] - lag, h + b, fl.t.size - 1)
            need = self.needed(split, (times.size, fl.n_copters))
            out = np.empty((times.size, fl.n_copters, 3, G))
            rp.imu_window_draws(fl.pos, fl.yaw_unwrapped, fl.t, times, h, b, fl.noise(sx, sy, seed), G, need, out)
            if lag != 0:  # lag 0: no turn, the windows stay bit for bit
                turn, shift = np.empty((times.size, fl.n_copters)), np.empty((times.size, fl.n_copters, 2))
                imu_latency_turn(fl.pos, fl.yaw_unwrapped, fl.t, fl.samples[split.u], times, h, b, turn, shift)
                turn_windows(out, turn, shift)
            hit = self.cache.put(key, (out,))
        return hit

    def draws(self, flights, p: ModelParams, rows: np.ndarray, seed: int, M: int):
        (ideal,), period = _gather(self, flights, rows, lambda fl, sp: self._ideal(p, seed, M, fl, sp), M)
        ch = self.channel[rows]
        ws = self.window_s[rows]
        # bias: body-frame accelerometer bias rotated into each window's world-frame integral
        bias = self.bias_gain[rows, 0] * p.imu.acc_bias_x + self.bias_gain[rows, 1] * p.imu.acc_bias_y
        bias = np.where(ch == 2, p.imu.gyro_bias * ws, bias)
        # white-noise density (unit·√s): the log's own sample period sets each sample's std, not the config's dt
        density = np.where(ch == 2, p.imu.gyro_sigma, p.imu.acc_sigma) * np.sqrt(p.imu.dt)
        acc_walk, gyro_walk = p.walk_density()
        walk = np.where(ch == 2, gyro_walk, acc_walk)
        # Σ of h white samples (std density/√dt each) times dt = density²·window seconds, and a bias random
        # walk of std walk·sqrt(t) integrated over the window
        sd = np.sqrt(density ** 2 * self.noise_s[rows] + (walk * ws) ** 2 * self.seconds[rows])
        out = np.empty_like(ideal)
        if p.imu.correction.shape[0] > 0:  # the learned correction the simulator flies (imu.correction_file)
            corrected_window_draws(np.ascontiguousarray(ideal), np.ascontiguousarray(bias), ch, self.flight[rows],
                                   self.time[rows], self.copter[rows] * 4 + ch, seed, p.imu.correction, out)
            return out, period
        gaussian_draws(np.ascontiguousarray(ideal), self.flight[rows], self.time[rows], self.copter[rows] * 4 + ch,
                       seed, np.ascontiguousarray(sd), np.ascontiguousarray(bias), out)
        return out, period
