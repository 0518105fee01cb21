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

- a drawn reading below 0 is set to 0: a range cannot be negative, and the sensor reports 0 for a
  tag on top of it. (With Parlow's mixture this practically never happens: the smallest component
  mean of the measured distance is 0.256 m.) Readings above ``max_range`` caused by the error are
  kept: only the *true* distance decides "out of range".

**Fast mixture sampling.** Evaluating K = 100 exponentials per reading is avoided by a
:class:`ResponsibilityTable`: the exact responsibilities r(x_g) at G equally spaced nodes
x_g = g·h on [0, max_range], each stored as a Walker/Vose alias table (O(1) sampling). For X between
nodes x_g and x_{g+1} the kernel takes node g+1 with probability f = (X − x_g)/h and node g
otherwise, which samples exactly the linear interpolation (1 − f)·r(x_g) + f·r(x_{g+1}) of the node
distributions. The node spacing is chosen at build time so that the total-variation distance between
that interpolation and the exact r(X) is below ``tol`` (default 1e-4); the realised maximum, measured
on a grid 16 times finer than the nodes using the distributions the alias tables actually encode, is
``table.max_tv_error`` (Parlow's model on [0, 2.5] m: 1640 nodes, h = 1.53 mm, 9.1e-5; the error is
O(h²), largest near X = 0.295 m). Any probability computed from a reading is therefore off by at most
that much. The table is 1640 × 100 × 12 bytes ≈ 2 MB and takes ≈ 0.1 s to build (cached per mixture).

**Random numbers.** Every draw is a counter-based uniform (:mod:`finkensim.kernels.rng`) of the key
``counter_key(seed, env_id, step, i, STREAM_RANGING)`` of the *measuring* copter ``i``; reading
column ``j`` (0…N−1 copters, N…N+M−1 beacons) uses its own indices, so i→j and j→i are independent
and a reading depends only on (seed, env_id, step, i, j), never on the batch size or thread count:

- ``mixture``: uniform ``4j`` picks the node, uniform ``4j+1`` the alias column (integer part of
  u·K) and the alias coin (fractional part), ``normal(key, 2j+1)`` (uniforms 4j+2, 4j+3) the noise;
- ``seed``: ``normal(key, j·K + i)`` for component i;
- ``gaussian``: ``normal(key, j)``.

**Params.** :class:`RangingModel` (``RangingModel.from_config(cfg.ranging)``) holds the mode, the
mixture, the table and ``params``: a flat tuple of scalars and read-only arrays that numba kernels
take as one argument (layout in :meth:`RangingModel._params`; unpack it once per kernel, outside the
loops). :func:`ranging_readings` is the batched sensor; :meth:`RangingModel.sample` draws readings for
given true distances (tests, diagnostics).

**Cost** (one core, shared machine): mixture ≈ 30 ns per reading, of which ≈ 19 ns are its random
numbers (2 uniforms + 1 Box–Muller normal); the exact 100-exponential draw would be ≈ 500 ns.
``seed`` ≈ 2.6 µs (100 normals ≈ 2.1 µs); ``gaussian`` ≈ 19 ns.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numba import njit, prange

from finkensim.kernels.rng import STREAM_RANGING, counter_key, normal, uniform

__all__ = [
    "MODES",
    "Mixture",
    "MixtureError",
    "RangingModel",
    "ResponsibilityTable",
    "ideal_ranges",
    "ranging_readings",
]

MODE_NONE = 0
MODE_GAUSSIAN = 1
MODE_MIXTURE = 2
MODE_SEED = 3
MODES = {"none": MODE_NONE, "gaussian": MODE_GAUSSIAN, "mixture": MODE_MIXTURE, "seed": MODE_SEED}

_ARRAYS = ("weights", "mean", "covar", "cond_mean", "cond_covar")
_UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
_DEFAULT_FILE = Path(__file__).resolve().parent.parent / "data" / "vranging_gmm_m.json"


class MixtureError(ValueError):
    """A mixture file or array is invalid. The message names the array and what is wrong."""


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------------------------------
# Mixture
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Mixture:
    """A Gaussian mixture over (X = true distance, Y = measured distance), in metres and m².

    Arrays, all of shape (K,):

    ``weights``    prior weight of each component (≥ 0, sums to 1 within 1e-3)
    ``mean``       mean of X of each component, m
    ``covar``      variance of X of each component, m² (> 0)
    ``cond_mean``  mean of Y of each component at X = ``mean`` (the component's Y mean), m
    ``cond_covar`` variance of Y given X of each component, m² (> 0). For a diagonal covariance this
                   is the Y variance; for a full one, cov_yy − cov_xy²/cov_xx.
    ``slope``      dE[Y | X]/dX within each component: cov_xy/cov_xx (0 for diagonal covariances).

    Given X, component i has conditional law N(cond_meanᵢ + slopeᵢ·(X − meanᵢ), cond_covarᵢ) and
    conditional weight rᵢ(X) ∝ weightsᵢ·N(X; meanᵢ, covarᵢ). Instances are immutable (read-only
    arrays). ``source`` is free-form metadata (where the numbers come from).
    """

    weights: np.ndarray
    mean: np.ndarray
    covar: np.ndarray
    cond_mean: np.ndarray
    cond_covar: np.ndarray
    slope: np.ndarray | None = None
    source: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        if self.slope is not None:
            arrays["slope"] = self.slope
        checked = _validate_arrays(arrays, "mixture")
        for name, value in checked.items():
            object.__setattr__(self, name, _readonly(value))
        if self.slope is None:
            object.__setattr__(self, "slope", _readonly(np.zeros_like(checked["weights"])))
        object.__setattr__(self, "source", dict(self.source))

    # -- basic properties ------------------------------------------------------------------------

    @property
    def n_components(self) -> int:
        return int(self.weights.shape[0])

    def __len__(self) -> int:
        return self.n_components

    @property
    def is_diagonal(self) -> bool:
        """True if every slope is 0 (the conditional means do not depend on X)."""
        return not np.any(self.slope)

    @property
    def digest(self) -> str:
        """SHA-1 of the arrays (identifies the numbers, e.g. for caching tables)."""
        h = hashlib.sha1()
        for name in _ARRAYS + ("slope",):
            h.update(np.ascontiguousarray(getattr(self, name)).tobytes())
        return h.hexdigest()

    def __repr__(self) -> str:
        kind = "diag" if self.is_diagonal else "with slopes"
        return f"Mixture(K={self.n_components}, {kind}, digest={self.digest[:10]})"

    # -- constructors ----------------------------------------------------------------------------

    @classmethod
    def default(cls) -> "Mixture":
        """Parlow's K = 100 model (``finkensim/data/vranging_gmm_m.json``; see ``data/README.md``)."""
        global _DEFAULT_MIXTURE
        if _DEFAULT_MIXTURE is None:
            _DEFAULT_MIXTURE = cls.load(_DEFAULT_FILE)
        return _DEFAULT_MIXTURE

    @classmethod
    def from_joint(cls, weights, means, covariances, source: Mapping[str, Any] | None = None) -> "Mixture":
        """From joint (X, Y) parameters: ``means`` (K, 2); ``covariances`` (K, 2) diagonal or (K, 2, 2) full."""
        w = np.asarray(weights, dtype=np.float64)
        mu = np.asarray(means, dtype=np.float64)
        cov = np.asarray(covariances, dtype=np.float64)
        k = w.shape[0] if w.ndim == 1 else -1
        if mu.shape != (k, 2):
            raise MixtureError(f"mixture: array 'means' has shape {mu.shape}, expected ({k}, 2) (X, Y per component)")
        if cov.shape == (k, 2):
            return cls(w, mu[:, 0], cov[:, 0], mu[:, 1], cov[:, 1], None, source or {})
        if cov.shape != (k, 2, 2):
            raise MixtureError(f"mixture: array 'covariances' has shape {cov.shape}, expected ({k}, 2) or ({k}, 2, 2)")
        cxx, cxy, cyx, cyy = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 0], cov[:, 1, 1]
        if not np.allclose(cxy, cyx, rtol=1e-9, atol=1e-15):
            raise MixtureError("mixture: array 'covariances' is not symmetric")
        if np.any(~(cxx > 0)):
            i = int(np.argmin(np.where(np.isfinite(cxx), cxx, -np.inf)))
            raise MixtureError(f"mixture: array 'covariances'[{i}, 0, 0] = {cxx[i]!r}: X variance must be > 0")
        slope = cxy / cxx
        cond_var = cyy - cxy * slope
        if np.any(~(cond_var > 0)):
            i = int(np.argmin(np.where(np.isfinite(cond_var), cond_var, -np.inf)))
            raise MixtureError(f"mixture: array 'covariances'[{i}] is not positive definite "
                               f"(conditional Y variance {cond_var[i]!r})")
        mean_y = mu[:, 1]
        return cls(w, mu[:, 0], cxx, mean_y, cond_var, slope, source or {})

    @classmethod
    def load(cls, path: str | Path) -> "Mixture":
        """Read a mixture from JSON or NPZ (see :meth:`save`); errors name the file and the array.

        JSON: an object with the five arrays as lists (or as ``{"values": [...]}`` objects, like the
        decoded ``shared/data/vranging_gmm.json``), optional ``slope``, optional ``units``
        (``{"distance": "m"|"cm"|"mm"}``; default m; converted to m) and optional ``source``.
        NPZ: arrays with the same names, in metres.
        """
        path = Path(path)
        where = f"mixture file {str(path)!r}"
        if not path.exists():
            raise MixtureError(f"{where} does not exist")
        suffix = path.suffix.lower()
        if suffix == ".json":
            try:
                data = json.loads(path.read_text())
            except json.JSONDecodeError as exc:
                raise MixtureError(f"{where}: invalid JSON: {exc}") from None
            if not isinstance(data, dict):
                raise MixtureError(f"{where}: expected a JSON object with arrays {', '.join(_ARRAYS)}")
            arrays = {}
            for name in _ARRAYS + ("slope",):
                if name not in data:
                    if name == "slope":
                        continue
                    raise MixtureError(f"{where}: array {name!r} is missing")
                value = data[name]
                if isinstance(value, dict):
                    if "values" not in value:
                        raise MixtureError(f"{where}: array {name!r} is an object without 'values'")
                    value = value["values"]
                arrays[name] = value
            units = data.get("units", {}) or {}
            unit = units.get("distance", "m") if isinstance(units, dict) else units
            if unit not in _UNIT_SCALE:
                raise MixtureError(f"{where}: units.distance = {unit!r}: expected one of {', '.join(_UNIT_SCALE)}")
            source = data.get("source", {})
            source = source if isinstance(source, dict) else {"source": source}
        elif suffix == ".npz":
            with np.load(path, allow_pickle=False) as npz:
                arrays = {}
                for name in _ARRAYS + ("slope",):
                    if name in npz.files:
                        arrays[name] = npz[name]
                    elif name != "slope":
                        raise MixtureError(f"{where}: array {name!r} is missing (found {', '.join(npz.files)})")
                source = {"file": str(path)}
            unit = "m"
        else:
            raise MixtureError(f"{where}: unknown format {suffix!r}; expected .json or .npz")
        checked = _validate_arrays(arrays, where)
        s = _UNIT_SCALE[unit]
        for name in ("mean", "cond_mean"):
            checked[name] = checked[name] * s
        for name in ("covar", "cond_covar"):
            checked[name] = checked[name] * (s * s)
        source = dict(source)
        if unit != "m":
            source["converted_from_units"] = unit
        return cls(checked["weights"], checked["mean"], checked["covar"], checked["cond_mean"],
                   checked["cond_covar"], checked.get("slope"), source)

    def save(self, path: str | Path) -> None:
        """Write JSON (plain lists, metres, with ``units`` and ``source``) or NPZ, by the file suffix."""
        path = Path(path)
        suffix = path.suffix.lower()
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        if not self.is_diagonal:
            arrays["slope"] = self.slope
        if suffix == ".json":
            data: dict[str, Any] = {
                "format": "finkensim ranging mixture v1",
                "source": dict(self.source),
                "n_components": self.n_components,
                "covariance_type": "diag" if self.is_diagonal else "conditional (slope)",
                "units": {"distance": "m", "variance": "m^2"},
            }
            data.update({name: [float(v) for v in a] for name, a in arrays.items()})
            path.write_text(json.dumps(data, indent=1) + "\n")
        elif suffix == ".npz":
            np.savez(path, **arrays)
        else:
            raise MixtureError(f"mixture file {str(path)!r}: unknown format {suffix!r}; expected .json or .npz")

    @classmethod
    def fit(cls, true, measured, n_components: int, covariance_type: str = "diag", seed: int = 0,
            **gmm_kwargs) -> "Mixture":
        """Fit a mixture to paired (true, measured) distances in m with scikit-learn's GaussianMixture.

        ``covariance_type`` is ``"diag"`` (Parlow's form, slopes 0) or ``"full"`` (per-component
        regression slope of the measured on the true distance). ``seed`` is GaussianMixture's
        ``random_state``; further keyword arguments (``n_init``, ``reg_covar``, ...) are passed on.
        """
        try:
            from sklearn.mixture import GaussianMixture
        except ImportError:  # pragma: no cover - depends on the environment
            raise ImportError("Mixture.fit needs scikit-learn: pip install finkensim[fit]") from None
        if covariance_type not in ("diag", "full"):
            raise ValueError(f"covariance_type = {covariance_type!r}: expected 'diag' or 'full'")
        x = np.asarray(true, dtype=np.float64).ravel()
        y = np.asarray(measured, dtype=np.float64).ravel()
        if x.shape != y.shape:
            raise ValueError(f"true and measured must have the same length, got {x.size} and {y.size}")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
            raise ValueError("true and measured must be finite")
        if x.size < n_components:
            raise ValueError(f"need at least n_components = {n_components} samples, got {x.size}")
        gm = GaussianMixture(n_components=n_components, covariance_type=covariance_type,
                             random_state=seed, **gmm_kwargs)
        gm.fit(np.column_stack([x, y]))
        source = {"fit": f"sklearn GaussianMixture, K={n_components}, covariance_type={covariance_type}, "
                         f"seed={seed}, n={x.size}"}
        return cls.from_joint(gm.weights_, gm.means_, gm.covariances_, source)

    # -- the analytic conditional mixture ---------------------------------------------------------

    def log_joint_x(self, x) -> np.ndarray:
        """log(weightsᵢ · N(x; meanᵢ, covarᵢ)), shape x.shape + (K,)."""
        x = np.asarray(x, dtype=np.float64)[..., None]
        with np.errstate(divide="ignore"):
            logw = np.log(self.weights)
        return logw - 0.5 * np.log(2.0 * np.pi * self.covar) - 0.5 * (x - self.mean) ** 2 / self.covar

    def responsibilities(self, x) -> np.ndarray:
        """rᵢ(x), the conditional component weights given true distance(s) x: shape x.shape + (K,)."""
        lp = self.log_joint_x(x)
        lp = lp - lp.max(axis=-1, keepdims=True)
        p = np.exp(lp)
        return p / p.sum(axis=-1, keepdims=True)

    def component_conditionals(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Per-component conditional (mean, std) of Y given x, each of shape x.shape + (K,)."""
        x = np.asarray(x, dtype=np.float64)[..., None]
        mu = self.cond_mean + self.slope * (x - self.mean)
        sd = np.broadcast_to(np.sqrt(self.cond_covar), mu.shape)
        return mu, sd

    def conditional_cdf(self, y, x, clip_at_zero: bool = False) -> np.ndarray:
        """P(Y ≤ y | X = x) of the conditional mixture; y and x broadcast together.

        ``clip_at_zero=True`` gives the CDF of max(Y, 0), i.e. of the sensor's reading (0 for y < 0,
        an atom at 0).
        """
        from scipy.special import ndtr

        y, x = np.broadcast_arrays(np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64))
        r = self.responsibilities(x)
        mu, sd = self.component_conditionals(x)
        cdf = np.sum(r * ndtr((y[..., None] - mu) / sd), axis=-1)
        if clip_at_zero:
            cdf = np.where(y < 0.0, 0.0, cdf)
        return cdf

    def conditional_pdf(self, y, x) -> np.ndarray:
        """Density of Y at y given X = x (1/m); y and x broadcast together."""
        y, x = np.broadcast_arrays(np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64))
        r = self.responsibilities(x)
        mu, sd = self.component_conditionals(x)
        z = (y[..., None] - mu) / sd
        return np.sum(r * np.exp(-0.5 * z * z) / (sd * math.sqrt(2.0 * math.pi)), axis=-1)

    def conditional_mean_std(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation of Y given X = x (the correct, ``mixture`` sampler), shape x.shape."""
        r = self.responsibilities(x)
        mu, sd = self.component_conditionals(x)
        m = np.sum(r * mu, axis=-1)
        var = np.sum(r * (sd * sd + mu * mu), axis=-1) - m * m
        return m, np.sqrt(np.maximum(var, 0.0))

    def seed_mean_std(self, x, variance_factor: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
        """Mean and std of the ``seed`` reading Σ rᵢ·N(cond_meanᵢ, factor·covarᵢ) given X = x (no clipping)."""
        r = self.responsibilities(x)
        m = np.sum(r * self.cond_mean, axis=-1)
        var = np.sum(r * r * (variance_factor * self.covar), axis=-1)
        return m, np.sqrt(var)


_DEFAULT_MIXTURE: Mixture | None = None


def _validate_arrays(arrays: Mapping[str, Any], where: str) -> dict[str, np.ndarray]:
    """Shapes, finiteness, positive variances, weights ≥ 0 summing to 1 within 1e-3."""
    out: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise MixtureError(f"{where}: array {name!r} is not a list of numbers") from None
        if a.ndim != 1:
            raise MixtureError(f"{where}: array {name!r} has shape {a.shape}, expected (K,) (one value per component)")
        out[name] = a
    k = out["weights"].shape[0]
    if k == 0:
        raise MixtureError(f"{where}: array 'weights' is empty; expected at least one component")
    for name, a in out.items():
        if a.shape != (k,):
            raise MixtureError(f"{where}: array {name!r} has shape {a.shape}, expected ({k},) like 'weights'")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise MixtureError(f"{where}: array {name!r}[{bad[0]}] = {a[bad[0]]!r} is not finite")
    for name in ("covar", "cond_covar"):
        bad = np.flatnonzero(~(out[name] > 0.0))
        if bad.size:
            raise MixtureError(f"{where}: array {name!r}[{bad[0]}] = {out[name][bad[0]]!r}: variances must be > 0")
    bad = np.flatnonzero(out["weights"] < 0.0)
    if bad.size:
        raise MixtureError(f"{where}: array 'weights'[{bad[0]}] = {out['weights'][bad[0]]!r}: weights must be >= 0")
    total = float(out["weights"].sum())
    if abs(total - 1.0) > 1e-3:
        raise MixtureError(f"{where}: array 'weights' sums to {total!r}, expected 1 within 1e-3")
    return out


# --------------------------------------------------------------------------------------------------
# Responsibility table (alias tables on a grid of X)
# --------------------------------------------------------------------------------------------------


@njit(cache=True)
def _build_alias(p, prob, alias):
    """Vose's alias method for every row of ``p`` (G, K) (rows sum to 1) into ``prob``/``alias``."""
    n_rows, k = p.shape
    small = np.empty(k, np.int64)
    large = np.empty(k, np.int64)
    q = np.empty(k)
    for g in range(n_rows):
        ns = 0
        nl = 0
        for i in range(k):
            q[i] = p[g, i] * k
            if q[i] < 1.0:
                small[ns] = i
                ns += 1
            else:
                large[nl] = i
                nl += 1
        while ns > 0 and nl > 0:
            ns -= 1
            s = small[ns]
            nl -= 1
            big = large[nl]
            prob[g, s] = q[s]
            alias[g, s] = big
            q[big] = (q[big] + q[s]) - 1.0
            if q[big] < 1.0:
                small[ns] = big
                ns += 1
            else:
                large[nl] = big
                nl += 1
        while nl > 0:  # leftovers are 1 up to rounding
            nl -= 1
            prob[g, large[nl]] = 1.0
            alias[g, large[nl]] = large[nl]
        while ns > 0:
            ns -= 1
            prob[g, small[ns]] = 1.0
            alias[g, small[ns]] = small[ns]


@njit(cache=True, inline="always")
def _pick_component(x, u_node, u_col, inv_h, prob, alias):
    """Component index for true distance x ≥ 0 from two uniforms (node choice, alias column + coin)."""
    n_nodes, k = prob.shape
    t = x * inv_h
    g = int(t)
    if g > n_nodes - 2:
        g = n_nodes - 2
    if u_node < t - g:  # take the upper node with probability f = t - g
        g += 1
    s = u_col * k
    c = int(s)
    if c > k - 1:  # u_col * k can round up to k
        c = k - 1
    if s - c < prob[g, c]:
        return c
    return alias[g, c]


@njit(cache=True)
def _pick_components_kernel(xs, key, inv_h, prob, alias, out):
    """Component draws for true distances ``xs`` with the mixture-mode uniforms of columns j = 0..n-1."""
    for j in range(xs.shape[0]):
        out[j] = _pick_component(xs[j], uniform(key, 4 * j), uniform(key, 4 * j + 1), inv_h, prob, alias)


def _alias_distribution(prob: np.ndarray, alias: np.ndarray) -> np.ndarray:
    """The distributions (G, K) that alias tables actually sample (reconstructed from prob/alias)."""
    n_nodes, k = prob.shape
    q = prob / k
    rows = np.repeat(np.arange(n_nodes), k)
    np.add.at(q, (rows, alias.ravel()), ((1.0 - prob) / k).ravel())
    return q


class ResponsibilityTable:
    """Alias tables of the responsibilities r(X) on the uniform grid x_g = g·h, g = 0…G−1, over [0, x_max].

    Attributes: ``x_max``, ``n_nodes`` (G), ``h``, ``inv_h`` = 1/h, ``prob`` (G, K) float64 and
    ``alias`` (G, K) int32 (row g samples component c with u·K → column c, coin ``prob[g, c]``, else
    ``alias[g, c]``), ``node_distribution`` (G, K) the distributions the rows actually encode, and
    ``max_tv_error``: the largest total-variation distance between the sampled component law at X,
    (1 − f)·node_g + f·node_{g+1}, and the exact r(X), over a grid ``check_subdivisions`` times finer
    than the nodes (``tv_check_points`` points). Build with :meth:`build`.
    """

    check_subdivisions = 16

    def __init__(self, mixture: Mixture, x_max: float, n_nodes: int):
        if not (x_max > 0 and math.isfinite(x_max)):
            raise ValueError(f"table x_max = {x_max!r}: expected a finite number > 0")
        if n_nodes < 2:
            raise ValueError(f"table n_nodes = {n_nodes!r}: expected >= 2")
        self.mixture = mixture
        self.x_max = float(x_max)
        self.n_nodes = int(n_nodes)
        self.h = self.x_max / (self.n_nodes - 1)
        self.inv_h = (self.n_nodes - 1) / self.x_max
        nodes = np.linspace(0.0, self.x_max, self.n_nodes)
        r = mixture.responsibilities(nodes)
        k = mixture.n_components
        self.prob = np.empty((self.n_nodes, k))
        self.alias = np.empty((self.n_nodes, k), dtype=np.int32)
        _build_alias(r, self.prob, self.alias)
        self.node_distribution = _alias_distribution(self.prob, self.alias)
        self.max_tv_error, self.tv_check_points = self._measure_tv()
        for a in (self.prob, self.alias, self.node_distribution):
            a.setflags(write=False)

    @classmethod
    def build(cls, mixture: Mixture, x_max: float, tol: float = 1e-4,
              max_bytes: float = 64e6) -> "ResponsibilityTable":
        """The coarsest grid whose ``max_tv_error`` is below ``tol`` (error ∝ h²; table ≤ ``max_bytes``)."""
        k = mixture.n_components
        cap = max(2, int(max_bytes // (12 * k)))
        n = min(cap, max(2, int(math.ceil(x_max / 0.004)) + 1))
        table = cls(mixture, x_max, n)
        for _ in range(8):
            if table.max_tv_error <= tol or table.n_nodes >= cap:
                break
            factor = math.sqrt(table.max_tv_error / tol) * 1.05  # error is O(h^2)
            n = min(cap, max(table.n_nodes + 1, int(math.ceil((table.n_nodes - 1) * factor)) + 1))
            table = cls(mixture, x_max, n)
        if table.max_tv_error > tol:
            warnings.warn(f"ranging table: total-variation error {table.max_tv_error:.2e} > tol {tol:.1e} "
                          f"with the largest allowed grid ({table.n_nodes} nodes over {x_max} m)", stacklevel=2)
        return table

    def component_distribution(self, x) -> np.ndarray:
        """The law the kernel samples components from at true distance(s) x in [0, x_max]: x.shape + (K,)."""
        x = np.asarray(x, dtype=np.float64)
        t = x * self.inv_h
        g = np.minimum(t.astype(np.int64), self.n_nodes - 2)
        f = (t - g)[..., None]
        return (1.0 - f) * self.node_distribution[g] + f * self.node_distribution[g + 1]

    def tv_error(self, x) -> np.ndarray:
        """Total-variation distance between :meth:`component_distribution` and the exact r(x)."""
        return 0.5 * np.abs(self.component_distribution(x) - self.mixture.responsibilities(x)).sum(axis=-1)

    def check_points(self) -> np.ndarray:
        """The points where ``max_tv_error`` is measured: nodes plus ``check_subdivisions − 1`` between each pair."""
        s = self.check_subdivisions
        fine = np.arange((self.n_nodes - 1) * s + 1) / ((self.n_nodes - 1) * s) * self.x_max
        return fine

    def _measure_tv(self) -> tuple[float, int]:
        pts = self.check_points()
        worst = 0.0
        for start in range(0, pts.size, 8192):
            worst = max(worst, float(self.tv_error(pts[start:start + 8192]).max()))
        return worst, int(pts.size)

    def sample_components(self, x, seed: int = 0, env: int = 0, step: int = 0, copter: int = 0) -> np.ndarray:
        """Component indices drawn by the kernel for true distances ``x`` (1-D), reading columns 0…n−1."""
        xs = np.ascontiguousarray(np.asarray(x, dtype=np.float64).ravel())
        if np.any(xs < 0) or np.any(xs > self.x_max):
            raise ValueError(f"true distances must lie in [0, {self.x_max}] m")
        out = np.empty(xs.size, dtype=np.int64)
        key = _row_key(seed, env, step, copter)
        _pick_components_kernel(xs, key, self.inv_h, self.prob, self.alias, out)
        return out

    def __repr__(self) -> str:
        return (f"ResponsibilityTable(K={self.prob.shape[1]}, nodes={self.n_nodes}, h={self.h:.3g} m, "
                f"max_tv_error={self.max_tv_error:.2e})")


def _row_key(seed, env, step, copter) -> np.uint64:
    """The counter key of one measuring copter's row, as a numba-ready uint64."""
    return np.uint64(counter_key(np.int64(seed), np.int64(env), np.int64(step), np.int64(copter),
                                 np.int64(STREAM_RANGING)))


_TABLE_CACHE: dict[tuple[str, float, float], ResponsibilityTable] = {}


def _cached_table(mixture: Mixture, x_max: float, tol: float) -> ResponsibilityTable:
    key = (mixture.digest, float(x_max), float(tol))
    table = _TABLE_CACHE.get(key)
    if table is None:
        if len(_TABLE_CACHE) >= 8:
            _TABLE_CACHE.pop(next(iter(_TABLE_CACHE)))
        table = ResponsibilityTable.build(mixture, x_max, tol)
        _TABLE_CACHE[key] = table
    return table


# --------------------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------------------


@njit(cache=True)
def _seed_reading(x, key, j, mean, cond_mean, log_wn, half_inv_covar, seed_std):
    """``seed`` mode, before clipping: exact responsibilities, one normal per component, weighted sum."""
    k = mean.shape[0]
    top = -np.inf
    for i in range(k):
        d = x - mean[i]
        lp = log_wn[i] - half_inv_covar[i] * d * d
        if lp > top:
            top = lp
    total = 0.0
    acc = 0.0
    for i in range(k):
        d = x - mean[i]
        r = np.exp(log_wn[i] - half_inv_covar[i] * d * d - top)
        total += r
        acc += r * (cond_mean[i] + seed_std[i] * normal(key, j * k + i))
    return acc / total


@njit(cache=True, inline="always")
def _fast_reading(x, key, j, mode, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std):
    """``mixture`` / ``gaussian`` / ``none`` reading before clipping, for true distance x in [0, max_range]."""
    if mode == MODE_MIXTURE:
        c = _pick_component(x, uniform(key, 4 * j), uniform(key, 4 * j + 1), inv_h, prob, alias)
        return cond_mean[c] + slope[c] * (x - mean[c]) + cond_std[c] * normal(key, 2 * j + 1)
    if mode == MODE_GAUSSIAN:
        return x + sigma * normal(key, j)
    return x


# The per-reading rule (range check, mode dispatch, clipping at 0) is written out in each kernel's loop
# body on purpose: wrapping it in one helper that takes the arrays and calls ``_seed_reading`` made the
# mixture path 3x slower (≈ 100 instead of ≈ 30 ns per reading; reference counting of the array
# arguments on every call). Keep the two copies identical; tests compare both with the NumPy reference.


@njit(cache=True)
def _sample_kernel(xs, key, p, out):
    """out[j]: reading of true distance xs[j] as column j of the row with counter key ``key``."""
    mode, max_range, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std, log_wn, half_inv_covar, seed_std = p
    for j in range(xs.shape[0]):
        x = xs[j]
        if x > max_range:
            y = max_range
        elif mode == MODE_SEED:
            y = _seed_reading(x, key, j, mean, cond_mean, log_wn, half_inv_covar, seed_std)
        else:
            y = _fast_reading(x, key, j, mode, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std)
        out[j] = y if y > 0.0 else 0.0


@njit(cache=True, parallel=True)
def _readings_kernel(positions, beacons, seed, env_ids, step, p, ideal, out):
    """out[b, i, j]: copter i's reading of copter j (j < N) or beacon j − N, environment b."""
    n_env, n, _ = positions.shape
    m = beacons.shape[0]
    mode, max_range, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std, log_wn, half_inv_covar, seed_std = p
    for b in prange(n_env):
        env = env_ids[b]
        for i in range(n):
            key = counter_key(seed, env, step, i, STREAM_RANGING)
            xi = positions[b, i, 0]
            yi = positions[b, i, 1]
            for j in range(n + m):
                if j == i:
                    out[b, i, j] = 0.0
                    continue
                if j < n:
                    dx = positions[b, j, 0] - xi
                    dy = positions[b, j, 1] - yi
                else:
                    dx = beacons[j - n, 0] - xi
                    dy = beacons[j - n, 1] - yi
                x = np.sqrt(dx * dx + dy * dy)
                if x > max_range:
                    y = max_range
                elif ideal:
                    y = x
                elif mode == MODE_SEED:
                    y = _seed_reading(x, key, j, mean, cond_mean, log_wn, half_inv_covar, seed_std)
                else:
                    y = _fast_reading(x, key, j, mode, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std)
                out[b, i, j] = y if y > 0.0 else 0.0


# --------------------------------------------------------------------------------------------------
# Model and batched sensor
# --------------------------------------------------------------------------------------------------


class RangingModel:
    """Everything the ranging kernels need, built once from the config.

    ``error``: ``"mixture"`` | ``"seed"`` | ``"gaussian"`` | ``"none"``; ``mixture``: a
    :class:`Mixture` (default :meth:`Mixture.default`; only loaded for mixture/seed); ``beacons``:
    (M, 2) fixed tags in m; ``table_tol``: the table's total-variation tolerance. ``table`` is the
    :class:`ResponsibilityTable` in mixture mode, else None. ``params`` is the numba argument tuple.
    """

    def __init__(self, error: str = "mixture", max_range: float = 2.5, sigma: float = 0.1,
                 mixture: Mixture | None = None, seed_variance_factor: float = 10.0, beacons=(),
                 table_tol: float = 1e-4):
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
        self.beacons = _as_beacons(beacons)
        if mixture is None and error in ("mixture", "seed"):
            mixture = Mixture.default()
        self.mixture = mixture
        self.table = _cached_table(mixture, self.max_range, table_tol) if error == "mixture" else None
        self.params = self._params()

    @classmethod
    def from_config(cls, cfg, mixture: Mixture | None = None, table_tol: float = 1e-4) -> "RangingModel":
        """From a ``RangingConfig`` (``cfg.ranging``); ``mixture_file`` is loaded unless ``mixture`` is given."""
        if mixture is None and cfg.mixture_file and cfg.error in ("mixture", "seed"):
            mixture = Mixture.load(cfg.mixture_file)
        return cls(error=cfg.error, max_range=cfg.max_range, sigma=cfg.sigma, mixture=mixture,
                   seed_variance_factor=cfg.seed_variance_factor, beacons=cfg.beacons, table_tol=table_tol)

    def _params(self) -> tuple:
        """(mode, max_range, sigma, inv_h, prob, alias, mean, slope, cond_mean, cond_std, log_wn,
        half_inv_covar, seed_std): int64, 3 float64, the table (G, K) float64 / int32, then (K,) float64
        arrays: log_wn = log weights − ½ log(2π covar), half_inv_covar = 1/(2 covar),
        seed_std = sqrt(seed_variance_factor · covar). Unused parts are 1-element placeholders."""
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
        # read-only arrays throughout, so every mode has the same numba signature (one compilation)
        arrays = (_ro(prob, np.float64), _ro(alias, np.int32)) + tuple(_ro(a, np.float64) for a in arrays)
        return (np.int64(self.mode), float(self.max_range), float(self.sigma), float(inv_h)) + arrays

    def sample(self, x, seed: int = 0, env: int = 0, step: int = 0, copter: int = 0) -> np.ndarray:
        """Readings for true distances ``x`` (any shape; element j of the flattened array uses reading
        column j of copter ``copter``'s key), with the same rules as :func:`ranging_readings`."""
        x = np.asarray(x, dtype=np.float64)
        xs = np.ascontiguousarray(x.ravel())
        if np.any(~(xs >= 0)):
            raise ValueError("true distances must be finite and >= 0")
        out = np.empty_like(xs)
        key = _row_key(seed, env, step, copter)
        _sample_kernel(xs, key, self.params, out)
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


@functools.lru_cache(maxsize=16)
def _model_for_config(cfg) -> "RangingModel":
    return RangingModel.from_config(cfg)


def _as_beacons(beacons) -> np.ndarray:
    b = np.asarray(beacons if beacons is not None else (), dtype=np.float64)
    if b.size == 0:
        return np.zeros((0, 2))
    if b.ndim != 2 or b.shape[1] != 2:
        raise ValueError(f"beacons: expected shape (M, 2) in m, got {b.shape}")
    if not np.all(np.isfinite(b)):
        raise ValueError("beacons: coordinates must be finite")
    return np.ascontiguousarray(b)


def _check_positions(positions) -> np.ndarray:
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 2:
        raise ValueError(f"positions: expected shape (B, N, 2) in m, got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("positions: coordinates must be finite")
    return pos


def ranging_readings(positions, beacons, seed: int, env_ids, step: int, params: RangingModel,
                     ideal: bool = False, out: np.ndarray | None = None) -> np.ndarray:
    """The virtual-ranging readings of a batch: (B, N, N + M) float64, m.

    ``positions`` (B, N, 2) copter positions, m; ``beacons`` (M, 2) fixed tags (may be empty);
    ``seed`` the run seed; ``env_ids`` (B,) int64 global environment indices (row b equals a B = 1
    run with ``env_ids=[env_ids[b]]``); ``step`` the step index; ``params`` a :class:`RangingModel`
    (a ``RangingConfig`` is accepted and converted, cached). Row i = measuring copter, columns = copters
    0…N−1 then beacons. ``ideal=True`` returns the true distances (self 0, clipped at max_range)
    without drawing random numbers. ``out`` may be a preallocated C-contiguous float64 array.
    """
    if not isinstance(params, RangingModel):
        params = _model_for_config(params)
    pos = _check_positions(positions)
    bea = _as_beacons(beacons)
    env = np.ascontiguousarray(env_ids, dtype=np.int64).reshape(-1)
    n_env, n, _ = pos.shape
    if env.shape[0] != n_env:
        raise ValueError(f"env_ids: expected {n_env} entries (one per environment), got {env.shape[0]}")
    shape = (n_env, n, n + bea.shape[0])
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out: expected a C-contiguous float64 array of shape {shape}")
    _readings_kernel(pos, bea, np.int64(seed), env, np.int64(step), params.params, bool(ideal), out)
    return out


def ideal_ranges(positions, beacons=(), max_range: float = 2.5) -> np.ndarray:
    """True distances (B, N, N + M): self 0, anything beyond ``max_range`` set to ``max_range``."""
    pos = _check_positions(positions)
    model = RangingModel("none", max_range=max_range)
    env = np.zeros(pos.shape[0], dtype=np.int64)
    return ranging_readings(pos, beacons, 0, env, 0, model, ideal=True)
