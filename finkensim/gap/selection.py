"""Which effect explains the gap, and the verdict: greedy forward selection over the fitted catalogue
and the report (``spec/gap-report.md``).

Every candidate effect is fitted on the training flights and scored on the held-out ones; the best is
added while it removes a significant share (``gap.accept_gain``) of the remaining held-out gap, up to
``max_added`` effects. The verdict names the first effect added when the selected effects remove at least
``gap.unexplained_shrink`` of the gap on the sensors where it is significant, else ``unexplained``.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..config import Config
from . import effects as fx
from .diagnose import Diagnosis
from .replay import GapInputError
from .result import GapDetails, GapReport

__all__ = ["run_diagnosis", "diagnose"]


def run_diagnosis(diag: Diagnosis, effect_names=None, max_added: int = 4, refit_top: int = 4) -> GapReport:
    """Locations, effect fits, greedy forward selection and verdict of a prepared :class:`Diagnosis`.

    effect_names: the candidate effects (default ``gap.effects``, else the whole catalogue); at most
    ``max_added`` effects are selected, each step refitting the ``refit_top`` leading candidates on top of
    what was added. Returns a :class:`~finkensim.gap.result.GapReport`."""
    cfg = diag.cfg.gap
    t0 = time.perf_counter()
    names = list(effect_names if effect_names is not None else (cfg.effects or fx.REGISTRY))
    unknown = [n for n in names if n not in fx.REGISTRY]
    if unknown:
        raise GapInputError(f"gap.effects names unknown effects {unknown}; catalogued: {sorted(fx.REGISTRY)}")
    cands = [fx.REGISTRY[n] for n in names if any(s in diag.tables for s in fx.REGISTRY[n].sensors)]

    diag.say("scoring the configured model")
    base = diag.base
    ev_b, rows_ho = diag.evaluate(base, "heldout")
    gap_vals = {s: g for s, (_, g) in ev_b.items()}
    gap_before, gap_ci, gap_p = diag.overall(gap_vals, rows_ho)
    base_scores = {s: c for s, (c, _) in ev_b.items()}
    score_before = float(np.mean([np.nanmean(c) for c in base_scores.values()]))
    # significance per sensor (Bonferroni over sensors): a gap in one sensor is not diluted by the
    # noise of the others
    per_sensor = {}
    for s in gap_vals:
        m, ci_s, p_s = diag.overall({s: gap_vals[s]}, {s: rows_ho[s]})
        per_sensor[s] = {"gap": m, "ci": list(ci_s), "p": p_s,
                         "significant": bool(np.isfinite(p_s) and p_s < cfg.alpha / len(gap_vals) and m > cfg.margin)}
    gap_sensors = [s for s, v in per_sensor.items() if v["significant"]]
    significant = bool(gap_sensors)

    def gap_on(values_by_sensor, sensors):
        """Mean held-out gap over the given sensors (the ones with a significant base gap)."""
        return float(np.mean([np.nanmean(values_by_sensor[s]) for s in sensors])) if sensors else math.nan

    base_gap_sig = gap_on(gap_vals, gap_sensors)

    diag.say("locating the gap")
    locs = diag.locations(base)

    diag.say(f"fitting {len(cands)} effects")
    first = []
    for e in cands:
        diag.say(f"  effect {e.name}")
        r = diag.score_heldout(diag.fit(e, base))
        first.append(r)
    first.sort(key=lambda r: r.score_heldout)

    def improvement(cur_scores, new_scores):
        diff = {s: cur_scores[s] - new_scores[s] for s in cur_scores if s in new_scores}
        return diag.overall(diff, rows_ho)

    # greedy forward selection on the held-out score
    current, cur_scores, cur_gap = base, base_scores, base_gap_sig
    waterfall = [{"step": "configured model", "effect": None, "gap_heldout": gap_before, "ci": list(gap_ci)}]
    added, pool = [], list(first)
    ties = []
    while significant and pool and len(added) < max_added:
        if added:  # refit the leading remaining candidates on top of what was added
            pool = sorted((diag.score_heldout(diag.fit(fx.REGISTRY[r.name], current)) for r in pool[:refit_top]),
                          key=lambda r: r.score_heldout)
        best = pool[0]
        imp, imp_ci, imp_p = improvement(cur_scores, best.rows_score)
        best_gap_sig = gap_on(best.rows_gap, gap_sensors)
        gain = (cur_gap - best_gap_sig) / cur_gap if cur_gap > 0 else 0.0
        if not (np.isfinite(imp_p) and imp_p < cfg.alpha and imp > 0 and gain >= cfg.accept_gain):
            break
        if not added:
            best_imp = score_before - best.score_heldout
            ties = [r.name for r in pool[1:]
                    if best_imp > 0 and (score_before - r.score_heldout) >= (1 - cfg.tie_tolerance) * best_imp]
        added.append(best)
        current, cur_scores, cur_gap = best.params, best.rows_score, best_gap_sig
        ev_c, _ = diag.evaluate(current, "heldout")
        g, ci, _ = diag.overall({s: gg for s, (_, gg) in ev_c.items()}, rows_ho)
        waterfall.append({"step": f"+ {best.name}", "effect": best.name, "gap_heldout": g, "ci": list(ci),
                          "params": _clean(best.values)})
        pool = [r for r in pool if r.name != best.name]
        diag.say(f"  added {best.name}: held-out gap {g:.4f}")
        if not (cur_gap > cfg.margin):
            break

    def shrink(g):
        return float(1.0 - g / gap_before) if gap_before > 0 else 0.0

    effects = [{"name": r.name, "params": _clean(r.values), "score_heldout": r.score_heldout,
                "gap_after_train": r.gap_train, "gap_after_heldout": r.gap_heldout,
                "shrink_heldout": shrink(r.gap_heldout)} for r in first]
    total_shrink = float(1.0 - cur_gap / base_gap_sig) if significant and base_gap_sig > 0 else 0.0
    if not significant:
        verdict = {"effect": None, "shrink_heldout": 0.0, "unexplained": False, "significant_gap": False}
    elif not added or total_shrink < cfg.unexplained_shrink:
        verdict = {"effect": None, "shrink_heldout": shrink(first[0].gap_heldout) if first else 0.0,
                   "unexplained": True, "significant_gap": True}
        diag.say(f"  best effects remove {100 * total_shrink:.0f} % of the gap on {', '.join(gap_sensors)}: unexplained")
    else:
        verdict = {"effect": added[0].name, "shrink_heldout": shrink(added[0].gap_heldout), "unexplained": False,
                   "significant_gap": True}

    details = GapDetails(
        gap_before_ci=list(gap_ci), gap_before_p=gap_p, score_before=score_before,
        per_sensor=per_sensor, gap_sensors=gap_sensors,
        waterfall=waterfall, added=[r.name for r in added], total_shrink=total_shrink, ties=ties,
        significant_locations=[i for i, loc in enumerate(locs) if loc["_significant"]],
        scales=diag.scale, sensors=list(diag.tables), n_readings={s: int(t.n) for s, t in diag.tables.items()},
        seconds=time.perf_counter() - t0, block_seconds=diag.block_seconds,
        catch_all=[r.name for r in first if fx.REGISTRY[r.name].catch_all], tie_tolerance=cfg.tie_tolerance,
        unexplained_shrink=cfg.unexplained_shrink)
    return GapReport(flights={"train": diag.train_names, "heldout": diag.heldout_names}, score="crps_gap_normalised",
                     gap_before=gap_before,
                     locations=[{k: v for k, v in loc.items() if not k.startswith("_")} for loc in locs],
                     effects=effects, verdict=verdict, details=details)


def _clean(values: dict) -> dict:
    return {k: (int(v) if isinstance(v, (int, np.integer)) else float(v)) for k, v in values.items()}


def diagnose(logs, names, cfg: Config | None = None, heldout=None, progress=None, effect_names=None) -> GapReport:
    """Diagnose the sim-to-real gap of flight logs against the simulator configured by ``cfg``.

    logs: :class:`~finkensim.flightlog.FlightLog` list; names: one name per log (file names);
    cfg: the simulator's config (default: the defaults); heldout: names of the held-out flights (default:
    the last; a single flight is split in halves); progress: callable taking a message, or None;
    effect_names: the candidate effects (default ``cfg.gap.effects``, else the whole catalogue).
    Returns a :class:`~finkensim.gap.result.GapReport` (``.to_spec()``, ``.write(out)``).
    """
    cfg = Config() if cfg is None else cfg
    diag = Diagnosis(logs, names, cfg, heldout=heldout, progress=progress)
    return run_diagnosis(diag, effect_names)
