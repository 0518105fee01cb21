"""The model a diagnosis scores readings against: the simulator's own sensor records plus the knobs
that only a diagnosis turns.

:class:`ModelParams` holds the :class:`~finkensim.sensors.sonar_model.SonarModel`, the
:class:`~finkensim.sensors.ranging.RangingModel` and the :class:`~finkensim.sensors.imu.ImuModel`
exactly as the simulator builds them from the same config (one source of defaults and codes), plus
the world and recording effects a log can show that the simulator does not model (tracking noise,
wall-displacement gain, latency, ranging NLOS and dropout, constant IMU biases). Effects
(:mod:`finkensim.gap.attribute.effects`) return modified copies; ``sensor_key`` makes the parts a sensor depends on
hashable so that scores can be cached per sensor.

The sonar reading draws call :func:`~finkensim.sensors.sonar_kernels.measured_reading`, the simulator's
error model, with counter-based keys per (seed, flight, time, channel) and the draw index as the block:
a refit with other parameters reuses the same random numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from numba import njit, prange

from ...config import Config
from ...kernels.rng import STREAM_CORRECTION, STREAM_EFFECT, counter_key, normal, uniform
from ...sensors.correction_table import correction_quantile
from ...sensors.imu import ImuModel
from ...sensors.latency import lag_steps
from ...sensors.ranging import RangingModel
from ...kernels.raycast import HIT_NONE
from ...sensors.sonar_kernels import echo_error, measured_reading
from ...sensors.sonar_model import ERROR_NONE, SonarModel, rayleigh_std, sonar_scalars

__all__ = ["ModelParams", "SENSORS", "SENSOR_FIELDS", "SHARED_FIELDS", "hinge_key", "sonar_echo_errors", "sonar_reading_draws", "gaussian_draws", "lag_steps"]


@dataclass(frozen=True, eq=False)
class ModelParams:
    """Every parameter of the predictive model (SI units).

    sonar, ranging, imu: the simulator's sensor records (from the config). sigma_xy m, sigma_yaw rad:
    tracking noise of the logged poses (``None`` = each flight's own). wall_gain: factor on the modelled
    plate displacement (1 with bending walls, 0 with rigid ones). bulge_amplitude m, bulge_reach m, bulge_shape: an
    extra displacement ``amplitude · exp(−(d/reach)^shape)`` of each plate toward the arena, d its distance to the
    nearest copter body (the ``wall_bulge`` effect; shape 2 a Gaussian, larger a flat bulge that ends sharply near
    reach); bulge_response s: the plates follow that displacement with this
    first-order time constant (0: at once). beam_rays: rays of a cone beam when an
    effect widens a single-ray beam. latency_* s: readings describe the world that much earlier (negative:
    later, as after a clock offset that was too early); each flight applies it as whole log steps (:func:`lag_steps`).
    The radio effects (NLOS near a third copter, dropout, bias, scale, node delays, antenna offsets, NLOS tail)
    are the ``ranging`` record's own (:meth:`with_ranging`, :mod:`finkensim.sensors.ranging_radio`). Constant IMU biases are fields of the ``imu`` record
    (``acc_bias_x``, ``acc_bias_y``, ``gyro_bias``: the simulator's config keys ``imu.acc_bias``, ``imu.gyro_bias``).
    bulge_hinge in [0, 1]: the weight of the walls' own polynomial law in the bulge's target
    (:func:`~finkensim.arena.bulge_law`; 0 = the catalogue's law; the config's ``walls.bulge_hinge``, fitted by the
    flexible refit of :mod:`finkensim.gap.attribute.parsimony`). walls_hinge: the hinge walls the replay drives with
    the logged copters, (max_amplitude_deg deg, threshold m, hinge_height m) as the config keys ``walls.*`` of the same
    names (the simulator's hinge, :func:`~finkensim.world.walls_from_positions`; the other hinge keys are the
    config's); () = the walls the flights were prepared with (the diagnosed config's). The plates move by it only
    with ``wall_gain`` > 0 (the ``wall_bulge`` effect's hinge version sets both, :mod:`finkensim.gap.attribute.hinge`).
    """

    sonar: SonarModel
    ranging: RangingModel
    imu: ImuModel
    sigma_xy: float | None = None
    sigma_yaw: float | None = None
    wall_gain: float = 1.0
    bulge_amplitude: float = 0.0
    bulge_reach: float = 0.3
    bulge_response: float = 0.0
    bulge_shape: float = 2.0
    beam_rays: int = 7
    latency_sonar: float = 0.0
    latency_ranging: float = 0.0
    latency_imu: float = 0.0
    bulge_hinge: float = 0.0
    walls_hinge: tuple = ()

    @classmethod
    def from_config(cls, cfg: Config) -> "ModelParams":
        """The simulator's models of ``cfg`` (the ranging mixture file is read here) and neutral gap knobs."""
        return cls(sonar=SonarModel.from_config(cfg), ranging=RangingModel.from_config(cfg.ranging),
                   imu=ImuModel.from_config(cfg.imu, cfg.simulation.dt),
                   wall_gain=1.0 if cfg.walls.bending and "hinge" in cfg.walls.model else 0.0,
                   beam_rays=int(cfg.sonar.beam_rays), **_bulge_from_config(cfg.walls),
                   walls_hinge=hinge_key(cfg.walls),
                   latency_sonar=cfg.sonar.latency, latency_ranging=cfg.ranging.latency, latency_imu=cfg.imu.latency,
                   **_tracking_from_config(cfg.gap))

    def with_(self, **kw) -> "ModelParams":
        """A copy with the given fields replaced."""
        return replace(self, **kw)

    def with_sonar(self, **kw) -> "ModelParams":
        """A copy whose sonar model has the given fields replaced (``rayleigh_s`` follows ``sigma``)."""
        if "sigma" in kw and "rayleigh_s" not in kw:
            kw["rayleigh_s"] = rayleigh_std(kw["sigma"])
        return replace(self, sonar=self.sonar._replace(**kw))

    def with_ranging(self, **kw) -> "ModelParams":
        """A copy whose ranging model has the given radio effects replaced (``RangingModel.with_radio``)."""
        return replace(self, ranging=self.ranging.with_radio(**kw))

    def sensor_key(self, sensor: str) -> tuple:
        """A hashable key of everything the predictive of ``sensor`` depends on (computed once per sensor: a fit
        asks for it at every evaluation, and the record is frozen; its arrays are never changed in place)."""
        keys = self.__dict__.setdefault("_sensor_keys", {})
        key = keys.get(sensor)
        if key is None:
            key = keys[sensor] = tuple(self.field_key(k) for k in SHARED_FIELDS + SENSOR_FIELDS[sensor])
        return key

    def field_key(self, name: str):
        """A hashable key of the field ``name`` (arrays by content, the ranging model by its parts)."""
        return _hashable(getattr(self, name))

    def walk_density(self) -> tuple[float, float]:
        """(accelerometer m/s²/√s, gyro rad/s/√s) bias random-walk densities of the IMU model."""
        sq = math.sqrt(self.imu.dt)
        return self.imu.acc_walk / sq, self.imu.gyro_walk / sq


def _tracking_from_config(gap) -> dict:
    """``sigma_xy``/``sigma_yaw``: the tracking noise ``gap.tracking_sigma_*`` states for every flight (the flights
    carry the same value, :func:`~finkensim.gap.replay.prepare_flights`), None (each log's own) when -1."""
    return {"sigma_xy": gap.tracking_sigma_xy if gap.tracking_sigma_xy >= 0 else None,
            "sigma_yaw": gap.tracking_sigma_yaw if gap.tracking_sigma_yaw >= 0 else None}


def hinge_key(walls) -> tuple:
    """(max_amplitude_deg, threshold m, hinge_height m) of a :class:`~finkensim.config.WallConfig`: the hinge walls
    of :attr:`ModelParams.walls_hinge`."""
    return (float(walls.max_amplitude_deg), float(walls.threshold), float(walls.hinge_height))


def _bulge_from_config(walls) -> dict:
    """The ``bulge_*`` fields of the curtain bulge the simulator flies (``walls.model``; amplitude 0 without)."""
    on = walls.bending and "bulge" in walls.model
    return dict(bulge_amplitude=walls.bulge_amplitude if on else 0.0, bulge_reach=walls.bulge_reach,
                bulge_response=walls.bulge_response, bulge_shape=walls.bulge_shape,
                bulge_hinge=walls.bulge_hinge if on else 0.0)


#: the diagnosed sensors by their gap-report keys (docs/formats/gap-report.md; "ultrasonic" is the report's key of
#: the sonar), in report order
SENSORS = ("ultrasonic", "ranging", "imu")
SHARED_FIELDS = ("sigma_xy", "sigma_yaw")
SENSOR_FIELDS = {
    "ultrasonic": ("sonar", "wall_gain", "bulge_amplitude", "bulge_reach", "bulge_response", "bulge_shape", "beam_rays", "latency_sonar",
                   "bulge_hinge", "walls_hinge"),
    "ranging": ("ranging", "latency_ranging"),
    "imu": ("imu", "latency_imu"),
}
assert {f.name for f in fields(ModelParams)} == set(SHARED_FIELDS).union(*SENSOR_FIELDS.values())


def _hashable(v):
    """v as a hashable value: arrays by dtype, shape and bytes; records field by field; RangingModel by its
    mode, ranges and mixture (by identity: it is loaded once per config)."""
    if isinstance(v, np.ndarray):
        return (v.dtype.str, v.shape, v.tobytes())
    if isinstance(v, RangingModel):
        return ("RangingModel", v.error, v.max_range, v.sigma, v.seed_variance_factor, id(v.mixture), v.radio_key())
    if isinstance(v, tuple):
        return tuple(_hashable(x) for x in v)
    return v


@njit(cache=True, parallel=True)
def sonar_echo_errors(flight, tidx, chan, seed, sp, out):
    """The echo errors (m) of the reading draws out (n, M) (:func:`~finkensim.sensors.sonar_kernels.echo_error`,
    keyed as in :func:`sonar_reading_draws`). They depend on the error model's parameters only, so every
    evaluation of a fit that leaves those alone shares them. ``sp.error`` must not be ERROR_NONE."""
    n, M = out.shape
    sps = sonar_scalars(sp)
    for i in prange(n):
        key = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT)
        for m in range(M):
            out[i, m] = echo_error(key, m, sps)


@njit(cache=True, parallel=True)
def sonar_reading_draws(dist, kind, xtalk, flight, tidx, chan, seed, sp, err, out):
    """Reading draws out (n, M) m from ideal draws dist (n, M) m, kind (n, M) (HIT_*), xtalk (n, M) m
    (cross-talk path, inf if none) with the simulator's error model ``sp`` (a SonarModel).

    Row i draws from ``counter_key(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT)``, draw m from block m;
    err (n, M) m: the echo errors from :func:`sonar_echo_errors` (not read when ``sp.error`` is ERROR_NONE).
    """
    n, M = dist.shape
    sps = sonar_scalars(sp)  # the per-reading calls take the scalars only (see SonarScalars)
    for i in prange(n):
        key = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT)
        if sps.error == ERROR_NONE:
            for m in range(M):
                out[i, m] = measured_reading(dist[i, m], kind[i, m] != HIT_NONE, xtalk[i, m], key, m, sps)
        else:
            for m in range(M):
                out[i, m] = measured_reading(dist[i, m], kind[i, m] != HIT_NONE, xtalk[i, m], key, m, sps, err[i, m])
        if sp.correction.shape[0] > 0:  # the learned correction the simulator flies (sonar.correction_file)
            ckey = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_CORRECTION)
            for m in range(M):
                if kind[i, m] != HIT_NONE and dist[i, m] < sps.max_range:
                    ref = sps.range_scale * dist[i, m] + sps.bias
                    r = ref + correction_quantile(sp.correction, ref, uniform(ckey, m))
                    out[i, m] = min(sps.max_range, max(sps.min_range, r))


@njit(cache=True, parallel=True)
def gaussian_draws(ideal, flight, tidx, chan, seed, sd, bias, out):
    """Draws out (n, M) = ideal (n, M) + bias (n,) + sd (n,)·N(0, 1), keyed like :func:`sonar_reading_draws`."""
    n, M = ideal.shape
    for i in prange(n):
        key = counter_key(seed, flight[i], tidx[i], chan[i], STREAM_EFFECT)
        for m in range(M):
            out[i, m] = ideal[i, m] + bias[i] + sd[i] * normal(key, m)
