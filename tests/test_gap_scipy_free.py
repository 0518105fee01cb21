"""The diagnosis computes its normal tails, densities and Benjamini–Hochberg adjustments without ``scipy.stats``
(a quarter second of every process's start): the same numbers as scipy's, bit for bit, and the diagnosis's modules
do not import it."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from finkensim.gap.model.scoring import crps_normal, normal_pdf, normal_sf
from finkensim.gap.detect.stats import bh_adjusted, fdr_significant

floats = st.floats(-40.0, 40.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(z=floats)
def test_normal_sf_is_scipys(z):
    assert normal_sf(z) == float(stats.norm.sf(z))


@settings(max_examples=50, deadline=None)
@given(z=st.lists(floats, min_size=1, max_size=30))
def test_normal_pdf_is_scipys(z):
    z = np.array(z + [np.inf, -np.inf, np.nan])
    np.testing.assert_array_equal(normal_pdf(z), stats.norm.pdf(z))


@settings(max_examples=50, deadline=None)
@given(mu=floats, sigma=st.floats(1e-3, 10.0), y=floats)
def test_crps_normal_matches_scipy_formula(mu, sigma, y):
    z = (y - mu) / sigma
    ref = sigma * (z * (2.0 * stats.norm.cdf(z) - 1.0) + 2.0 * stats.norm.pdf(z) - 1.0 / np.sqrt(np.pi))
    assert float(crps_normal(mu, sigma, y)) == float(ref)


@settings(max_examples=200, deadline=None)
@given(p=st.lists(st.one_of(st.floats(0.0, 1.0), st.sampled_from([0.0, 1.0, 0.05, 0.01])), min_size=0,
                  max_size=60))
def test_bh_adjusted_is_scipys(p):
    p = np.array(p, dtype=float)
    np.testing.assert_array_equal(bh_adjusted(p), stats.false_discovery_control(p, method="bh"))
    np.testing.assert_array_equal(fdr_significant(p, 0.05), stats.false_discovery_control(p, method="bh") <= 0.05
                                  if p.size else np.zeros(0, bool))


def test_diagnosis_modules_do_not_import_scipy_stats():
    code = ("import sys, numpy as np; import finkensim.cli, finkensim.gap.attribute.selection, finkensim.gap.report.write; "
            "from finkensim.gap.detect.stats import fdr_significant, BlockBootstrap; fdr_significant([0.01, 0.2, 0.03]); "
            "print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stdout + out.stderr
