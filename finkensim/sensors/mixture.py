"""Gaussian-mixture model of the virtual-ranging error: the data model, its files and its analytic laws.

A :class:`Mixture` is a K-component Gaussian mixture over (X = true distance, Y = measured distance)
in metres and m². Given X, component i has the conditional law
N(cond_meanᵢ + slopeᵢ·(X − meanᵢ), cond_covarᵢ) and conditional weight (responsibility)
rᵢ(X) ∝ weightsᵢ·N(X; meanᵢ, covarᵢ). The sensor that samples it is :mod:`finkensim.sensors.ranging`.

- files: :meth:`Mixture.load` / :meth:`Mixture.save` (JSON or NPZ; JSON may be in m, cm or mm),
  :meth:`Mixture.default` (Parlow's K = 100 model, ``finkensim/data/vranging_gmm_m.json``);
- constructors: :meth:`Mixture.from_joint` (joint (X, Y) means and covariances), :meth:`Mixture.fit`
  (scikit-learn);
- analytic laws: :meth:`Mixture.responsibilities`, :meth:`Mixture.conditional_cdf`,
  :meth:`Mixture.conditional_pdf`, :meth:`Mixture.conditional_mean_std`, :meth:`Mixture.seed_mean_std`.

Every invalid file or array raises :class:`MixtureError`, naming the file, the array and what is wrong.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..atomic import atomic_path, write_text_atomic
from ..config import ConfigError

__all__ = ["ARRAY_NAMES", "DEFAULT_MIXTURE_FILE", "Mixture", "MixtureError"]

#: The five arrays every mixture file holds (``slope`` is optional), each of shape (K,).
ARRAY_NAMES = ("weights", "mean", "covar", "cond_mean", "cond_covar")
_UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Parlow's K = 100 model in metres (provenance in ``finkensim/data/README.md``).
DEFAULT_MIXTURE_FILE = Path(__file__).resolve().parent.parent / "data" / "vranging_gmm_m.json"

class MixtureError(ConfigError):
    """A mixture file or array is invalid. The message names the array and what is wrong. A
    :class:`~finkensim.config.ConfigError`: commands report it as bad input, in one line."""


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Mixture:
    """A Gaussian mixture over (X = true distance, Y = measured distance), in metres and m².

    Arrays, all of shape (K,):

    ``weights``
        prior weight of each component (≥ 0, sums to 1 within 1e-3)
    ``mean``
        mean of X of each component, m
    ``covar``
        variance of X of each component, m² (> 0)
    ``cond_mean``
        mean of Y of each component at X = ``mean`` (the component's Y mean), m
    ``cond_covar``
        variance of Y given X of each component, m² (> 0). For a diagonal covariance this is the Y variance;
        for a full one, cov_yy − cov_xy²/cov_xx.
    ``slope``
        dE[Y | X]/dX within each component: cov_xy/cov_xx (0 for diagonal covariances).

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
        arrays = {name: getattr(self, name) for name in ARRAY_NAMES}
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
        for name in ARRAY_NAMES + ("slope",):
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
            _DEFAULT_MIXTURE = cls.load(DEFAULT_MIXTURE_FILE)
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
                raise MixtureError(f"{where}: expected a JSON object with arrays {', '.join(ARRAY_NAMES)}")
            arrays = {}
            for name in ARRAY_NAMES + ("slope",):
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
                for name in ARRAY_NAMES + ("slope",):
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
        arrays = {name: getattr(self, name) for name in ARRAY_NAMES}
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
            write_text_atomic(path, json.dumps(data, indent=1) + "\n")
        elif suffix == ".npz":
            with atomic_path(path) as tmp, open(tmp, "xb") as f:
                np.savez(f, **arrays)
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


