"""The report of a finished diagnosis: the spec's fields (:class:`~.result.GapReport`) and what people need to read
them (:class:`~.result.GapDetails`), from the detect, attribute and quantify steps' results."""
from __future__ import annotations

from ..attribute import effects as fx
from ..attribute.selection import Selection, clean_values
from ..quantify.verdict import Outcome
from ..detect.sufficiency import too_little_data
from .result import GapDetails, GapReport

__all__ = ["assemble_report"]


def _gap_before_interval(diag, found, sensors) -> tuple:
    """The block-bootstrap 95 % interval and p-value of ``gap_before`` itself: the held-out gap averaged over the
    sensors the shrink is measured on (``sensors``, those with a significant gap when there are any). The detect
    step's interval is of the average over every sensor (the report's ``calibration_gap``); it is reused when the
    two averages are over the same sensors."""
    if list(sensors) == list(found.gap_vals):
        return found.gap_ci, found.gap_p
    _, ci, p = diag.overall({s: found.gap_vals[s] for s in sensors}, found.rows_ho)
    return ci, p


def assemble_report(sel: Selection, out: Outcome, seconds: float) -> GapReport:
    """The :class:`GapReport` of a selection and its measures.

    Parameters
    ----------
    sel : Selection
        The finished selection (:class:`~finkensim.gap.attribute.selection.Selection`; its ``found`` is the detect
        step's result).
    out : Outcome
        The quantify step's result, correction included (:class:`~finkensim.gap.quantify.verdict.Outcome`).
    seconds : float
        Wall-clock seconds the diagnosis took (reported, never asserted).

    Returns
    -------
    GapReport
        The report (``docs/formats/gap-report.md``).
    """
    diag, found, cfg = sel.diag, sel.found, sel.diag.cfg.gap
    significant, locs = found.significant, found.locs
    little = too_little_data(found.sizes, {s: s in found.gap_sensors for s in found.sizes})
    gap_ci, gap_p = _gap_before_interval(diag, found, out.meter.sensors)
    details = GapDetails(
        gap_before_ci=list(gap_ci), gap_before_p=gap_p, score_before=found.score_before,
        per_sensor=found.per_sensor, gap_sensors=found.gap_sensors,
        waterfall=out.waterfall, added=[r.name for r in sel.added], total_shrink=out.total_shrink,
        ties=sel.ambiguous,
        significant_locations=[i for i, loc in enumerate(locs) if loc["_significant"]] if significant else [],
        scales=diag.scale, sensors=list(diag.tables), n_readings={s: int(t.n) for s, t in diag.tables.items()},
        seconds=seconds, block_seconds=diag.block_seconds,
        catch_all=[r.name for r in sel.first if fx.REGISTRY[r.name].catch_all], tie_tolerance=cfg.tie_tolerance,
        unexplained_shrink=cfg.unexplained_shrink, remaining=out.remaining, calibration_gap=found.calibration_gap,
        calibration_ci=list(found.gap_ci), best_score=out.meter.s_min,
        censoring={s: c.to_dict() for s, c in diag.censoring.items()}, correction=out.correction,
        targeted=found.targeted, correction_skipped=out.correction_skipped,
        limit_notes=dict(getattr(diag, "limit_notes", {})), sample_sizes=found.sizes,
        too_little_data=little, at_bound=out.bounds, residuals=[loc["_residual"] for loc in locs],
        added_params={r.name: clean_values(r.values) for r in sel.added}, config=diag.cfg)
    locations = [{**{k: v for k, v in loc.items() if not k.startswith("_")},
                  "significant": bool(loc["_significant"] and significant)} for loc in locs]
    return GapReport(flights={"train": diag.train_names, "heldout": diag.heldout_names}, score="crps_gap_normalised",
                     gap_before=out.meter.c0, locations=locations, effects=out.effects, verdict=out.verdict,
                     correction=out.correction_block, details=details)
