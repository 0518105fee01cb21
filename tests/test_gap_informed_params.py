"""Parameters the logs cannot inform stay where they start: ``ranging_node_delay`` has a delay per node
(``MAX_DELAY_NODES``), but a log of three copters informs three; the joint searches (``fits.joint_fit``) and the
intervals leave the others at their start (0: no delay) instead of wandering along a flat objective (the MURP
calibration once wrote delays of −0.235 and 0.046 m for nodes 3–9 that no reading involves)."""
from __future__ import annotations

import numpy as np
from types import SimpleNamespace

from hypothesis import given, settings, strategies as st

from finkensim.gap.attribute import effects as fx
from finkensim.gap.attribute.effects_radio import MAX_DELAY_NODES, delay_nodes, pair_sums_l1
from finkensim.gap.attribute.fits import joint_fit
from tests.naive import gap as naive


class _Diag:
    """Three nodes range to each other; the objective would pull every delay toward 0.1 m if it could."""

    base = None
    flights: list = []

    def __init__(self, pairs):
        copter, channel = np.array(pairs).T
        self.tables = {"ranging": SimpleNamespace(copter=copter, channel=channel)}

    def objective(self, chain, current, sensors, values):
        return sum((v - 0.1) ** 2 for v in values.values())


def test_delay_nodes_are_the_ends_of_the_readings():
    assert delay_nodes(_Diag([(0, 1), (1, 2), (2, 0)])) == ("delay_0", "delay_1", "delay_2")
    assert delay_nodes(_Diag([(0, 5)])) == ("delay_0", "delay_5")
    assert delay_nodes(SimpleNamespace(tables={})) == ()
    assert delay_nodes(_Diag([(0, MAX_DELAY_NODES + 2)])) == ("delay_0",)


def test_free_is_every_parameter_without_a_rule():
    bias = fx.REGISTRY["ranging_bias"]
    assert bias.free(_Diag([(0, 1)])) == bias.params


def test_joint_fit_moves_only_informed_delays():
    effect = fx.REGISTRY["ranging_node_delay"]
    start = {f"delay_{k}": 0.0 for k in range(MAX_DELAY_NODES)}
    (out,) = joint_fit(_Diag([(0, 1), (1, 2), (2, 0)]), [effect], [start], maxfev=200)
    assert all(out[f"delay_{k}"] == 0.0 for k in range(3, MAX_DELAY_NODES)), out
    assert all(abs(out[f"delay_{k}"] - 0.1) < abs(0.0 - 0.1) for k in range(3)), out


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 300), nodes=st.integers(1, MAX_DELAY_NODES), seed=st.integers(0, 2**32 - 1),
       anchors=st.booleans())
def test_the_node_delays_solve_matches_the_dense_reference(n, nodes, seed, anchors):
    # the normal equations summed by bincount against the dense design's least squares, step for step (a sum
    # pinned down only: one node ranging to fixed anchors, minimum norm in both)
    rng = np.random.default_rng(seed)
    a = rng.integers(0, nodes, n)
    b = np.zeros(n, int) if anchors else rng.integers(0, nodes, n)
    r = rng.normal(0.0, 0.2, n) + rng.exponential(0.3, n) * (rng.random(n) < 0.2)
    np.testing.assert_allclose(pair_sums_l1(r, a, b, MAX_DELAY_NODES), naive.pair_sums_l1(r, a, b, MAX_DELAY_NODES),
                               rtol=0, atol=1e-9)
