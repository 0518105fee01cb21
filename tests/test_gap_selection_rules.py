"""Two rules of the greedy selection (finkensim.gap.attribute.selection), on hand-made selections: which hopeless
candidates are refitted once an effect is in (the masked ones only), and how a second effect's cut of the calibration
gap is counted (by the gap's size: a gap turned negative is no cut)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import finkensim.gap  # noqa: F401  (registers the whole catalogue, radio effects included)
from finkensim.config import load_config
from finkensim.gap.attribute import effects as fx
from finkensim.gap.attribute.fit_result import FitResult
from finkensim.gap.attribute.selection import _abs_share, _unmasked
from finkensim.gap.model.params import ModelParams

BASE = ModelParams.from_config(load_config())


def _fit(name, **values):
    start = fx.REGISTRY[name].start(BASE)
    return FitResult(name, {**start, **values}, BASE, math.nan)


def _selection(first, added, left_significant=True, gap_sensors=("ranging",)):
    """A selection with the first round ``first``, the effects ``added`` and what they leave on each gap sensor."""
    left = {s: {"significant": left_significant} for s in gap_sensors}
    return SimpleNamespace(first=first, added=added, diag=SimpleNamespace(base=BASE),
                           found=SimpleNamespace(gap_sensors=list(gap_sensors)), remaining=lambda: left)


def test_a_candidate_that_switched_itself_off_is_refitted_beside_an_effect_on_its_sensor():
    # a positive tail under a negative offset: fitted alone it goes to probability 0, its neutral start
    tail = _fit("ranging_nlos_tail")
    sel = _selection([tail], [_fit("ranging_bias", bias=-0.11)])
    assert _unmasked(sel, "ranging_nlos_tail")


def test_a_candidate_that_fitted_something_and_gained_nothing_stays_out():
    # MURP: a range scale of 1.007 beside the node delays is not masked, it is not there
    sel = _selection([_fit("ranging_scale", factor=1.007)], [_fit("ranging_node_delay", delay_0=0.2)])
    assert not _unmasked(sel, "ranging_scale")


@pytest.mark.parametrize("added, significant", [("sonar_bias", True), ("ranging_bias", False)])
def test_unmasking_needs_a_shared_sensor_with_a_significant_gap_left(added, significant):
    sel = _selection([_fit("ranging_nlos_tail")], [_fit(added)], left_significant=significant,
                     gap_sensors=("ranging", "ultrasonic"))
    assert not _unmasked(sel, "ranging_nlos_tail")


def test_a_gap_cut_counts_the_gap_size_not_its_sign():
    per_sensor = {"ranging": {"gap": 0.238}}
    alone = {"ranging": np.full(50, 0.063)}
    # MURP: +0.063 -> -0.080 is a larger gap, not a cut of 0.143
    assert _abs_share(alone, {"ranging": np.full(50, -0.080)}, ["ranging"], per_sensor) < 0
    # ranging_bias + ranging_nlos_tail: 0.051 -> 0.009 cuts a quarter of the configured model's 0.169
    per_sensor = {"ranging": {"gap": 0.169}}
    share = _abs_share({"ranging": np.full(50, 0.051)}, {"ranging": np.full(50, 0.009)}, ["ranging"], per_sensor)
    assert share == pytest.approx(0.042 / 0.169)
