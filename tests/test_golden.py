"""Golden results stay bit-identical (see tests/golden.py; regenerate only for a deliberate fix)."""
from __future__ import annotations

import json

import pytest

from tests import golden

EXPECTED = json.loads(golden.GOLDEN_FILE.read_text())


def _compare(kind, got, expected):
    bad = {k: (got.get(k), v) for k, v in expected.items() if got.get(k) != v}
    extra = sorted(set(got) - set(expected))
    assert not bad and not extra, (
        f"{kind}: results changed (got, expected) {bad}; new keys {extra}. If this is a deliberate fix, "
        f"run `python -m tests.golden --update` and say so in the commit")


@pytest.mark.parametrize("name", [f[0] for f in golden.FLIGHTS])
def test_flight_logs_are_bit_identical(name):
    spec = next(f for f in golden.FLIGHTS if f[0] == name)
    from finkensim.scenario import simulate_flight

    _, over, duration, seed = spec
    log, _, _ = simulate_flight(golden._config(over), duration=duration, seed=seed, ideal=True)
    _compare(name, golden.digest_log(log), EXPECTED["flights"][name])


def test_sweep_table_is_bit_identical():
    _compare("sweep", golden.sweep_digest(), EXPECTED["sweep"])


def test_gap_report_numbers_are_bit_identical():
    _compare("gap", golden.gap_digest(), EXPECTED["gap"])
