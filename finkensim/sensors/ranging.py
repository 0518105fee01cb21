"""Virtual ranging: radio distances between ranging tags, with Parlow's Gaussian-mixture error.

Every copter carries an omnidirectional, unoccluded range sensor; fixed beacons may carry tags too.
Copter ``i`` measures its distance to every other copter and to every beacon. For a true distance X:

- the distance to itself reads exactly 0;
- X > ``max_range`` reads exactly ``max_range`` (the original "out of range" value), with no error;
- otherwise the error model gives the reading (``error`` in the ``[ranging]`` config section):

  ``mixture`` (default)
      The correct conditional draw from a K-component Gaussian mixture over (X, Y = measured
      distance): pick ONE component i with probability rᵢ(X) ∝ weightsᵢ·N(X; meanᵢ, covarᵢ), then
      draw Y ~ N(cond_meanᵢ + slopeᵢ·(X − meanᵢ), cond_covarᵢ). Parlow's model (the default
      :class:`Mixture`) has diagonal covariances, so every slope is 0.
  ``seed``
      The original V-REP script: exact responsibilities rᵢ(X), one normal draw per component with
      standard deviation sqrt(seed_variance_factor·covarᵢ) around cond_meanᵢ, and the reading is the
      rᵢ-weighted SUM of all K draws. (Slopes are ignored, as in the script.)
  ``gaussian``
      X + N(0, sigma²).
  ``none``
      X.

- with a learned correction (``ranging.correction_file``) a reading in range is the model's median reading plus
  the correction's quantile at a uniform draw instead (:func:`~finkensim.sensors.ranging_radio.corrected_reading`);
- a drawn reading below 0 is set to 0: a range cannot be negative, and the sensor reports 0 for a
  tag on top of it. (With Parlow's mixture this practically never happens: the smallest component
  mean of the measured distance is 0.256 m.) Readings above ``max_range`` caused by the error are
  kept: only the *true* distance decides "out of range".

**Modules.** :mod:`finkensim.sensors.mixture` holds the mixture (:class:`Mixture`, its files and
analytic laws); :mod:`finkensim.sensors.ranging_table` the alias tables the ``mixture`` mode samples
components from (:class:`ResponsibilityTable`, how exact they are); :mod:`finkensim.sensors.ranging_kernels`
the numba kernels (the per-reading rule :func:`~finkensim.sensors.ranging_kernels.reading_rule`,
one environment :func:`~finkensim.sensors.ranging_kernels.ranging_env`) and the random-number layout.
This module builds the kernels' parameters and is the batched public API; it re-exports
:class:`Mixture`, :class:`MixtureError`, :class:`ResponsibilityTable` and the ``MODE_*`` codes.

**Params.** :class:`RangingModel` (``RangingModel.from_config(cfg.ranging)``) holds the mode, the
mixture, the table and ``params``: a :class:`~finkensim.sensors.ranging_kernels.RangingParams` record
of scalars and read-only arrays that numba kernels take as one argument (``ideal_params``: the same
with mode ``none``, i.e. the true distances). :func:`ranging_readings` is the batched sensor;
:meth:`RangingModel.sample` draws readings for given true distances (tests, diagnostics);
:func:`ideal_ranges` gives the true distances.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from ..arrays import as_array, as_env_ids, as_points, check_inplace
from ..config import ConfigError
from .mixture import Mixture, MixtureError
from .ranging_kernels import (MODE_GAUSSIAN, MODE_MIXTURE, MODE_NONE, MODE_SEED, MODES, RangingParams,
                              ranging_along_poses, ranging_batch, row_key, sample_readings)
from .correction_table import NO_TABLE, CorrectionTable, read_correction
from .ranging_radio import RadioParams, neutral_radio
from .ranging_table import ResponsibilityTable, cached_table

__all__ = [
    "MODES",
    "MODE_GAUSSIAN",
    "MODE_MIXTURE",
    "MODE_NONE",
    "MODE_SEED",
    "Mixture",
    "MixtureError",
    "RangingModel",
    "RangingParams",
    "RadioParams",
    "RADIO_KEYS",
    "ResponsibilityTable",
    "ideal_ranges",
    "ranging_readings",
    "readings_along_poses",
]


class RangingModel:
    """Everything the ranging kernels need, built once from the config.

    ``error``: ``"mixture"`` | ``"seed"`` | ``"gaussian"`` | ``"none"``; ``max_range`` m; ``sigma`` m
    (``gaussian``); ``mixture``: a :class:`Mixture` (default :meth:`Mixture.default`; only loaded for
    mixture/seed); ``seed_variance_factor`` (``seed``); ``beacons``: (M, 2) fixed tags in m;
    ``table_tol``: the table's total-variation tolerance. ``table`` is the :class:`ResponsibilityTable`
    in mixture mode, else None. ``correction``: the learned correction's
    :class:`~finkensim.sensors.correction_table.CorrectionTable` (None = none). ``params`` is the kernels'
    :class:`RangingParams`, ``ideal_params`` the same with mode ``none`` (readings = true distances, no random numbers
    used).
    """

    def __init__(self, error: str = "mixture", max_range: float = 2.5, sigma: float = 0.1,
                 mixture: Mixture | None = None, seed_variance_factor: float = 10.0, beacons=(),
                 table_tol: float = 1e-4, correction: CorrectionTable | None = None, **radio):
        if error not in MODES:
            raise ValueError(f"ranging.error = {error!r}: expected one of {', '.join(map(repr, MODES))}")
        if not (max_range > 0 and math.isfinite(max_range)):
            raise ValueError(f"ranging.max_range = {max_range!r}: expected a finite number > 0")
        if not (sigma >= 0 and math.isfinite(sigma)):
            raise ValueError(f"ranging.sigma = {sigma!r}: expected a finite number >= 0")
        if not (seed_variance_factor > 0 and math.isfinite(seed_variance_factor)):
            raise ValueError(f"ranging.seed_variance_factor = {seed_variance_factor!r}: expected > 0")
        self.error = error
        self.mode = MODES[error]
        self.max_range = float(max_range)
        self.sigma = float(sigma)
        self.seed_variance_factor = float(seed_variance_factor)
        self.beacons = as_points("beacons", beacons, ("M",), allow_empty=True)
        if mixture is None and error in ("mixture", "seed"):
            mixture = Mixture.default()
        self.mixture = mixture
        self.table = cached_table(mixture, self.max_range, table_tol) if error == "mixture" else None
        unknown = sorted(set(radio) - set(RADIO_KEYS))
        if unknown:
            raise TypeError(f"RangingModel: unknown radio effect {unknown[0]!r}; expected one of {RADIO_KEYS}")
        self.radio = {**RADIO_DEFAULTS, **radio}
        self.correction = correction
        self.params = self._params()
        self.ideal_params = self.params._replace(mode=np.int64(MODE_NONE), **neutral_radio()._asdict(),
                                                 correction=NO_TABLE)

    def with_radio(self, **changes) -> "RangingModel":
        """A copy with the given radio effects (keys of ``RADIO_KEYS``, units as the ``[ranging]`` config keys
        of the same names) replaced; the error model, its table and mixture are shared."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new.radio = {**self.radio, **changes}
        new.params = self.params._replace(**self._radio_fields(new.radio))
        return new

    def _radio_fields(self, radio: dict) -> dict:
        """The radio fields of the kernels' record for the effects ``radio``; ``radio_on`` also with a correction
        (the correction runs on the radio path)."""
        fields = radio_params(radio)._asdict()
        if self.correction is not None:
            fields["radio_on"] = np.int64(1)
        return fields

    def noise_key(self) -> tuple:
        """A hashable key of the error model alone (what :meth:`sample` depends on; the radio effects left out)."""
        return ("RangingModel", self.error, self.max_range, self.sigma, self.seed_variance_factor, id(self.mixture))

    def radio_key(self) -> tuple:
        """A hashable key of the radio effects (canonical: trailing zero delays and offsets dropped) and of the
        learned correction, if any."""
        r = radio_params(self.radio)
        key = tuple(v.tobytes() if isinstance(v, np.ndarray) else float(v) for v in r)
        return key if self.correction is None else key + (self.params.correction.tobytes(),)

    def __setstate__(self, state):
        # pickle (process pools, Dask, deepcopy) restores every array writeable; the kernels' records must keep their
        # read-only arrays, or each compiled kernel that takes them (the whole closed-loop engine among them) is
        # compiled again for the second type: ≈ 30 s in each worker process of a sweep
        self.__dict__.setdefault("correction", None)
        self.__dict__.update(state)
        self.params = _readonly_params(self.params)
        self.ideal_params = _readonly_params(self.ideal_params)

    @classmethod
    def from_config(cls, cfg, mixture: Mixture | None = None, table_tol: float = 1e-4) -> "RangingModel":
        """From a ``RangingConfig`` (``cfg.ranging``); ``mixture_file`` is loaded unless ``mixture`` is given, and the
        ``ranging`` table of ``correction_file``."""
        correction = (read_correction(cfg.correction_file, "ranging", key="ranging.correction_file")
                      if cfg.correction_file else None)
        if mixture is None and cfg.mixture_file and cfg.error in ("mixture", "seed"):
            try:
                mixture = Mixture.load(cfg.mixture_file)
            except MixtureError as exc:
                raise MixtureError(f"ranging.mixture_file = {cfg.mixture_file!r}: {exc}") from None
        return cls(error=cfg.error, max_range=cfg.max_range, sigma=cfg.sigma, mixture=mixture,
                   seed_variance_factor=cfg.seed_variance_factor, beacons=cfg.beacons, table_tol=table_tol,
                   correction=correction, **{k: getattr(cfg, k) for k in RADIO_KEYS})

    def _params(self) -> RangingParams:
        """The kernels' record (layout in :class:`RangingParams`); unused parts are 1-element placeholders."""
        mix = self.mixture
        if self.table is not None:
            inv_h, prob, alias = self.table.inv_h, self.table.prob, self.table.alias
        else:
            inv_h, prob, alias = 1.0, np.ones((2, 1)), np.zeros((2, 1), dtype=np.int32)
        if mix is not None:
            with np.errstate(divide="ignore"):
                log_wn = np.log(mix.weights) - 0.5 * np.log(2.0 * np.pi * mix.covar)
            arrays = (mix.mean, mix.slope, mix.cond_mean, np.sqrt(mix.cond_covar), log_wn,
                      0.5 / mix.covar, np.sqrt(self.seed_variance_factor * mix.covar))
        else:
            arrays = tuple(np.zeros(1) for _ in range(7))
        # read-only arrays throughout, so every mode has the same numba type (one compilation)
        comp = np.stack([np.asarray(a, dtype=np.float64) for a in arrays], axis=1)  # (K, 7), columns COMP_*
        if self.correction is None:
            correction, median = NO_TABLE, np.zeros(2)
        else:
            correction, median = self.correction.packed(), error_medians(self, MEDIAN_NODES)
        radio = RadioParams(**self._radio_fields(self.radio))
        return _readonly_params(RangingParams(np.int64(self.mode), float(self.max_range), float(self.sigma),
                                              float(inv_h), prob, alias, comp, *radio, correction, median))

    def sample(self, x, seed: int = 0, env: int = 0, step: int = 0, copter: int = 0) -> np.ndarray:
        """Readings, m, for true distances ``x`` m (any shape; element j of the flattened array uses reading
        column j of copter ``copter``'s key), with the same rules as :func:`ranging_readings`."""
        x = as_array("x", x, np.float64, unit="m")
        xs = x.ravel()
        bad = np.flatnonzero(~(xs >= 0))
        if bad.size:
            raise ConfigError(f"x (flattened)[{bad[0]}] = {xs[bad[0]].item()!r}: expected true distances >= 0 m "
                              f"(+inf reads max_range)")
        out = np.empty_like(xs)
        sample_readings(xs, row_key(seed, env, step, copter), self.params, out)
        return out.reshape(x.shape)

    def __repr__(self) -> str:
        extra = f", table={self.table!r}" if self.table is not None else ""
        return (f"RangingModel(error={self.error!r}, max_range={self.max_range}, sigma={self.sigma}, "
                f"beacons={len(self.beacons)}, mixture={self.mixture!r}{extra})")


def _ro(a, dtype) -> np.ndarray:
    """``a`` as a read-only C-contiguous array of ``dtype`` (no copy if it already is one)."""
    if isinstance(a, np.ndarray) and a.dtype == dtype and a.flags.c_contiguous and not a.flags.writeable:
        return a
    a = np.array(a, dtype=dtype, order="C", copy=True)
    a.setflags(write=False)
    return a


def _readonly_params(p: RangingParams) -> RangingParams:
    """``p`` with its arrays read-only (the one numba type of :class:`RangingParams`)."""
    return p._replace(prob=_ro(p.prob, np.float64), alias=_ro(p.alias, np.int32), comp=_ro(p.comp, np.float64),
                      node_delay=_ro(p.node_delay, np.float64), antenna=_ro(p.antenna, np.float64),
                      correction=_ro(p.correction, np.float64), median=_ro(p.median, np.float64))


#: nodes of the error model's median reading over [0, max_range] (``RangingParams.median``)
MEDIAN_NODES = 1025


def error_medians(model: "RangingModel", R: int) -> np.ndarray:
    """The median reading m of the error model of ``model`` (clipped at 0, as a reading) at the true distances
    x_k = k·max_range/(R − 1), k = 0 … R − 1: (R,). ``mixture``: the conditional mixture's CDF solved by bisection
    (to 1e-9 m); ``seed``: the mean of its normal reading; ``gaussian``, ``none``: x."""
    x = np.linspace(0.0, model.max_range, R)
    if model.error == "seed":
        return np.maximum(model.mixture.seed_mean_std(x, model.seed_variance_factor)[0], 0.0)
    if model.error != "mixture":
        return x
    mu, sd = model.mixture.component_conditionals(x)
    lo, hi = (mu - 10.0 * sd).min(axis=-1), (mu + 10.0 * sd).max(axis=-1)
    while np.max(hi - lo) > 1e-9:
        mid = 0.5 * (lo + hi)
        below = model.mixture.conditional_cdf(mid, x) < 0.5
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return np.maximum(0.5 * (lo + hi), 0.0)


@functools.lru_cache(maxsize=16)
def _model_for_config(cfg) -> "RangingModel":
    return RangingModel.from_config(cfg)


def ranging_readings(positions, beacons, seed: int, env_ids, step: int, params: RangingModel,
                     ideal: bool = False, out: np.ndarray | None = None, yaw=None) -> np.ndarray:
    """The virtual-ranging readings of a batch: (B, N, N + M) float64, m.

    ``positions`` (B, N, 2) copter positions, m; ``beacons`` (M, 2) fixed tags (may be empty);
    ``seed`` the run seed; ``env_ids`` (B,) int64 global environment indices (row b equals a B = 1
    run with ``env_ids=[env_ids[b]]``); ``step`` the step index; ``params`` a :class:`RangingModel`
    (a ``RangingConfig`` is accepted and converted, cached). Row i = measuring copter, columns = copters
    0…N−1 then beacons. ``ideal=True`` returns the true distances (self 0, clipped at max_range)
    without drawing random numbers. ``out`` may be a preallocated C-contiguous float64 array. ``yaw`` (B, N)
    rad: the headings (read by the antenna offsets; None = 0). A reading lost to dropout is NaN.
    Wrong inputs raise :class:`~finkensim.config.ConfigError` naming the array.
    """
    if not isinstance(params, RangingModel):
        params = _model_for_config(params)
    pos = as_points("positions", positions, ("B", "N"))
    bea = as_points("beacons", beacons, ("M",), allow_empty=True)
    n_env, n, _ = pos.shape
    env = as_env_ids("env_ids", env_ids, n_env)
    shape = (n_env, n, n + bea.shape[0])
    out = np.empty(shape) if out is None else check_inplace("out", out, shape)
    p = params.ideal_params if ideal else params.params
    yaws = np.zeros(pos.shape[:2]) if yaw is None else as_array("yaw", yaw, np.float64, unit="rad")
    if yaws.shape != pos.shape[:2]:
        raise ConfigError(f"yaw has shape {yaws.shape}: expected {pos.shape[:2]} (B, N) rad like positions")
    ranging_batch(pos, np.ascontiguousarray(yaws), bea, np.int64(seed), env, np.int64(step), p, out)
    return out


def readings_along_poses(pose, params: RangingModel, *, z=None, seed: int = 0, env: int = 0,
                         step0: int = 0) -> np.ndarray:
    """The copters' ranging readings of each other along given poses (a recorded flight): (T, N, N) float64, m.

    The simulator's own kernel (:func:`~finkensim.sensors.ranging_kernels.ranging_along_poses`): sample k reads
    what the engine reads at step ``step0 + k`` of environment ``env`` of the run ``seed`` with the copters at
    those poses, at 3-D (tag-to-tag) distances where heights are given. Row i = measuring copter, diagonal 0, a
    reading lost to dropout NaN. Fixed beacons (``ranging.beacons``) are not read: nodes are the poses' copters.

    Parameters
    ----------
    pose : array_like, shape (T, N, 3)
        x m, y m, heading rad of each copter at each sample (a flight log's ``pose``).
    params : RangingModel
        The sensor model (a ``RangingConfig`` is accepted and converted, cached).
    z : array_like, shape (T, N), optional
        Each copter's height, m (a flight log's ``z``); None = every copter at one height (planar distances).
    seed : int
        The run seed of the counter keys.
    env : int
        The environment index of the counter keys.
    step0 : int
        The step index of sample 0 (sample k is step ``step0 + k``).

    Returns
    -------
    ndarray, shape (T, N, N)
        Readings, m.

    Raises
    ------
    ConfigError
        A wrong array, named.
    """
    if not isinstance(params, RangingModel):
        params = _model_for_config(params)
    p = as_array("pose", pose, np.float64, ("T", "N", 3), unit="m, m, rad", finite=True)
    T, n, _ = p.shape
    h = np.zeros((T, n)) if z is None else as_array("z", z, np.float64, ("T", "N"), sizes={"T": T, "N": n}, unit="m",
                                                        finite=True)
    out = np.empty((T, n, n))
    ranging_along_poses(np.ascontiguousarray(p[..., :2]), h, np.ascontiguousarray(p[..., 2]), np.int64(seed),
                        np.int64(env), np.int64(step0), params.params, out)
    return out


def ideal_ranges(positions, beacons=(), max_range: float = 2.5) -> np.ndarray:
    """True distances (B, N, N + M) m of ``positions`` (B, N, 2) m and ``beacons`` (M, 2) m: self 0,
    anything beyond ``max_range`` m set to ``max_range``."""
    pos = as_points("positions", positions, ("B", "N"))
    model = RangingModel("none", max_range=max_range)
    env = np.zeros(pos.shape[0], dtype=np.int64)
    return ranging_readings(pos, beacons, 0, env, 0, model, ideal=True)


#: The radio effects' keys (the ``[ranging]`` config keys of the same names) and their neutral defaults.
RADIO_DEFAULTS = {"bias": 0.0, "scale": 1.0, "node_delay": (), "antenna_offset": (0.0, 0.0, 0.0),
                  "antenna_offset_per_copter": (), "nlos_bias": 0.0, "nlos_width": 0.2,
                  "nlos_tail_probability": 0.0, "nlos_tail_mean": 0.3, "dropout_a": -100.0, "dropout_b": 0.0}
RADIO_KEYS = tuple(RADIO_DEFAULTS)
#: ``dropout_a`` at or below this means no dropout at all (the config's lower bound)
DROPOUT_NEVER = -100.0


def _trim(a: np.ndarray) -> np.ndarray:
    """``a`` without its trailing all-zero rows (one canonical form per set of values)."""
    nz = np.flatnonzero(np.any(a.reshape(a.shape[0], -1) != 0.0, axis=1)) if a.size else np.zeros(0, int)
    return a[:nz[-1] + 1] if nz.size else a[:0]


def radio_params(v: dict) -> RadioParams:
    """The kernels' :class:`RadioParams` of the radio effects ``v`` (keys of ``RADIO_KEYS``, config units)."""
    delay = _trim(np.asarray(v["node_delay"], dtype=np.float64).reshape(-1))
    per = np.asarray(v["antenna_offset_per_copter"], dtype=np.float64).reshape(-1, 2)
    per = _trim(np.concatenate([per, np.zeros((per.shape[0], 1))], axis=1))
    shared = np.asarray(v["antenna_offset"], dtype=np.float64).reshape(1, 3)
    antenna = np.concatenate([shared, per], axis=0)
    a = float(v["dropout_a"])
    dropout_on = a > DROPOUT_NEVER
    antenna_on = bool(np.any(antenna != 0.0))
    nlos_on = float(v["nlos_bias"]) != 0.0
    tail_on = float(v["nlos_tail_probability"]) > 0.0
    on = (antenna_on or nlos_on or tail_on or dropout_on or delay.size > 0 or float(v["scale"]) != 1.0
          or float(v["bias"]) != 0.0)
    out = RadioParams(np.int64(on), np.int64(antenna_on), np.int64(nlos_on), np.int64(tail_on), np.int64(dropout_on),
                      float(v["scale"]), float(v["bias"]), delay, antenna, float(v["nlos_bias"]),
                      float(v["nlos_width"]), float(v["nlos_tail_probability"]), float(v["nlos_tail_mean"]),
                      a if dropout_on else -np.inf, float(v["dropout_b"]))
    for arr in (out.node_delay, out.antenna):
        arr.setflags(write=False)
    return out
