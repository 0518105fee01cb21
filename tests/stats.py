"""Statistical assertions for the test suite: every tolerance is a stated number of standard errors (SE).

Each helper compares a statistic of a sample with its expected value and fails when they differ by more than
``n_se`` standard errors of that statistic. The SE comes from the sample itself (default) or, where the model gives
it in closed form, from the caller (``se=``, e.g. σ/√n for a mean of known spread). The default multiplier is 5:
with the fixed seeds the tests use, a correct implementation fails with probability ≈ 6e-7 per check (normal
tails), while a bias larger than about 5 SE fails. A test states, next to its check, the SE it expects and so the
smallest relative bias it detects.

Failure messages name the quantity, the measured and expected values, the SE, the multiplier and the bound, e.g.
``mixture reading mean at 1 m: measured 1.0123, expected 1.011; |difference| 0.0013 ≥ 5 SE = 0.00081 (0.08% of
the expected value) (SE 0.00016)``.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    "N_SE", "se_mean", "se_std", "se_std_normal", "se_proportion", "se_median_bootstrap", "se_bootstrap",
    "assert_within_se",
    "assert_above_se", "assert_mean_within_se", "assert_std_within_se", "assert_proportion_within_se",
    "assert_median_within_se",
]

#: the default multiplier: 5 standard errors
N_SE = 5.0


def _flat(sample) -> np.ndarray:
    x = np.asarray(sample, dtype=float).ravel()
    if x.size < 2:
        raise ValueError(f"a sample of {x.size} value(s) has no standard error")
    return x


def se_mean(sample) -> float:
    """SE of the mean of an iid sample, from the sample: s/√n with the ddof = 1 standard deviation s."""
    x = _flat(sample)
    return float(x.std(ddof=1) / math.sqrt(x.size))


def se_std(sample) -> float:
    """SE of the standard deviation of an iid sample, from the sample (delta method, any distribution):
    SD((x − x̄)²) / (2·s·√n). For normal data this is ≈ σ/√(2n); heavy tails make it larger."""
    x = _flat(sample)
    d2 = (x - x.mean()) ** 2
    return float(d2.std(ddof=1) / (2.0 * math.sqrt(d2.mean()) * math.sqrt(x.size)))


def se_std_normal(sigma: float, n: int) -> float:
    """SE of the sample standard deviation of n normal values with standard deviation sigma: σ/√(2(n − 1))."""
    return float(sigma / math.sqrt(2.0 * (n - 1)))


def se_proportion(p: float, n: int) -> float:
    """SE of a proportion over n independent trials with success probability p: √(p(1 − p)/n)."""
    return float(math.sqrt(p * (1.0 - p) / n))


def se_median_bootstrap(sample, n_boot: int = 400, seed: int = 0) -> float:
    """SE of the median of an iid sample: standard deviation of the medians of n_boot bootstrap resamples (fixed
    seed). For normal data it is ≈ 1.2533·σ/√n; the bootstrap needs no assumption about the distribution."""
    x = _flat(sample)
    rng = np.random.default_rng(seed)
    meds = np.array([np.median(x[rng.integers(0, x.size, x.size)]) for _ in range(n_boot)])
    return float(meds.std(ddof=1))


def se_bootstrap(statistic, n: int, n_boot: int = 200, seed: int = 0) -> float:
    """SE of any statistic of n iid rows where no formula is at hand: the standard deviation of
    ``statistic(idx)`` over n_boot bootstrap index vectors ``idx`` (n row numbers drawn with replacement, fixed
    seed). ``statistic(np.arange(n))`` is the statistic of the sample itself."""
    rng = np.random.default_rng(seed)
    reps = np.array([float(statistic(rng.integers(0, n, n))) for _ in range(n_boot)])
    return float(reps.std(ddof=1))


def _check_se(se, what):
    if not (np.isfinite(se) and se > 0):
        raise AssertionError(f"{what}: standard error {se!r} is not a positive number (a constant sample?)")


def assert_within_se(value, expected, se, n_se: float = N_SE, what: str = "statistic", slack: float = 0.0) -> float:
    """Assert |value − expected| < n_se·se (+ slack); return se. The workhorse of the other helpers: use it directly
    for a statistic whose SE is known in closed form (a correlation under independence, 1/√n; a fitted parameter).
    ``slack`` is a stated deterministic error bound added to the statistical one (e.g. a lookup table's error, the
    rounding of a documented figure); it is 0 unless the test names its source."""
    _check_se(se, what)
    value, expected = float(value), float(expected)
    bound = n_se * se + slack
    rel = f" ({bound / abs(expected):.2%} of the expected value)" if expected != 0 else ""
    extra = f" + slack {slack:.3g}" if slack else ""
    assert abs(value - expected) < bound, (
        f"{what}: measured {value:.6g}, expected {expected:.6g}; |difference| {abs(value - expected):.3g} ≥ "
        f"{n_se:g} SE{extra} = {bound:.3g}{rel} (SE {se:.3g})")
    return float(se)


def assert_above_se(value, threshold, se, n_se: float = N_SE, what: str = "statistic") -> float:
    """One-sided: assert value > threshold + n_se·se (the statistic clears the threshold by more than its noise,
    e.g. a gap that must be positive); return se."""
    _check_se(se, what)
    value, threshold = float(value), float(threshold)
    assert value > threshold + n_se * se, (
        f"{what}: measured {value:.6g}, expected above {threshold:.6g} by more than {n_se:g} SE = {n_se * se:.3g} "
        f"(SE {se:.3g})")
    return float(se)


def assert_mean_within_se(sample, expected, n_se: float = N_SE, se: float | None = None,
                          what: str = "mean", slack: float = 0.0) -> float:
    """Assert the sample mean is within n_se SE (+ slack, see :func:`assert_within_se`) of expected. SE: ``se`` if
    given (closed form from the model), else s/√n from the sample. Returns the SE used."""
    x = _flat(sample)
    return assert_within_se(x.mean(), expected, se_mean(x) if se is None else se, n_se, what, slack)


def assert_std_within_se(sample, expected, n_se: float = N_SE, se: float | None = None, ddof: int = 1,
                         what: str = "standard deviation", slack: float = 0.0) -> float:
    """Assert the sample standard deviation (``ddof``) is within n_se SE (+ slack, see :func:`assert_within_se`)
    of expected. SE: ``se`` if given (e.g. :func:`se_std_normal`), else the delta-method SE of :func:`se_std` from
    the sample. Returns the SE used."""
    x = _flat(sample)
    return assert_within_se(x.std(ddof=ddof), expected, se_std(x) if se is None else se, n_se, what, slack)


def assert_proportion_within_se(hits, expected, n_se: float = N_SE, what: str = "proportion") -> float:
    """Assert the share of True in the boolean sample ``hits`` is within n_se SE of the expected probability; the
    SE is √(p(1 − p)/n) at the expected p (the binomial SE under the hypothesis tested). Returns the SE."""
    h = np.asarray(hits, dtype=bool).ravel()
    if not 0.0 < expected < 1.0:
        raise ValueError(f"{what}: expected probability {expected!r} must lie strictly between 0 and 1")
    return assert_within_se(h.mean(), expected, se_proportion(expected, h.size), n_se, what)


def assert_median_within_se(sample, expected, n_se: float = N_SE, se: float | None = None,
                            what: str = "median") -> float:
    """Assert the sample median is within n_se SE of expected. SE: ``se`` if given (e.g. 1.2533·σ/√n for normal
    data), else :func:`se_median_bootstrap`. Returns the SE used."""
    x = _flat(sample)
    return assert_within_se(np.median(x), expected, se_median_bootstrap(x) if se is None else se, n_se, what)
