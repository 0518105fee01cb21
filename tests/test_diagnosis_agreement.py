"""benchmarks.diagnosis_agreement's comparison of two samples of validation trials (no trial is run here)."""
from __future__ import annotations

import json

from benchmarks.diagnosis_agreement import compare


def _row(case, seed, correct, effects, cpu, values=None, unexplained=False):
    return dict(case=case, seed=seed, cpu_s=cpu, correct=correct, significant=bool(effects) or unexplained,
                effects=effects, unexplained=unexplained, ambiguous=[], values=values or {})


def _write(path, rows):
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(path)


def test_compare_names_changed_verdicts_and_right_to_wrong(tmp_path):
    before = _write(tmp_path / "b.jsonl", [
        _row("latency", 1, True, ["latency"], 4.0, {"latency": {"ultrasonic": 0.2}}),
        _row("sonar_bias", 1, True, ["sonar_bias"], 6.0),
        _row("null", 1, True, [], 2.0),
        _row("only_before", 1, True, [], 1.0)])
    after = _write(tmp_path / "a.jsonl", [
        _row("latency", 1, True, ["latency"], 2.0, {"latency": {"ultrasonic": 0.22}}),
        _row("sonar_bias", 1, False, [], 3.0, unexplained=True),
        _row("null", 1, True, [], 1.0)])
    text = compare(before, after)
    assert "trials compared: 3; same verdict: 2; right before: 3, right after: 2" in text
    assert "right -> wrong: ['sonar_bias:1']" in text
    assert "wrong -> right: none" in text
    assert "sonar_bias:1 (True, ('sonar_bias',), False) -> (True, (), True)" in text
    assert "largest 0.091" in text  # |0.22 − 0.2| / 0.22
    assert "median 4.00 -> 2.00, mean 4.00 -> 2.00, sum 12.0 -> 6.0" in text


def test_compare_counts_exactly_equal_values_and_bit_identical_reports(tmp_path):
    same = {"latency": {"ultrasonic": 0.2}}
    before = _write(tmp_path / "b.jsonl", [
        {**_row("latency", 1, True, ["latency"], 4.0, same), "report_sha256": "aa"},
        {**_row("latency", 2, True, ["latency"], 4.0, same), "report_sha256": "bb"},
        _row("null", 1, True, [], 2.0)])
    after = _write(tmp_path / "a.jsonl", [
        {**_row("latency", 1, True, ["latency"], 3.0, same), "report_sha256": "aa"},
        {**_row("latency", 2, True, ["latency"], 3.0, {"latency": {"ultrasonic": 0.2 + 1e-16}}),
         "report_sha256": "cc"},
        _row("null", 1, True, [], 1.0)])
    text = compare(before, after)
    assert "fitted values of the named effects exactly equal: 2 of 3; differ: latency:2" in text
    assert "bit-identical: 1 of 2; differ: latency:2" in text


def test_report_digest_sees_every_bit_of_a_fitted_value():
    import numpy as np

    from benchmarks.diagnosis_agreement import _report_digest

    class Report:
        def __init__(self, x):
            self.details = type("D", (), {"added_params": {"latency": {"ultrasonic": x}},
                                          "param_intervals": {"latency": {"draws": np.array([x, 1.0])}}})()

        def to_json(self):
            return "{}\n"

    assert _report_digest(Report(0.2)) == _report_digest(Report(0.2))
    assert _report_digest(Report(0.2)) != _report_digest(Report(np.nextafter(0.2, 1.0)))
