"""``gap.attribute.fits.smoothed_min``: the minimum of a rough 1-D objective (the tracking-noise fit's search)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.gap.attribute.fits import SMOOTH_POINTS, smoothed_min


@settings(max_examples=200, deadline=None)
@given(lo=st.floats(-5.0, 5.0), width=st.floats(0.01, 10.0), where=st.floats(0.0, 1.0), scale=st.floats(0.1, 100.0))
def test_a_parabolas_minimum_is_found_exactly(lo, width, where, scale):
    hi = lo + width
    m = lo + where * width
    x = smoothed_min(lambda v: scale * (v - m) ** 2 + 1.0, lo, hi)
    assert lo <= x <= hi
    assert x == pytest.approx(m, abs=1e-6 * width)


def test_a_dip_beside_the_minimum_does_not_catch_it():
    """The case that made the fit miss: a smooth bowl with narrow dips (as the tracking-noise score has where rays
    flip); a bracketing search stops in the deepest dip, the parabola keeps to the bowl's centre."""
    m, lo, hi = 22.6, 12.0, 35.0
    rng = np.random.default_rng(0)
    centres = rng.uniform(lo, hi, 40)
    depths = rng.uniform(0.0, 0.02, 40)

    def f(v):
        return 0.001 * (v - m) ** 2 - float(np.sum(depths * np.exp(-0.5 * ((v - centres) / 0.05) ** 2)))

    from scipy import optimize

    brent = optimize.minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 0.02 * (hi - lo),
                                                                                    "maxiter": 10}).x
    got = smoothed_min(f, lo, hi)
    assert abs(got - m) < 0.5 and abs(got - m) < abs(brent - m)


def test_without_a_bowl_the_best_point_is_kept():
    assert smoothed_min(lambda v: -v, 0.0, 1.0) == 1.0  # monotone: the best point, at the end
    assert smoothed_min(lambda v: -((v - 0.5) ** 2), 0.0, 1.0) in (0.0, 1.0)  # opens downward
    calls = []
    smoothed_min(lambda v: calls.append(v) or (v - 0.3) ** 2, 0.0, 1.0)
    assert len(calls) <= 2 * SMOOTH_POINTS - 1 and len(set(calls)) == len(calls)


def test_unscorable_points_are_skipped():
    x = smoothed_min(lambda v: np.nan if v > 0.8 else (v - 0.4) ** 2, 0.0, 1.0)
    assert x == pytest.approx(0.4, abs=1e-9)
