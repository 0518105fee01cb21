"""Proof that the loop closes (``finkensim gap-validate --calibrate``): diagnose, calibrate, diagnose new flights.

Each trial runs the withheld-effect case as :func:`~finkensim.gap.validation.cases.run_case` does, writes the calibrated
config of its report (:func:`~finkensim.gap.quantify.calibrate.write_calibrated`, with the learned correction's table when
the verdict is unexplained), then generates *new* "real" flights of the same truth (the same case and seed, so the
same effect at the same strength, other flight seeds) and diagnoses them against the calibrated config. The row
gains ``calibrated_significant`` (a significant gap remains), ``calibrated_gap`` (the new held-out gap) and
``calibrated_gap_ratio`` (new gap / the first diagnosis's gap: what is left of it). :func:`calibrated_table`
summarises them per case: the share of trials with no significant gap after calibration (Wilson 95 % interval),
and the median ratio.
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

__all__ = ["run_calibrated_case", "calibrated_table"]


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
               calibrated_effects=list(again.verdict["effects"]),
               calibrated_correction=", ".join(correction_files(cal)))
    return row


def calibrated_table(rows: list[dict]) -> str:
    """Markdown: per case, trials, the share with no significant gap after calibration (Wilson 95 % interval), the
    median of what is left of the first diagnosis's held-out gap, and the share of trials whose calibration used the
    learned correction."""
    by: dict[str, list[dict]] = {}
    for r in rows:
        if "calibrated_significant" in r:
            by.setdefault(r["case"], []).append(r)
    lines = ["| case | trials | no significant gap after calibration | 95 % interval | median gap left | "
             "with the learned correction |", "|---|---|---|---|---|---|"]
    for case in sorted(by):
        rs = by[case]
        n = len(rs)
        k = sum(not r["calibrated_significant"] for r in rs)
        lo, hi = wilson(k, n)
        ratio = np.nanmedian([r["calibrated_gap_ratio"] for r in rs]) if n else math.nan
        corr = sum(bool(r.get("calibrated_correction")) for r in rs)
        lines.append(f"| {case} | {n} | {100 * k / n:.0f} % | {100 * lo:.0f}–{100 * hi:.0f} % | "
                     f"{'n/a' if not np.isfinite(ratio) else f'{round(100 * ratio)} %'} | {corr}/{n} |")
    return "\n".join(lines) + "\n"
