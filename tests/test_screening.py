"""Coarse-to-fine fits (finkensim/gap/screening.py): which readings the coarse stage scores, and that its objective
is the full one on those readings."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.gap.screening import SCREEN_MIN_READINGS, SCREEN_SHARE, coarse_objective, full_objective, screen_rows, screens


class _Params:
    def __init__(self, shift):
        self.shift = shift

    def sensor_key(self, sensor):
        return (sensor, self.shift)


class _Effect:
    @staticmethod
    def apply(current, values):
        return _Params(values["shift"])


class _Diag:
    """The parts of a Diagnosis the screening uses: training rows, tables, per-row scores and the objective."""

    def __init__(self, sizes):
        self.rows_fit = {s: np.sort(np.random.default_rng(1).choice(10 * n, n, replace=False)) for s, n in sizes.items()}
        self.tables = dict.fromkeys(sizes)
        self.scored = []

    def score_rows(self, sensor, p, rows):
        self.scored.append((sensor, rows.size))
        crps = np.abs(np.sin(rows * 0.01) - p.shift)
        return crps, crps

    def _objective(self, effect, current, sensors, values):
        p = effect.apply(current, values)
        return sum(float(np.nanmean(self.score_rows(s, p, self.rows_fit[s])[0])) for s in sensors if s in self.tables)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 3 * SCREEN_MIN_READINGS))
def test_screen_rows_are_every_kth_training_row_or_all(n):
    diag = _Diag({"ultrasonic": n})
    rows = screen_rows(diag, "ultrasonic")
    fit = diag.rows_fit["ultrasonic"]
    if n < SCREEN_MIN_READINGS:
        assert rows is fit and not screens(diag, ["ultrasonic"])
    else:
        np.testing.assert_array_equal(rows, fit[::SCREEN_SHARE])
        assert screens(diag, ["ultrasonic"])
    assert screen_rows(diag, "ultrasonic") is rows  # one array: score caches key on it


def test_coarse_objective_is_the_full_objective_on_the_screen_rows():
    diag = _Diag({"ultrasonic": 2 * SCREEN_MIN_READINGS, "imu": 100})
    sensors = ["ultrasonic", "imu", "ranging"]  # ranging has no table: skipped
    coarse = coarse_objective(diag, _Effect, None, sensors)
    v = coarse({"shift": 0.3})
    want = sum(float(np.nanmean(np.abs(np.sin(screen_rows(diag, s) * 0.01) - 0.3))) for s in ("ultrasonic", "imu"))
    assert v == want
    n = len(diag.scored)
    assert coarse({"shift": 0.3}) == v and len(diag.scored) == n  # cached per sensor and predictive
    assert diag.scored[0] == ("ultrasonic", 2 * SCREEN_MIN_READINGS // SCREEN_SHARE)


def test_without_enough_readings_coarse_is_full():
    diag = _Diag({"imu": 100})
    coarse = coarse_objective(diag, _Effect, None, ["imu"])
    full = full_objective(diag, _Effect, None, ["imu"])
    assert coarse({"shift": 0.1}) == full({"shift": 0.1})


class _Prm:
    def __init__(self, name, lo, hi):
        self.name, self.lo, self.hi, self.integer = name, lo, hi, False


@settings(max_examples=25, deadline=None)
@given(a=st.floats(-0.9, 0.9), b=st.floats(0.5, 9.5), offset=st.floats(-0.05, 0.05))
def test_simplex_polished_on_all_readings_is_never_worse_and_finds_the_minimum(a, b, offset):
    """A bowl whose coarse version is shifted a little (a subsample's noise): the polish on the full objective
    ends near the full minimum, and never above the full objective at the start."""
    from finkensim.gap.fits import nelder_mead

    group = [_Prm("a", -1.0, 1.0), _Prm("b", 0.0, 10.0)]
    full = lambda v: (v["a"] - a) ** 2 + ((v["b"] - b) / 10) ** 2  # noqa: E731
    coarse = lambda v: (v["a"] - a - offset) ** 2 + ((v["b"] - b) / 10 - offset) ** 2  # noqa: E731
    start = {"a": 0.0, "b": 5.0}
    out = nelder_mead(full, start, group, [0.0, 5.0], full(start), maxfev=60, coarse=coarse)
    assert full(out) <= full(start)
    assert abs(out["a"] - a) < 0.06 and abs(out["b"] - b) < 0.6
    assert -1.0 <= out["a"] <= 1.0 and 0.0 <= out["b"] <= 10.0
