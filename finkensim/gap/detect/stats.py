"""Uncertainty for per-reading discrepancies: block bootstrap and false-discovery control.

Sensor readings are autocorrelated in time and across copters of one flight, so a mean over
readings is resampled by *blocks*: contiguous time windows of one flight (all copters and
channels in the window together). Each bootstrap replicate draws blocks with replacement and
takes the ratio mean Σ values / Σ counts over the drawn blocks.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.scoring import normal_sf


def time_blocks(flight_index, time_index, n_time_steps, n_blocks_per_flight=None, block_seconds=None, dt=None):
    """Block id of each reading: flights are cut into contiguous time windows.

    flight_index, time_index (n,) ints; n_time_steps: dict or array flight → T. Either a fixed
    number of blocks per flight or a block length in seconds (with ``dt``). Returns (n,) int64 ids.
    """
    flight_index = np.asarray(flight_index, dtype=np.int64)
    time_index = np.asarray(time_index, dtype=np.int64)
    n_steps = np.asarray([n_time_steps[f] for f in range(int(flight_index.max()) + 1)]) if flight_index.size else []
    if block_seconds is not None:
        per = np.maximum(1, np.ceil(n_steps * dt / block_seconds).astype(np.int64))
    else:
        per = np.full(len(n_steps), n_blocks_per_flight or 25, dtype=np.int64)
    per = np.minimum(per, np.maximum(1, n_steps))
    offset = np.concatenate([[0], np.cumsum(per)[:-1]])
    within = (time_index * per[flight_index]) // np.maximum(1, n_steps[flight_index])
    return offset[flight_index] + within


@dataclass(frozen=True)
class BlockStats:
    """Mean of a per-reading quantity with a block-bootstrap confidence interval."""

    mean: float
    ci: tuple[float, float]
    se: float
    n: int
    n_blocks: int
    p_positive: float  # one-sided p-value for H0: mean <= 0


class BlockBootstrap:
    """Reusable block-bootstrap resampler: the same replicate weights for every quantity.

    Reusing one set of weights for all bins and all candidate models makes comparisons paired
    (differences between models are resampled consistently) and deterministic for a seed.
    """

    def __init__(self, block_ids, n_boot=400, seed=0):
        block_ids = np.asarray(block_ids)
        self.uniq, self.inverse = np.unique(block_ids, return_inverse=True)
        self.n_blocks = self.uniq.size
        rng = np.random.default_rng(seed)
        self.weights = rng.multinomial(self.n_blocks, np.full(self.n_blocks, 1.0 / max(1, self.n_blocks)), size=n_boot)

    def stats(self, values, mask=None, level=0.95) -> BlockStats:
        """Mean of ``values`` (n,) over readings where ``mask`` (n,) is true and finite, with CI."""
        values = np.asarray(values, dtype=float)
        ok = np.isfinite(values) if mask is None else (np.asarray(mask, bool) & np.isfinite(values))
        n = int(ok.sum())
        if n == 0:
            return BlockStats(np.nan, (np.nan, np.nan), np.nan, 0, 0, np.nan)
        sums = np.bincount(self.inverse[ok], weights=values[ok], minlength=self.n_blocks)
        counts = np.bincount(self.inverse[ok], minlength=self.n_blocks).astype(float)
        mean = sums.sum() / counts.sum()
        used = counts > 0
        nb = int(used.sum())
        with np.errstate(invalid="ignore", divide="ignore"):
            reps = (self.weights @ sums) / (self.weights @ counts)
        reps = reps[np.isfinite(reps)]
        if nb < 2 or reps.size < 10:
            return BlockStats(float(mean), (np.nan, np.nan), np.nan, n, nb, np.nan)
        se = float(np.std(reps, ddof=1))
        a = (1.0 - level) / 2.0
        lo, hi = np.quantile(reps, [a, 1.0 - a])
        p = normal_sf(mean / se) if se > 0 else (0.0 if mean > 0 else 1.0)
        return BlockStats(float(mean), (float(lo), float(hi)), se, n, nb, p)


def fdr_significant(p_values, alpha=0.05):
    """Benjamini–Hochberg: boolean (k,) of discoveries among p-values (NaN never significant)."""
    p = np.asarray(p_values, dtype=float)
    out = np.zeros(p.shape, dtype=bool)
    ok = np.isfinite(p)
    if ok.any():
        out[ok] = bh_adjusted(p[ok]) <= alpha
    return out


def bh_adjusted(p: np.ndarray) -> np.ndarray:
    """Benjamini–Hochberg adjusted p-values of p (k,) in [0, 1]: the numbers of
    ``scipy.stats.false_discovery_control(p, method="bh")`` (its algorithm, step for step; a test compares them),
    without importing ``scipy.stats``, which takes a quarter second of every diagnosis process's start."""
    p = np.asarray(p, dtype=float)
    if p.size <= 1:
        return p
    order = np.argsort(p)
    ps = p[order] * (p.size / np.arange(1, p.size + 1, dtype=float))
    np.minimum.accumulate(ps[::-1], out=ps[::-1])
    out = np.empty_like(ps)
    out[order] = ps
    return np.clip(out, 0.0, 1.0)
