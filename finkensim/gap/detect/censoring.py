"""Censored scoring at a sensor's range limits, so that how a tool records a lost echo cannot make a gap.

Real drivers record a sonar ping without echo in different ways: exactly ``max_range``, ``max_range``
plus noise clipped to the range, a sentinel such as 0, or a longer maximum than the simulator's.
None of these is wrong, and none says anything about the physics. The diagnosis therefore scores
every reading with the *threshold-weighted* CRPS (Gneiting & Ranjan 2011) of weight 1 on
``(lo, hi)``: draws and observations alike pass through the chaining function

    v(x) = clip(x, lo, hi)

before the ensemble terms are computed. A reading at or beyond ``hi`` (a lost echo in any convention,
or a far wall) equals every other such reading; readings inside the interval are scored as before;
the gap E|v(X) − v(y)| − E|v(X) − v(X')| stays exactly zero-mean under the model (v is fixed). An
effect that *moves* readings to the limit (a lost echo where the model expects one at 1.5 m) still
shows: v(y) = hi is far from v(X) ≈ 1.5.

The limits come from the configuration and from the log itself:

- ``hi`` = (the smaller of the configured ``max_range`` and a repeated maximum value the log shows)
  − ``margin``; ``lo`` = ``min_range`` + ``margin``, where ``margin`` covers the base noise (4 standard
  deviations), so a noisy-clipped time-out lands above ``hi``.
- A value below ``min_range`` that repeats exactly (an atom, e.g. 0.0) cannot be an echo: it is the
  tool's no-echo sentinel and is scored as a reading at ``hi``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Censoring", "detect_censoring", "atoms"]

ATOM_MIN_COUNT = 20  # an exactly repeated value counts as a recording convention from this many readings,
ATOM_MIN_SHARE = 0.002  # this share of the readings (continuous noise never repeats exactly),
ATOM_MIN_RATIO = 10.0  # and this many times the median count of a distinct value (quantised drivers repeat all)


@dataclass(frozen=True)
class Censoring:
    """The chaining interval [lo, hi] (m) of one sensor and its no-echo sentinels (exact values)."""

    lo: float
    hi: float
    no_echo: tuple[float, ...] = ()

    def draws(self, x: np.ndarray) -> np.ndarray:
        """v(x) of model draws (any shape): clipped to [lo, hi]; NaN stays NaN."""
        return np.clip(x, self.lo, self.hi)

    def observed(self, y: np.ndarray) -> np.ndarray:
        """v(y) of real readings (any shape): no-echo sentinels go to ``hi``, the rest are clipped."""
        y = np.asarray(y, dtype=np.float64)
        out = np.clip(y, self.lo, self.hi)
        for a in self.no_echo:
            out[y == a] = self.hi
        return out

    def to_dict(self) -> dict:
        return {"lo": float(self.lo), "hi": float(self.hi), "no_echo": [float(a) for a in self.no_echo]}


def atoms(y: np.ndarray) -> list[tuple[float, int]]:
    """Values of y (finite, 1-D) that repeat exactly often enough to be a recording convention:
    [(value, count)], most frequent first."""
    y = y[np.isfinite(y)]
    if y.size == 0:
        return []
    vals, counts = np.unique(y, return_counts=True)
    need = max(ATOM_MIN_COUNT, ATOM_MIN_SHARE * y.size, ATOM_MIN_RATIO * float(np.median(counts)))
    keep = counts >= need
    order = np.argsort(-counts[keep], kind="stable")
    return [(float(v), int(c)) for v, c in zip(vals[keep][order], counts[keep][order])]


def detect_censoring(y: np.ndarray, min_range: float, max_range: float, noise_std: float,
                     margin_floor: float = 0.0) -> Censoring:
    """The censoring of a range sensor from its configured limits (m), the base noise standard
    deviation (m) and the logged readings y (any shape, NaN = no reading).

    margin = max(4 · noise_std, margin_floor). ``hi`` is lowered to a repeated maximum of the log (a
    shorter range than configured); exact repeats below ``min_range`` are no-echo sentinels.
    """
    y = np.asarray(y, dtype=np.float64).ravel()
    y = y[np.isfinite(y)]
    margin = max(4.0 * float(noise_std), float(margin_floor))
    top = float(max_range)
    sentinels = []
    for value, _ in atoms(y):
        if value < min_range:
            sentinels.append(value)
        elif 0.5 * max_range <= value < top and np.mean(y > value) < 0.001:
            top = value  # the log's own maximum range: a repeated value that (almost) nothing exceeds
    hi = top - margin
    lo = min(float(min_range) + margin, hi)
    return Censoring(lo=lo, hi=hi, no_echo=tuple(sorted(sentinels)))
