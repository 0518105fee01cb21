"""Work the diagnosis's searches leave out (issue 43): candidates that explained nothing alone are not refitted in
the later rounds."""
from __future__ import annotations

import math
from types import SimpleNamespace

from hypothesis import given, settings, strategies as st

from finkensim.gap.attribute.selection import hopeless


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.0, 2.0), min_size=1, max_size=8), st.floats(0.0, 2.0))
def test_hopeless_are_the_candidates_no_better_than_the_configured_model(scores, before):
    first = [SimpleNamespace(name=f"e{i}", score_heldout=s) for i, s in enumerate(scores)]
    first.append(SimpleNamespace(name="nan", score_heldout=math.nan))  # an unscorable fit is hopeless too
    out = hopeless(first, before)
    assert out == {r.name for r in first if not r.score_heldout < before}
    assert "nan" in out
