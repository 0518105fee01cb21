"""Proof that the loop closes (``finkensim gap-validate --calibrate``): diagnose, calibrate, diagnose new flights.

Each trial runs the withheld-effect case as :func:`~finkensim.gap.validation.cases.run_case` does, writes the calibrated
config of its report (:func:`~finkensim.gap.quantify.calibrate.write_calibrated`, with the learned correction's table when
the verdict is unexplained), then generates *new* "real" flights of the same truth (the same case and seed, so the
same effect at the same strength, other flight seeds) and diagnoses them against the calibrated config. The row
gains ``calibrated_significant`` (a significant gap remains), ``calibrated_gap`` (the new held-out gap),
``calibrated_gap_ratio`` (new gap / the first diagnosis's gap, each normalised by its own diagnosis's scale) and
``calibrated_gap_left`` (what is left of the first diagnosis's gap, both in the first diagnosis's units:
:func:`gap_left`). :func:`calibrated_table` summarises them per case: the share of trials with no significant gap
after calibration (Wilson 95 % interval), and the median of what is left.

Why two ratios: a diagnosis normalises each sensor's gap by its configured model's mean absolute error on the
training readings (:mod:`finkensim.gap.diagnosis`). The first diagnosis's configured model lacks the effect, the
re-diagnosis's is calibrated, so its error, and with it the scale, is smaller: the same residual reads larger in the
re-diagnosis's units (``calibrated_gap_ratio``; docs/calibration.md measures how much). ``calibrated_gap_left``
undoes that.
"""
from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from ...config import load_config
from ..quantify.calibrate import correction_files, write_calibrated
from ..diagnosis import Diagnosis
from ..pipeline import run_diagnosis
from .cases import generate, get_case, run_case
from .tables import wilson

__all__ = ["run_calibrated_case", "calibrated_table", "gap_left"]


def gap_left(first, again) -> float:
    """What the re-diagnosis ``again`` leaves of the held-out gap of the diagnosis ``first`` (two
    :class:`~finkensim.gap.report.result.GapReport`), both in ``first``'s units.

    Parameters
    ----------
    first : GapReport
        The diagnosis of the "real" flights under the configured model.
    again : GapReport
        The diagnosis of new flights of the same truth under the calibrated config.

    Returns
    -------
    float
        The mean over ``first``'s gap sensors (those ``first.gap_before`` averages: the ones with a significant gap,
        or every sensor when none has one) of ``again``'s per-sensor held-out gap times ``again``'s scale over
        ``first``'s scale, divided by ``first.gap_before``; NaN when ``first``'s gap is not positive and finite or
        ``again`` lacks one of those sensors.
    """
    gap0 = first.gap_before
    if not (math.isfinite(gap0) and gap0 > 0):
        return math.nan
    d1, d2 = first.details, again.details
    sensors = list(d1.gap_sensors) or list(d1.per_sensor)
    if any(s not in d2.per_sensor or s not in d2.scales for s in sensors):
        return math.nan
    left = [d2.per_sensor[s]["gap"] * d2.scales[s] / d1.scales[s] for s in sensors]
    return float(np.mean(left) / gap0)


def run_calibrated_case(name: str, seed: int, n_flights: int = 2, duration: float = 60.0, n_copters=None,
                        conventions=None) -> dict:
    """One trial of ``name`` (:func:`~finkensim.gap.validation.cases.run_case`'s row) plus its calibrated re-diagnosis on
    ``n_flights`` new flights of the same truth."""
    keep: dict = {}
    row = run_case(name, seed, n_flights=n_flights, duration=duration, n_copters=n_copters, conventions=conventions,
                   keep=keep)
    report = keep["report"]
    with tempfile.TemporaryDirectory(prefix="finkensim-calibrate-") as tmp:
        path = write_calibrated(report, Path(tmp) / "calibrated.toml")
        cal = load_config(path)
        logs, _, _ = generate(get_case(name), seed, n_flights=n_flights, duration=duration, n_copters=n_copters,
                              conventions=keep["conventions"], flights_from=n_flights)
        names = [f"{name}-{seed}-new{i}.npz" for i in range(len(logs))]
        again = run_diagnosis(Diagnosis(logs, names, cal))
    gap0 = row["gap_before"]
    row.update(calibrated_significant=bool(again.verdict["significant_gap"]), calibrated_gap=again.gap_before,
               calibrated_gap_ratio=again.gap_before / gap0 if gap0 and math.isfinite(gap0) else math.nan,
               calibrated_gap_left=gap_left(report, again),
               calibrated_effects=list(again.verdict["effects"]),
               calibrated_correction=", ".join(correction_files(cal)))
    return row


def calibrated_table(rows: list[dict]) -> str:
    """Markdown: per case (the pairs pooled in one row, those left with a significant gap named below the table),
    trials, the share with no significant gap after calibration (Wilson 95 % interval), the
    median of what is left of the first diagnosis's held-out gap (``calibrated_gap_left``, in its units; rows written
    before it existed: ``calibrated_gap_ratio``; n/a when no first gap was positive), and the share of trials whose
    calibration used the learned correction.

    Parameters
    ----------
    rows : list of dict
        Trial rows of :func:`run_calibrated_case` (rows without ``calibrated_significant`` are skipped).

    Returns
    -------
    str
        The markdown table.
    """
    by: dict[str, list[dict]] = {}
    for r in rows:
        if "calibrated_significant" in r:
            by.setdefault(r["case"], []).append(r)
    pairs = sorted(c for c in by if "+" in c)
    pooled = {f"**every pair** ({len(pairs)})": [r for c in pairs for r in by.pop(c)]} if pairs else {}
    lines = ["| case | trials | no significant gap after calibration | 95 % interval | median gap left | "
             "with the learned correction |", "|---|---|---|---|---|---|"]
    for case, rs in [(c, by[c]) for c in sorted(by)] + list(pooled.items()):
        n = len(rs)
        k = sum(not r["calibrated_significant"] for r in rs)
        lo, hi = wilson(k, n)
        # a first gap that is not positive (null: no gap) has nothing to leave
        left = [r.get("calibrated_gap_left", r["calibrated_gap_ratio"]) if r.get("gap_before", 1.0) > 0 else math.nan
                for r in rs]
        ratio = np.nanmedian(left) if n and not np.isnan(left).all() else math.nan
        corr = sum(bool(r.get("calibrated_correction")) for r in rs)
        lines.append(f"| {case} | {n} | {100 * k / n:.0f} % | {100 * lo:.0f}–{100 * hi:.0f} % | "
                     f"{'n/a' if not np.isfinite(ratio) else f'{round(100 * ratio)} %'} | {corr}/{n} |")
    left_open = sorted(f"{r['case']} (seed {r['seed']})" for rs in pooled.values() for r in rs if r["calibrated_significant"])
    if left_open:
        lines += ["", f"Pairs with a significant gap after calibration: {', '.join(left_open)}."]
    return "\n".join(lines) + "\n"
