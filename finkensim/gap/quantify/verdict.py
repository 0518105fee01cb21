"""Quantify: how much of the gap the selection explains, the waterfall of its steps, each candidate's shrink, the
verdict, and — when the gap stays unexplained — the data-driven correction (:mod:`.correction`).

The verdict names the first effect added when the selected effects remove at least ``gap.unexplained_shrink`` of
the gap on the sensors where it is significant (or what remains cannot be told from zero), else ``unexplained``
(``docs/formats/gap-report.md``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..attribute.selection import Selection, clean_values
from ..attribute.stated import stated_fields
from ..detect.significance import sensor_gaps
from .bounds import flag_bounds
from .correction import fit_correction
from ..attribute.shrink import ShrinkMeter

__all__ = ["Outcome", "quantify", "correct"]


@dataclass
class Outcome:
    """What the quantify step measured.

    Parameters
    ----------
    meter : ShrinkMeter
        The shrink measure over every model evaluated (:class:`~finkensim.gap.attribute.shrink.ShrinkMeter`).
    shrink_sensors : list of str
        The sensors the shrink is measured on (those with a significant gap, else all).
    waterfall : list of dict
        The report's waterfall: one entry per selection step.
    effects : list of dict
        The report's ``effects``: every first-round candidate with its fit and shrink.
    bounds : dict
        Effect name → its parameters fitted at a bound (:func:`~finkensim.gap.quantify.bounds.flag_bounds`).
    total_shrink : float
        The selection's held-out shrink (0 without a significant gap).
    verdict : dict
        The report's ``verdict``.
    remaining : dict
        Sensor → the test of what the selection leaves (:func:`~finkensim.gap.detect.significance.sensor_gaps`).
    correction : Correction or None
        The fitted correction (:class:`~finkensim.gap.quantify.correction.Correction`), when the gap stays
        unexplained.
    correction_block : dict or None
        The report's ``correction``.
    correction_skipped : dict
        Sensor (or "all") → why no correction was fitted.
    """

    meter: ShrinkMeter
    shrink_sensors: list
    waterfall: list
    effects: list
    bounds: dict
    total_shrink: float
    verdict: dict
    remaining: dict
    correction: object = None
    correction_block: dict | None = None
    correction_skipped: dict = field(default_factory=dict)


def quantify(sel: Selection) -> Outcome:
    """Measure the selection: the waterfall, each candidate's shrink, the verdict.

    Parameters
    ----------
    sel : Selection
        The finished selection (:class:`~finkensim.gap.attribute.selection.Selection`).

    Returns
    -------
    Outcome
        The measures and the verdict (no correction yet: :func:`correct`).
    """
    diag, found, cfg = sel.diag, sel.found, sel.diag.cfg.gap
    shrink_sensors = found.gap_sensors or list(found.base_scores)
    # how much each model explains: calibration and proper score, against what the catalogue built
    meter = ShrinkMeter(found.base_scores, found.gap_vals, shrink_sensors, sel.evaluated)
    waterfall = []
    for step, name, rows_score, rows_gap, params in sel.steps:
        g, ci, _ = diag.overall({s: rows_gap[s] for s in shrink_sensors},
                                {s: found.rows_ho[s] for s in shrink_sensors})
        w = {"step": step, "effect": name, "gap_heldout": meter.gap_after(rows_score, rows_gap),
             "calibration_gap": g, "ci": list(ci)}
        if params is not None:
            w["params"] = params
        waterfall.append(w)
    effects = [{"name": r.name, "params": clean_values(r.values), "score_heldout": r.score_heldout,
                "gap_after_train": r.gap_train, "gap_after_heldout": meter.gap_after(r.rows_score, r.rows_gap),
                "shrink_heldout": meter.shrink(r.rows_score, r.rows_gap),
                **stated_fields(diag.flights, r.name, r.values)}
               for r in sel.first]
    bounds = flag_bounds(effects, diag.base)
    total_shrink = meter.shrink(sel.cur_scores, sel.cur_gaps) if found.significant else 0.0
    names_added = [r.name for r in sel.added]
    verdict = {"effect": None, "effects": [], "ambiguous": [], "shrink_heldout": 0.0, "unexplained": False,
               "significant_gap": found.significant}
    # spec: 'unexplained' means a significant gap *remains*; a shrink under the threshold whose remainder cannot be
    # told from zero (a small gap measured with little power) is an explanation as good as the data can show
    remaining = sensor_gaps(diag, sel.cur_gaps, found.rows_ho, found.gap_sensors, len(found.gap_vals), cfg,
                            remainder=True) if sel.added else {}
    remains = not sel.added or any(r["significant"] for r in remaining.values())
    if found.significant and (not sel.added or (total_shrink < cfg.unexplained_shrink and remains)):
        verdict.update(unexplained=True, shrink_heldout=total_shrink if sel.added else 0.0)
        diag.say(f"  best effects remove {100 * total_shrink:.0f} % of the gap on {', '.join(found.gap_sensors)}: "
                 "unexplained")
    elif found.significant:
        verdict.update(effect=names_added[0], effects=names_added, ambiguous=sel.ambiguous,
                       shrink_heldout=total_shrink)
    if sel.earned is not None or sel.refits:
        verdict["tried"] = (sel.earned.tried if sel.earned is not None else []) + sel.refits
    return Outcome(meter, shrink_sensors, waterfall, effects, bounds, total_shrink, verdict, remaining)


def correct(sel: Selection, out: Outcome, with_correction: bool = True) -> None:
    """An unexplained gap: fit the data-driven correction on the sensors with a gap (largest first) and the
    features where it was located, and measure its shrink. Updates ``out`` in place.

    Parameters
    ----------
    sel : Selection
        The finished selection.
    out : Outcome
        The quantify step's result; its ``correction``, ``correction_block`` and ``correction_skipped`` are set.
    with_correction : bool
        False: no correction is fitted (``correction_skipped`` says so when the gap is unexplained).
    """
    if not out.verdict["unexplained"]:
        return
    if not with_correction:
        out.correction_skipped["all"] = "not asked for"
        return
    found = sel.found
    located = {}
    for loc in found.locs:
        if loc["_significant"] and loc["feature"] not in located.setdefault(loc["sensor"], []):
            located[loc["sensor"]].append(loc["feature"])
    out.correction = correction = fit_correction(
        sel.diag, sel.current, sorted(found.gap_sensors, key=lambda s: -found.per_sensor[s]["gap"]), located,
        why=out.correction_skipped)
    if correction is not None:
        # measured against everything, itself included: a flexible regression is sharper than any physical
        # model with approximate parts, which is not a defect of the catalogue's effects
        meter = ShrinkMeter(found.base_scores, found.gap_vals, out.shrink_sensors,
                            sel.evaluated + [correction.rows_score])
        out.correction_block = {"sensor": correction.sensor, "features": correction.features,
                                "shrink_heldout": meter.shrink(correction.rows_score, correction.rows_gap),
                                "method": correction.method}
