"""Nested effects in the validation's judge (finkensim.gap.validation.cases.NESTED): a constant ranging offset is
every node's delay raised by half of it, so a trial withholding both is explained exactly by the node delays alone."""
import numpy as np
import pytest

import finkensim as fs
from finkensim.gap.validation.cases import NESTED, essential, explains
from finkensim.gap.validation.tables import exactly_withheld, judged


@pytest.mark.parametrize("bias", [0.13, -0.08])
def test_a_ranging_offset_flies_as_every_node_delay_raised_by_half_of_it(bias):
    """The simulator's readings with ``ranging.bias = b`` equal those with every node's delay raised by b / 2."""
    base = {"copters.n": 4, "ranging.enabled": True, "ranging.max_range": 6.0}
    delays = [0.05, -0.12, 0.2, 0.07]
    a = fs.load_config({}).replace({**base, "ranging.bias": bias, "ranging.node_delay": delays})
    b = fs.load_config({}).replace({**base, "ranging.node_delay": [d + bias / 2 for d in delays]})
    log_a, _, _ = fs.simulate_flight(a, duration=2.0, seed=5)
    log_b, _, _ = fs.simulate_flight(b, duration=2.0, seed=5)
    assert np.isfinite(log_a.ranging).sum() > 50
    np.testing.assert_allclose(log_a.ranging, log_b.ranging, rtol=0, atol=1e-12, equal_nan=True)


def test_nesting_judges_pairs_and_keeps_single_effects_strict():
    assert NESTED == {"ranging_bias": "ranging_node_delay"}
    assert essential({"ranging_bias", "ranging_node_delay"}) == {"ranging_node_delay"}
    assert essential({"ranging_bias", "sonar_bias"}) == {"ranging_bias", "sonar_bias"}
    assert explains({"ranging_node_delay"}, {"ranging_bias", "ranging_node_delay"})
    assert not explains({"ranging_bias"}, {"ranging_bias", "ranging_node_delay"})  # the smaller cannot stand in
    row = dict(case="ranging_bias+ranging_node_delay", significant=True, unexplained=False, correct=False,
               effects=["ranging_node_delay"])
    assert judged(row) and exactly_withheld(row)  # rows written before the rule are judged by it
    assert judged(dict(row, effects=["ranging_bias", "ranging_node_delay"]))
    assert exactly_withheld(dict(row, effects=["ranging_bias", "ranging_node_delay"]))
    assert not judged(dict(row, effects=["ranging_bias"]))
    assert not judged(dict(row, unexplained=True))
    assert not exactly_withheld(dict(row, effects=["ranging_node_delay", "latency"]))
    single = dict(case="ranging_bias", significant=True, unexplained=False, correct=False,
                  effects=["ranging_node_delay"])
    assert not judged(single)  # a single case is right only when its own effect comes first (the row's verdict)
