"""Two rules of the greedy selection (finkensim.gap.attribute.selection), on hand-made selections: which hopeless
candidates are refitted once an effect is in (those on its sensors, while a significant gap is left there), and how a second effect's cut of the calibration
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


def test_a_candidate_that_fitted_something_alone_is_refitted_beside_an_effect_on_its_sensor():
    # a -0.12 m offset hidden by a tag's antenna offset: fitted alone it went to -0.025 m and lost held-out score
    sel = _selection([_fit("ranging_bias", bias=-0.025)], [_fit("ranging_antenna_offset", x=-0.12, y=0.13)])
    assert _unmasked(sel, "ranging_bias")


def test_a_candidate_the_first_round_did_not_fit_is_not_refitted():
    sel = _selection([_fit("ranging_nlos_tail")], [_fit("ranging_bias", bias=-0.11)])
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


def test_a_lone_effect_is_joined_with_every_candidate_on_its_sensors():
    # a range scale of 0.935 beside a +0.39 m bias near third copters went the wrong way alone (hopeless); a scale
    # of 0.919 beside per-node delays ranked sixth on top of them: both are partners, on-top fits first
    from finkensim.gap.attribute.joint import _partners
    first = [_fit("ranging_nlos", bias=0.3), _fit("ranging_nlos_tail"), _fit("ranging_scale", factor=0.997),
             _fit("sonar_bias", bias=0.001), _fit("ranging_bias", bias=-0.01)]
    on_top = _fit("ranging_nlos_tail", probability=0.01)
    sel = _selection(first, [first[0]])
    sel.pool = [on_top, _fit("sonar_bias", bias=0.002)]
    assert _partners(sel) == [on_top, first[2], first[4]]
    # a lone latency (every sensor) with the gap on the sonar: partners on the sonar only
    sel = _selection([_fit("latency"), *first[1:]], [_fit("latency")], gap_sensors=("ultrasonic",))
    sel.pool = []
    assert [r.name for r in _partners(sel)] == ["sonar_bias"]


@pytest.mark.parametrize("pair_explains, lone_explains, adopted", [(False, True, False), (True, True, True),
                                                                    (False, False, True)])
def test_a_joint_second_never_costs_the_selection_its_explanation(monkeypatch, pair_explains, lone_explains, adopted):
    # MURP: a range scale jointly with the node delays won held-out score by widening the predictive, and the
    # calibration gap's shrink fell under gap.unexplained_shrink
    from finkensim.gap.attribute import joint
    delays, scale = _fit("ranging_node_delay", delay_0=0.2), _fit("ranging_scale", factor=1.007)
    pair = [delays, FitResult("ranging_scale", scale.values, BASE, math.nan, score_heldout=0.28,
                              rows_score={"ranging": np.zeros(3)}, rows_gap={"ranging": np.ones(3)})]
    monkeypatch.setattr(joint, "_best_joint_pair", lambda *args: pair)
    sel = _selection([delays, scale], [delays])
    sel.pool, sel.evaluated, sel.cur_score = [], [], 0.31
    sel.cur_scores, sel.cur_gaps = {"ranging": np.ones(3)}, {"ranging": np.zeros(3)}
    sel.found.significant = True
    sel.diag.say = lambda msg: None
    sel.explains = lambda rows_score, rows_gap: pair_explains if rows_score is pair[-1].rows_score else lone_explains
    sel.second_matters = lambda chain, n: True
    calls = []
    sel.adopt = lambda chain, label: calls.append(label)
    joint.join_second(sel)
    assert calls == (["joint second"] if adopted else [])


def test_without_a_pair_of_the_leader_every_pair_on_the_gap_sensors_is_fitted(monkeypatch):
    # a -0.12 m ranging offset beside a 1.082 range scale cancel at the distances flown: each alone fits about
    # nothing, and the leader (an antenna offset) pairs with neither; every pair of gap-sensor candidates is tried
    from finkensim.gap.attribute import joint
    first = [_fit("ranging_antenna_offset"), _fit("ranging_bias"), _fit("ranging_scale"), _fit("ranging_nlos_tail"),
             _fit("sonar_bias")]
    tried = []

    def best_joint_pair(diag, a, others, evaluated):
        tried.extend((a.name, b.name) for b in others)
        score = {"ranging_bias": 0.40, "ranging_scale": 0.45}.get(a.name, 0.5)
        return [a, FitResult(others[0].name, {}, BASE, math.nan, score_heldout=score)]

    monkeypatch.setattr(joint, "_pair_second_chance", lambda *args: None)
    monkeypatch.setattr(joint, "_best_joint_pair", best_joint_pair)
    clears = []
    monkeypatch.setattr(joint, "_pair_clears", lambda sel, pair, n: clears.append((pair, n)) or pair is not None)
    sel = _selection(first, [])
    sel.found.significant, sel.lead, sel.diag.say, sel.evaluated = True, first[0], lambda msg: None, []
    adopted = []
    sel.adopt = lambda chain, label: adopted.append((chain[0].name, chain[1].name, label))
    joint.pair_lead(sel)
    assert tried == [("ranging_bias", "ranging_scale"), ("ranging_bias", "ranging_nlos_tail"),
                     ("ranging_scale", "ranging_nlos_tail")]
    assert clears[-1][1] == 3 and adopted == [("ranging_bias", "ranging_scale", "joint pair of two")]
