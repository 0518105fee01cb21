"""Predictive distributions of every logged reading: M draws per reading from the model.

:class:`ModelParams` holds every knob of the sensor and world models that an effect can turn
(base values from the config). Each sensor has a table (:class:`SonarTable`,
:class:`RangingTable`, :class:`ImuTable`) of the real readings with their identity (flight,
time, copter, channel), context features, and a ``draws(params, rows)`` method returning the
model's predictive ensemble (len(rows), M) for those readings. Ideal values come from the replay
kernels (pose draws); error models are applied here with counter-based random numbers keyed by
the reading and the draw index, so a refit with other parameters reuses the same numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit, prange

from ..config import Config
from ..kernels.rng import STREAM_EFFECT, counter_key, normal, uniform
from ..sensors.ranging import RangingModel
from ..sensors.sonar_model import SonarModel
from . import replay as rp

ERR_NONE, ERR_GAUSSIAN, ERR_RAYLEIGH, ERR_SEED = 0, 1, 2, 3
_ERR = {"none": ERR_NONE, "gaussian": ERR_GAUSSIAN, "rayleigh": ERR_RAYLEIGH, "seed": ERR_SEED}
_SCHED = {"simultaneous": 0, "round_robin": 1,
          "random_offset": 2}

SONAR_NAMES = {0.0: "front", 90.0: "left", 180.0: "back", -90.0: "right"}


def sonar_channel_names(yaw_rad) -> list[str]:
    """Names of sonars from their mounting yaw: front/left/back/right within 10°, else 'sonar<k>'."""
    names = []
    for k, y in enumerate(np.degrees(np.asarray(yaw_rad, dtype=float))):
        y = (y + 180.0) % 360.0 - 180.0
        best = min(SONAR_NAMES, key=lambda a: abs((y - a + 180.0) % 360.0 - 180.0))
        names.append(SONAR_NAMES[best] if abs((y - best + 180.0) % 360.0 - 180.0) <= 10.0 else f"sonar{k}")
    return names


@dataclass(frozen=True)
class ModelParams:
    """Every parameter of the predictive model. Units SI; ``None`` sigmas = the flight's own."""

    sigma_xy: float | None = None
    sigma_yaw: float | None = None
    # sonar
    sonar_error: int = ERR_RAYLEIGH
    sonar_sigma: float = 0.05
    sonar_sign: float = -1.0
    sonar_bias: float = 0.0
    sonar_scale: float = 1.0
    sonar_min: float = 0.2
    sonar_max: float = 3.0
    xtalk_const_p: float = 0.0
    xtalk_geo_q: float = 0.0
    xtalk_schedule: int = 1
    xtalk_slots: int = 4
    xtalk_half_angle: float = math.radians(45.0)
    xtalk_jitter: float = 0.02
    wall_gain: float = 1.0
    beam_half_angle: float = 0.0
    beam_rays: int = 7
    latency_sonar: int = 0
    # ranging
    ranging_error: str = "mixture"
    ranging_sigma: float = 0.1
    ranging_max: float = 2.5
    nlos_bias: float = 0.0
    nlos_width: float = 0.2
    dropout_a: float = -np.inf
    dropout_b: float = 0.0
    latency_ranging: int = 0
    # imu (per-sample white-noise std and bias-walk std per sqrt(s))
    acc_white: float = 0.0
    acc_walk: float = 0.0
    gyro_white: float = 0.0
    gyro_walk: float = 0.0
    acc_bias_x: float = 0.0
    acc_bias_y: float = 0.0
    gyro_bias: float = 0.0
    latency_imu: int = 0

    @classmethod
    def from_config(cls, cfg: Config) -> "ModelParams":
        s, r, i = cfg.sonar, cfg.ranging, cfg.imu
        dt = cfg.simulation.dt
        geo = s.crosstalk == "geometric"
        return cls(
            sonar_error=_ERR[s.error], sonar_sigma=s.sigma, sonar_sign=(1.0 if s.error == "seed" else s.rayleigh_sign),
            sonar_min=s.min_range, sonar_max=s.max_range,
            xtalk_const_p=s.crosstalk_probability if s.crosstalk == "constant" else 0.0,
            xtalk_geo_q=1.0 if geo else 0.0, xtalk_schedule=_SCHED[s.schedule] if geo else 0,
            xtalk_slots=s.n_slots, xtalk_half_angle=math.radians(s.cone_half_angle_deg), xtalk_jitter=s.crosstalk_jitter,
            wall_gain=1.0 if cfg.walls.bending else 0.0,
            beam_half_angle=math.radians(s.cone_half_angle_deg) if s.beam == "cone" else 0.0, beam_rays=s.beam_rays,
            ranging_error=r.error, ranging_sigma=r.sigma, ranging_max=r.max_range,
            acc_white=i.acc_noise_density / math.sqrt(dt), acc_walk=i.acc_bias_walk,
            gyro_white=i.gyro_noise_density / math.sqrt(dt), gyro_walk=i.gyro_bias_walk,
        )

    def with_(self, **kw) -> "ModelParams":
        return replace(self, **kw)


# --------------------------------------------------------------------------------------- error kernels

@njit(cache=True, parallel=True)
def _sonar_error(dist, kind, xtalk, flight, tidx, chan, seed, err, sigma, sign, rs, bias, scale, p_const, q_geo,
                 jitter, lo, hi, out):
    """Reading draws (n, M) from ideal draws dist/kind/xtalk (n, M) and the error parameters."""
    n, M = dist.shape
    for i in prange(n):
        key = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT)
        for m in range(M):
            d = dist[i, m]
            if kind[i, m] == 0:
                y = hi
            else:
                y = d * scale + bias
                if err == 1:
                    y += sigma * normal(key, 4 * m + 1)
                elif err >= 2:
                    R = np.sqrt(-2.0 * sigma * sigma * np.log(uniform(key, 8 * m)))
                    y += sign * (R - rs)
            if p_const > 0.0 and uniform(key, 8 * m + 4) < p_const:
                y = 0.5 * d
            L = xtalk[i, m]
            if q_geo > 0.0 and L < np.inf and uniform(key, 8 * m + 5) < q_geo:
                c = 0.5 * L + jitter * normal(key, 4 * m + 3)
                if c < y:
                    y = c
            out[i, m] = min(hi, max(lo, y))


@njit(cache=True, parallel=True)
def _gauss_error(ideal, flight, tidx, chan, seed, white, walk_var_per_s, t_since, bias, out):
    """Draws ideal + bias + N(0, white² + walk_var_per_s·t_since), all per row (n,). (n, M)."""
    n, M = ideal.shape
    for i in prange(n):
        key = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT)
        sd = np.sqrt(white[i] * white[i] + walk_var_per_s[i] * t_since[i])
        for m in range(M):
            out[i, m] = ideal[i, m] + bias[i] + sd * normal(key, m)


# --------------------------------------------------------------------------------------- tables

AMBIGUITY_SIGMAS = 3.0  # sonar readings closer than this (in pose-noise units) to a geometric flip are not scored
GEOMETRY_DRAWS = 8  # distinct pose draws per reading when the poses are noisy (reused cyclically across M)


def geometry_draws(sx: float, sy: float, M: int) -> int:
    """Pose draws needed: one when the logged poses are exact, else min(M, GEOMETRY_DRAWS)."""
    return 1 if (sx == 0.0 and sy == 0.0) else min(M, GEOMETRY_DRAWS)


class LRU:
    """A small bounded cache (insertion-ordered dict, least recently used evicted first)."""

    def __init__(self, size=16):
        self.size = size
        self.d = {}

    def get(self, key):
        v = self.d.pop(key, None)
        if v is not None:
            self.d[key] = v
        return v

    def put(self, key, value):
        self.d[key] = value
        while len(self.d) > self.size:
            self.d.pop(next(iter(self.d)))
        return value


def _gather(tab, flights, rows, ideal_fn, M):
    """Per-row ideal draws, each (len(rows), M), from per-flight arrays computed on the needed samples.

    ideal_fn(fl, u) → tuple of arrays shaped (len(u), N, X, G) for the sorted unique sample positions
    u that the rows need (X the channel axis). Draw m uses geometry column m % G.
    """
    outs = None
    period = np.ones(rows.size, dtype=np.int64)
    for fl in flights:
        sel = np.nonzero(tab.flight[rows] == fl.index)[0]
        if sel.size == 0:
            continue
        r = rows[sel]
        u = np.unique(tab.sample[r])
        arrays = ideal_fn(fl, u)
        if outs is None:
            outs = [np.empty((rows.size, M), dtype=a.dtype) for a in arrays]
        pos = np.searchsorted(u, tab.sample[r])
        for o, a in zip(outs, arrays):
            cols = np.arange(M) % a.shape[-1]
            o[sel] = a[pos, tab.copter[r], tab.channel[r]][:, cols]
        period[sel] = arrays[0].shape[-1]
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
    cache: LRU = field(default_factory=LRU, repr=False)

    @property
    def n(self) -> int:
        return self.y.shape[0]

def _range_rate(values, dt):
    """d/dt along axis 0 (central differences), values (K, ...) sampled every dt."""
    if values.shape[0] < 3:
        return np.zeros_like(values)
    return np.gradient(values, dt, axis=0)

class SonarTable(Table):
    """Ultrasonic readings; ideal draws depend on pose noise, wall gain, beam width and latency."""

    @classmethod
    def build(cls, flights, cfg: Config, seed: int):
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
            rp.sonar_features(f.geometry, f.sonar_model(SonarModel.from_config(cfg)).with_beam(0.0, 1), f.samples, f.sigma_xy,
                              f.sigma_yaw, out)
            y = f.log.ultrasonic[f.samples].copy()  # (K, N, S)
            # readings whose ideal value flips under the tracking noise (grazing a rim, at the range
            # limit) are left out of every score alike: a small ensemble cannot represent them
            y[out[..., 7] < AMBIGUITY_SIGMAS] = np.nan
            nd = _nearest_neighbor(f.pos[f.samples])  # (K, N)
            sp = _speed(f)  # (K, N)
            rr = _range_rate(out[..., 0], f.dt * max(1, int(np.median(np.diff(f.samples))) if K > 1 else 1))
            kk, nn, ss = np.meshgrid(np.arange(K), np.arange(N), np.arange(S), indexing="ij")
            ok = np.isfinite(y)
            _append_identity(cols, f, y, ok, kk, nn, ss)
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
        t.sonar0 = SonarModel.from_config(cfg)
        return t

    def _ideal(self, p: ModelParams, seed: int, M: int, fl, u: np.ndarray):
        """Ideal draws (dist, kind, xtalk), each (len(u), N, S, G), at sample positions u of one flight."""
        sx = fl.sigma_xy if p.sigma_xy is None else p.sigma_xy
        sy = fl.sigma_yaw if p.sigma_yaw is None else p.sigma_yaw
        G = geometry_draws(sx, sy, M)
        key = ("sonar", fl.index, _rows_key(u), round(sx, 9), round(sy, 9), round(p.wall_gain, 6),
               round(p.beam_half_angle, 6), p.beam_rays, p.latency_sonar, p.xtalk_schedule, p.xtalk_slots,
               round(p.xtalk_half_angle, 6), G, p.sonar_max)
        hit = self.cache.get(key)
        if hit is not None:
            return hit
        times = np.maximum(0, fl.samples[u] - p.latency_sonar)
        K, N, S = times.size, fl.n_copters, fl.sonar_yaw.shape[0]
        dist = np.empty((K, N, S, G))
        kind = np.empty((K, N, S, G), dtype=np.int8)
        xt = np.empty((K, N, S, G))
        sp = fl.sonar_model(self.sonar0)._replace(
            max_range=p.sonar_max, half_angle=p.xtalk_half_angle, cos_half_angle=math.cos(p.xtalk_half_angle),
            schedule=p.xtalk_schedule, n_slots=p.xtalk_slots).with_beam(p.beam_half_angle, p.beam_rays)
        rp.sonar_draws(fl.geometry, sp, p.wall_gain, times, fl.noise(sx, sy, seed), G, dist, kind, xt)
        return self.cache.put(key, (dist, kind, xt))

    def draws(self, flights, p: ModelParams, rows: np.ndarray, seed: int, M: int) -> np.ndarray:
        """Predictive draws (len(rows), M) of the sonar readings ``rows`` under parameters p."""
        (dist, kind, xt), period = _gather(self, flights, rows, lambda fl, u: self._ideal(p, seed, M, fl, u), M)
        out = np.empty((rows.size, M))
        chan = self.copter[rows] * 64 + self.channel[rows]
        rs = math.sqrt((4.0 - math.pi) / 2.0) * p.sonar_sigma
        _sonar_error(dist, kind, xt, self.flight[rows], self.time[rows], chan, seed, p.sonar_error, p.sonar_sigma,
                     p.sonar_sign, rs, p.sonar_bias, p.sonar_scale, p.xtalk_const_p, p.xtalk_geo_q, p.xtalk_jitter,
                     p.sonar_min, p.sonar_max, out)
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
            d = np.sqrt(((P[:, :, None, :] - P[:, None, :, :]) ** 2).sum(-1))
            clear = np.empty((K, N, N))
            rp.ranging_clearance(f.pos, f.samples, clear)
            y = f.log.ranging[f.samples]
            kk, aa, bb = np.meshgrid(np.arange(K), np.arange(N), np.arange(N), indexing="ij")
            off = aa != bb
            miss = ~np.isfinite(y)
            sp = _speed(f)
            tr = np.minimum(d, cfg.ranging.max_range)
            rr = _range_rate(tr, f.dt * max(1, int(np.median(np.diff(f.samples))) if K > 1 else 1))
            nd = _nearest_neighbor(P)
            wd = _wall_distance(P, f.arena)
            sel = off
            _append_identity(cols, f, y, sel, kk, aa, bb)
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

    def _model(self, p: ModelParams) -> RangingModel:
        key = ("model", p.ranging_error, p.ranging_sigma, p.ranging_max)
        m = self.cache.get(key)
        if m is None:
            m = self.cache.put(key, RangingModel(error=p.ranging_error, max_range=p.ranging_max, sigma=p.ranging_sigma))
        return m

    def _ideal(self, p: ModelParams, seed: int, M: int, fl, u: np.ndarray):
        sx = fl.sigma_xy if p.sigma_xy is None else p.sigma_xy
        G = geometry_draws(sx, 0.0, M)
        key = ("ranging", fl.index, _rows_key(u), round(sx, 9), p.latency_ranging, G)
        hit = self.cache.get(key)
        if hit is None:
            times = np.maximum(0, fl.samples[u] - p.latency_ranging)
            N = fl.n_copters
            out = np.empty((times.size, N, N, G))
            rp.ranging_draws(fl.pos, fl.yaw, times, fl.noise(sx, 0.0, seed), G, out)
            hit = self.cache.put(key, (out,))
        return hit

    def draws(self, flights, p: ModelParams, rows: np.ndarray, seed: int, M: int) -> np.ndarray:
        key = ("mix", id(rows), rows.size, p.sigma_xy, p.latency_ranging, p.ranging_error, p.ranging_sigma,
               p.ranging_max, seed, M)
        hit = self.cache.get(key)
        if hit is None:
            (x,), period = _gather(self, flights, rows, lambda fl, u: self._ideal(p, seed, M, fl, u), M)
            model = self._model(p)
            # one key per call; the flat index keeps draws aligned with rows and draws (common random numbers)
            y0 = model.sample(np.minimum(x, p.ranging_max).ravel(), seed=seed, env=0, step=0, copter=0).reshape(x.shape)
            hit = self.cache.put(key, (x, y0, period))
        x, y, period = hit
        inside = x <= p.ranging_max
        if p.nlos_bias != 0.0:
            clear = self.features["los_clearance"][rows]
            y = y + (p.nlos_bias * np.exp(-((clear / max(p.nlos_width, 1e-6)) ** 2)))[:, None]
        y = np.where(inside, np.maximum(y, 0.0), p.ranging_max)
        return y, period

    def dropout_prob(self, p: ModelParams, rows: np.ndarray) -> np.ndarray:
        """Model probability (len(rows),) that a reading is missing."""
        if not np.isfinite(p.dropout_a):
            return np.zeros(rows.size)
        z = p.dropout_a + p.dropout_b * self.features["true_range"][rows]
        return 1.0 / (1.0 + np.exp(-z))


class ImuTable(Table):
    """IMU readings integrated over a window of h steps (about ``gap.imu_window`` s):
    channels 0, 1 = Δv_x, Δv_y (m/s, world frame: each body-frame sample rotated by the logged
    yaw), 2 = Δψ (rad). Comparing integrals instead of single samples keeps the pose-derived
    ideal free of smoothing bias and of 1/dt² noise amplification.

    Extra per-row arrays: ``bias_gain`` (n, 2) maps a body-frame accelerometer bias (b_x, b_y)
    onto the row's channel (Σ R(ψ_j) dt_j row), and ``window_s`` (n,) the window length in s.
    """

    window: int = 20
    bias_gain: np.ndarray = None
    window_s: np.ndarray = None

    @classmethod
    def build(cls, flights, cfg: Config, seed: int):
        cols = {k: [] for k in ("y", "flight", "sample", "time", "copter", "channel", "sec", "sp", "wd", "am",
                                "g0", "g1", "ws")}
        any_ = False
        for f in flights:
            if f.log.imu_acc is None:
                continue
            any_ = True
            h = max(1, int(round(cfg.gap.imu_window / f.dt)))
            samples = f.samples[f.samples >= h + 1]
            if samples.size == 0:
                continue
            K, N = samples.size, f.n_copters
            dts = np.diff(f.t, prepend=f.t[0])
            c, sn = np.cos(f.yaw), np.sin(f.yaw)
            ax, ay, g = f.log.imu_acc[..., 0], f.log.imu_acc[..., 1], f.log.imu_gyro
            csum = lambda a: np.cumsum(np.nan_to_num(a * dts[:, None], nan=0.0), axis=0)  # noqa: E731
            wx, wy, wg = csum(c * ax - sn * ay), csum(sn * ax + c * ay), csum(g)
            cc, ss = csum(c), csum(sn)
            nan_acc = np.cumsum(~np.isfinite(ax) | ~np.isfinite(ay), axis=0)
            nan_g = np.cumsum(~np.isfinite(g), axis=0)
            win = lambda a: a[samples] - a[samples - h]  # noqa: E731  (K, N) sums over (k-h, k]
            y = np.stack([win(wx), win(wy), win(wg)], axis=-1)
            # a window with a missing sample has no integral: NaN (excluded), never silently filled
            y[..., :2][win(nan_acc) > 0] = np.nan
            y[..., 2][win(nan_g) > 0] = np.nan
            Cc, Cs = win(cc), win(ss)
            g0 = np.stack([Cc, Cs, np.zeros_like(Cc)], axis=-1)  # coefficient of b_x per channel
            g1 = np.stack([-Cs, Cc, np.zeros_like(Cc)], axis=-1)  # coefficient of b_y per channel
            ws = np.broadcast_to((f.t[samples] - f.t[samples - h])[:, None, None], y.shape)
            pos_idx = np.searchsorted(f.samples, samples)
            kk, nn, ch = np.meshgrid(pos_idx, np.arange(N), np.arange(3), indexing="ij")
            ok = np.isfinite(y)
            sp = _speed(f)[pos_idx]
            P = f.pos[samples]
            wd = _wall_distance(P, f.arena)
            am = np.sqrt(y[..., 0] ** 2 + y[..., 1] ** 2) / ws[..., 0]
            _append_identity(cols, f, y, ok, kk, nn, ch)
            cols["g0"].append(g0[ok])
            cols["g1"].append(g1[ok])
            cols["ws"].append(ws[ok])
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
        t.window = max(1, int(round(cfg.gap.imu_window / flights[0].dt)))
        return t

    def _ideal(self, p: ModelParams, seed: int, M: int, fl, u: np.ndarray):
        sx = fl.sigma_xy if p.sigma_xy is None else p.sigma_xy
        sy = fl.sigma_yaw if p.sigma_yaw is None else p.sigma_yaw
        G = geometry_draws(sx, sy, M)
        h = self.window
        key = ("imu", fl.index, _rows_key(u), round(sx, 9), round(sy, 9), p.latency_imu, G, h)
        hit = self.cache.get(key)
        if hit is None:
            times = np.maximum(h + 1, fl.samples[u] - p.latency_imu)
            out = np.empty((times.size, fl.n_copters, 3, G))
            rp.imu_window_draws(fl.pos, fl.yaw_unwrapped, fl.t, times, h, fl.noise(sx, sy, seed), G, out)
            hit = self.cache.put(key, (out,))
        return hit

    def draws(self, flights, p: ModelParams, rows: np.ndarray, seed: int, M: int):
        (ideal,), period = _gather(self, flights, rows, lambda fl, u: self._ideal(p, seed, M, fl, u), M)
        ch = self.channel[rows]
        ws = self.window_s[rows]
        # bias: body-frame accelerometer bias rotated into each window's world-frame integral
        bias = self.bias_gain[rows, 0] * p.acc_bias_x + self.bias_gain[rows, 1] * p.acc_bias_y
        bias = np.where(ch == 2, p.gyro_bias * ws, bias)
        white = np.where(ch == 2, p.gyro_white, p.acc_white)
        walk = np.where(ch == 2, p.gyro_walk, p.acc_walk)
        dt_mean = ws / self.window
        # Σ of h white samples times dt, and a bias random walk of std walk·sqrt(t) integrated over the window
        sd = np.sqrt(self.window * (white * dt_mean) ** 2 + (walk * ws) ** 2 * self.seconds[rows])
        out = np.empty_like(ideal)
        _gauss_error(np.ascontiguousarray(ideal), self.flight[rows], self.time[rows], self.copter[rows] * 4 + ch, seed,
                     np.ascontiguousarray(sd), np.zeros(rows.size), np.zeros(rows.size), np.ascontiguousarray(bias), out)
        return out, period


def _append_identity(cols, f, y, sel, sample_pos, copter, channel):
    """Append the identity columns of the selected readings y[sel] of flight f to ``cols``.

    sample_pos, copter, channel: index arrays shaped like y (sample_pos indexes ``f.samples``).
    """
    cols["y"].append(y[sel])
    cols["flight"].append(np.full(int(np.count_nonzero(sel)), f.index))
    cols["sample"].append(sample_pos[sel])
    cols["time"].append(f.samples[sample_pos[sel]])
    cols["copter"].append(copter[sel])
    cols["channel"].append(channel[sel])
    cols["sec"].append(f.t[f.samples[sample_pos[sel]]] - f.t[0])


def _wall_distance(P, arena):
    """(..., ) distance (m) of copter centres P (..., 2) to the nearest wall line."""
    return np.minimum(np.minimum(P[..., 0], arena.width - P[..., 0]), np.minimum(P[..., 1], arena.length - P[..., 1]))


def _nearest_neighbor(P):
    """(K, N) distance from each copter centre to the nearest other one (inf alone)."""
    d = np.sqrt(((P[:, :, None, :] - P[:, None, :, :]) ** 2).sum(-1))
    n = P.shape[1]
    d[:, np.arange(n), np.arange(n)] = np.inf
    return d.min(axis=-1) if n > 1 else np.full(P.shape[:2], np.inf)


def _speed(f) -> np.ndarray:
    """(K, N) speed (m/s) at the used samples from central differences of the logged positions."""
    v = np.gradient(f.pos, f.t, axis=0)
    return np.sqrt((v[f.samples] ** 2).sum(-1))
