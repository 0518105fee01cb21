"""The gap report for people (``report.md``): one step per section — the flights and sensors compared, the verdict in
words, how the scores are computed, where the gap lies, which effects were tried, how far the gap shrinks, and the
closing line. :func:`markdown` joins them; :func:`~finkensim.gap.report.write.write_report` writes the file.
"""
from __future__ import annotations

import math

import numpy as np

from ..detect.locations import MIN_BIN_READINGS
from .result import GapReport

__all__ = ["markdown", "bin_text", "uniform_features", "residual_sentences", "CATEGORIES", "UNITS"]

#: names of the categories of the discrete location features (``spec/gap-report.md``: hit_type 0 none, 1 wall,
#: 2 copter); the JSON keeps the numeric bin, the Markdown names the category
CATEGORIES = {"hit_type": ("none", "wall", "copter"), "neighbor_in_beam": ("no", "yes"),
              "axis": ("acc_x", "acc_y", "gyro")}


def bin_text(loc) -> str:
    """A location's bin in words: ``hit_type = none`` for a category, ``[0.20, 0.60)`` otherwise."""
    names = CATEGORIES.get(loc["feature"])
    low = loc["low"]
    if names is not None and low is not None and float(low).is_integer() and 0 <= int(low) < len(names):
        return f"{loc['feature']} = {names[int(low)]}"
    return f"[{_fmt(low, 2)}, {_fmt(loc['high'], 2)})"


def uniform_features(locations) -> dict:
    """(sensor, channel) -> features whose bins (at least two) all share one 95 % CI range: the gap does not
    change across that feature's bins as far as the data can tell."""
    groups = {}
    for loc in locations:
        if loc["ci"][0] is None or loc["ci"][1] is None:
            continue
        groups.setdefault((loc["sensor"], loc["channel"], loc["feature"]), []).append(loc["ci"])
    out = {}
    for (s, c, f), cis in groups.items():
        if len(cis) >= 2 and max(lo for lo, _ in cis) <= min(hi for _, hi in cis):
            out.setdefault((s, c), []).append(f)
    return out


UNITS = {"ultrasonic": "m", "ranging": "m", "imu": "(m/s or rad)"}


def _signed(x, sensor) -> str:
    if x is None or not math.isfinite(x):
        return "n/a"
    return f"{x:+.3f} {UNITS.get(sensor, '')}".strip()


def residual_sentences(locations, residuals) -> list:
    """Per sensor and channel, what is left in physical units along the ideal reading (``true_range``): "ranging
    reads +0.150 m long at every true_range bin ([+0.12, +0.18] m)" when every bin has one sign, else the bins'
    medians from short to long."""
    groups = {}
    for loc, r in zip(locations, residuals):
        if loc["feature"] == "true_range" and r is not None and math.isfinite(r):
            groups.setdefault((loc["sensor"], loc["channel"]), []).append((loc["low"], r))
    out = []
    for (s, c), bins in groups.items():
        bins.sort()
        vals = np.array([r for _, r in bins])
        name = s if c == "all" else f"{s}/{c}"
        if np.all(vals > 0) or np.all(vals < 0):
            word = "long" if vals[0] > 0 else "short"
            out.append(f"- {name} reads {_signed(float(np.median(vals)), s)} {word} at every true_range bin "
                       f"([{_signed(float(vals.min()), s)}, {_signed(float(vals.max()), s)}] across {vals.size} bins).")
        else:
            out.append(f"- {name}: reading − model median by true_range bin, short to long: "
                       + ", ".join(_signed(float(v), s) for v in vals) + ".")
    return out


def _fmt(x, nd=3):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{nd}f}"


def markdown(report: GapReport, figs: dict, max_locations: int = 15) -> str:
    """The report for people (Markdown): verdict in words, locations, effects, waterfall.

    Parameters
    ----------
    report : GapReport
        The diagnosis's report.
    figs : dict
        Figure name (``gap``, ``effects``, ``waterfall``, ``correction``) → file name, for each figure written.
    max_locations : int
        Rows of the locations table.
    """
    sections = (_flights_section(report), _verdict_section(report), _scores_section(report),
                _where_section(report, figs, max_locations), _which_section(report, figs),
                _how_far_section(report, figs), _closing_section(report, figs))
    return "\n".join(line for section in sections for line in section) + "\n"


def _flights_section(report: GapReport) -> list[str]:
    """Title, the flights (training / held out), the sensors and their readings, range limits, the gap per sensor."""
    priv = report.details
    lines = ["# Sim-to-real gap report", ""]
    fl = report["flights"]
    if fl["train"] == fl["heldout"]:
        lines.append(f"One flight, {', '.join(fl['train'])}: first half for training, second half held out.  ")
    else:
        lines.append(f"Training flights: {', '.join(fl['train'])}  ")
        lines.append(f"Held-out flights: {', '.join(fl['heldout'])}  ")
    lines.append(f"Sensors compared: {', '.join(priv.sensors)} "
                 f"({', '.join(f'{k}: {n} readings' for k, n in priv.n_readings.items())})  ")
    for s, n in priv.sample_sizes.items():
        lines.append(f"Held-out split, {s}: {n['train']} training and {n['heldout']} held-out readings in "
                     f"{n['blocks']} bootstrap blocks  ")
    for note in priv.limit_notes.values():
        lines.append(f"Range limit: {note}  ")
    lines.append("")
    if priv.per_sensor:
        lines.append("Held-out gap per sensor (the one figure used in every section): " + "; ".join(
            f"{s} {_fmt(v['gap'])} (95 % CI {_fmt(v['ci'][0])} … {_fmt(v['ci'][1])})" for s, v in priv.per_sensor.items())
            + ".")
        lines.append("")
    return lines


def _verdict_section(report: GapReport) -> list[str]:
    """## Verdict: a gap only the targeted test found, what too little data cannot decide, then no gap, an unexplained
    gap or the effect(s) that explain it."""
    priv = report.details
    v = report["verdict"]
    lines = ["## Verdict", ""]
    if v["significant_gap"] and priv.targeted is not None:
        t = priv.targeted
        lines += [f"The omnibus test of each sensor's calibration gap found nothing, but the targeted test did: "
                  f"{t['effect']}, fitted on the training flights, improves the held-out score of "
                  f"{', '.join(t['sensors'])} by {_fmt(t['improvement'])} (95 % CI {_fmt(t['ci'][0])} … "
                  f"{_fmt(t['ci'][1])}; p = {t['p']:.2g}, below {t['threshold']:.2g}, α over the structured effects).",
                  ""]
    for s, text in priv.too_little_data.items():
        lines += [f"**{s[0].upper() + s[1:]}: {text}.**", ""]
    if not v["significant_gap"]:
        cal, cal_ci = priv.calibration_gap, priv.calibration_ci
        lines.append(f"**No significant gap.** The held-out readings are consistent with the simulator: mean "
                     f"calibration gap {_fmt(cal)} (95 % CI {_fmt(cal_ci[0])} … {_fmt(cal_ci[1])})"
                     + (" — as far as these few readings can tell." if priv.too_little_data else "."))
    elif v["unexplained"]:
        lines += _unexplained_lines(report)
    else:
        lines += _explained_lines(report)
    return lines


def _unexplained_lines(report: GapReport) -> list[str]:
    """A significant gap no catalogued effect explains: its size, the best tries, the data-driven correction (or why
    there is none)."""
    priv = report.details
    v = report["verdict"]
    gs = priv.gap_sensors
    head = ("Significant gap; too little data to decide what explains it" if gs and all(
        s in priv.too_little_data for s in gs) else "Significant gap, unexplained")
    lines = [f"**{head}.** Held-out gap {_fmt(report['gap_before'])} on {', '.join(gs)} "
             f"(per sensor above); no catalogued effect "
             f"explains at least {100 * priv.unexplained_shrink:.0f} % of it (best single effect: "
             f"{report['effects'][0]['name'] if report['effects'] else 'none'}; selected effects together: "
             f"shrink {_fmt(v['shrink_heldout'], 2)}). Where it lies is listed below."]
    c = report.correction
    if c is not None:
        lines += ["", f"A data-driven correction of {c['sensor']} ({c['method']}) removes "
                      f"{100 * c['shrink_heldout']:.0f} % of the held-out gap: reality departs from the "
                      "simulator in a way the catalogue does not describe (see its partial dependence below)."]
    for s, why in priv.correction_skipped.items():
        lines += ["", f"No data-driven correction{'' if s == 'all' else ' of ' + s}: {why}."]
    return lines


def _explained_lines(report: GapReport) -> list[str]:
    """The effect that explains the gap with its fitted values, then its parameters at a bound, the other effects
    selected with it, a remainder the data cannot tell from zero, and near ties."""
    priv = report.details
    v = report["verdict"]
    e = next(e for e in report["effects"] if e["name"] == v["effect"])
    params = ", ".join(f"{k} = {_fmt(x, 4)}" for k, x in e["params"].items())
    lines = [f"**{v['effect']}** explains the gap: fitted on the training flights ({params}), it removes "
             f"{100 * e['shrink_heldout']:.0f} % of the held-out gap (from {_fmt(report['gap_before'])} "
             f"to {_fmt(e['gap_after_heldout'])})."]
    if priv.at_bound.get(v["effect"]):
        lines += ["", f"**At bound:** {', '.join(priv.at_bound[v['effect']])} of {v['effect']} sits at a bound of "
                      "its range: widen the range or suspect another effect."]
    if len(v["effects"]) > 1:
        lines += ["", f"Several effects at once: {', '.join(v['effects'])} (refitted jointly; together they remove "
                      f"{100 * v['shrink_heldout']:.0f} %)."]
    if v["shrink_heldout"] < priv.unexplained_shrink and priv.remaining:
        left = "; ".join(f"{k} {_fmt(r['gap'])} (95 % CI {_fmt(r['ci'][0])} … {_fmt(r['ci'][1])})"
                         for k, r in priv.remaining.items())
        lines += ["", f"The selected effects remove {100 * v['shrink_heldout']:.0f} % of the gap, less than "
                      f"{100 * priv.unexplained_shrink:.0f} %, but what is left cannot be told from zero on the "
                      f"held-out flights ({left}): the data cannot show more to explain."]
    if v["ambiguous"]:
        lines += ["", f"Ambiguous: {', '.join(v['ambiguous'])} improve the held-out score within "
                      f"{priv.tie_tolerance:.0%} of {v['effect']}. Do not trust the name alone."]
    return lines


def _scores_section(report: GapReport) -> list[str]:
    """How the scores, the gap and the shrink are computed, with each sensor's censoring limits."""
    priv = report.details
    return ["", f"Scores: `{report['score']}`. Per reading, the threshold-weighted CRPS (readings at a range limit "
                "are censored, so how a tool records a lost echo cannot make a gap; limits: "
                + "; ".join(f"{k} [{_fmt(c['lo'], 2)}, {_fmt(c['hi'], 2)}] m"
                            + (f", no-echo value(s) {c['no_echo']}" if c["no_echo"] else "")
                            for k, c in priv.censoring.items())
                + ") divided by the sensor's base mean absolute error. The gap is the calibration gap "
                "CRPS − E_F[CRPS] (0 on average when reality could have come from the simulator). An effect's shrink "
                "is the smaller of 1 − |gap after| / gap before and its share of the best held-out score improvement "
                "any predictive achieved, so a wider predictive distribution cannot pass for an explanation.", ""]


def _where_section(report: GapReport, figs: dict, max_locations: int) -> list[str]:
    """## Where: the figure, sensors no location can decide, the locations table, what is left in physical units,
    and features along which the gap does not change."""
    priv = report.details
    lines = ["## Where", ""]
    if "gap" in figs:
        lines += [f"![gap by condition]({figs['gap']})", ""]
    located = {loc["sensor"] for loc in report["locations"]}
    for s in priv.sensors:
        if s not in located:
            lines += [f"**{s}: too little data to decide where the gap lies**: no bin of any feature holds the "
                      f"{MIN_BIN_READINGS} readings a location needs.", ""]
    sig = {i for i, loc in enumerate(report["locations"]) if loc.get("significant")}
    res = priv.residuals if len(priv.residuals) == len(report["locations"]) else [math.nan] * len(report["locations"])
    lines.append("| sensor | channel | feature | bin | gap | 95 % CI | n | significant | reads (median − model) |")
    lines.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for i, loc in enumerate(report["locations"][:max_locations]):
        lines.append(f"| {loc['sensor']} | {loc['channel']} | {loc['feature']} | {bin_text(loc)} | {_fmt(loc['gap'])} | "
                     f"{_fmt(loc['ci'][0])} … {_fmt(loc['ci'][1])} | {loc['n']} | {'yes' if i in sig else ''} | "
                     f"{_signed(res[i], loc['sensor'])} |")
    lines += ["", *residual_sentences(report["locations"], res)]
    for (s, c), feats in uniform_features(report["locations"]).items():
        lines += ["", f"Uniform across bins: the {s}{'' if c == 'all' else '/' + c} gap is the same in every bin of "
                      f"{', '.join(feats)} (every bin's 95 % CI overlaps the others)."]
    return lines


def _which_section(report: GapReport, figs: dict) -> list[str]:
    """## Which: the figure and the table of every candidate effect's fit."""
    priv = report.details
    lines = ["", "## Which", ""]
    if "effects" in figs:
        lines += [f"![effects]({figs['effects']})", ""]
    lines.append("| effect | fitted parameters | held-out score | gap after (train) | gap after (held-out) | shrink |")
    lines.append("| --- | --- | --- | --- | --- | --- |")
    for e in report["effects"]:
        params = ", ".join(f"{k}={_fmt(x, 3)}" + (" (at bound: widen or suspect another effect)"
                                                   if k in priv.at_bound.get(e["name"], ()) else "")
                           for k, x in e["params"].items())
        params += "".join(f"; {k}: {_fmt(x, 3)} stated, excess {_fmt(e['excess'][k], 3)}"
                          for k, x in e.get("stated", {}).items())
        lines.append(f"| {e['name']} | {params} | {_fmt(e['score_heldout'], 4)} | {_fmt(e['gap_after_train'])} | "
                     f"{_fmt(e['gap_after_heldout'])} | {_fmt(e['shrink_heldout'], 2)} |")
    return lines


def _how_far_section(report: GapReport, figs: dict) -> list[str]:
    """## How far (with the waterfall figure): the gap left after each selection step, and the effects tried beside
    the selected ones."""
    lines = ["", "## How far", "", f"![waterfall]({figs['waterfall']})", ""] if "waterfall" in figs else []
    for w in report.details.waterfall:
        lines.append(f"- {w['step']}: held-out gap {_fmt(w['gap_heldout'])} (its calibration part "
                     f"{_fmt(w.get('calibration_gap'))})")
    for t in report["verdict"].get("tried", ()):
        if t.get("refit"):  # a structured effect refitted as another model (gap/attribute/hinge.py)
            lines.append(f"- tried {t['effect']} as {t['refit']} beside {t['beside']}: held-out improvement "
                         f"{_fmt(t['improvement'], 4)}, p = {t['p']:.3g} (needs < {t['threshold']:.3g}): "
                         f"{'kept' if t['kept'] else 'not kept'}")
            continue
        lines.append(f"- tried {t['effect']} beside {t['beside']}: held-out improvement {_fmt(t['improvement'], 4)} "
                     f"(needs {_fmt(t['bar'], 4)}), p = {t['p']:.3g} (needs < {t['threshold']:.3g}): "
                     f"{'kept' if t['kept'] else 'dropped'}"
                     f"{' (without it the gap is unexplained)' if t.get('needed_to_explain') else ''}")
    return lines


def _closing_section(report: GapReport, figs: dict) -> list[str]:
    """The data-driven correction's figure, and the time the diagnosis took."""
    priv = report.details
    lines = ["", "## Data-driven correction", "", f"![correction]({figs['correction']})"] if "correction" in figs else []
    return lines + ["", f"_Computed in {priv.seconds:.0f} s; bootstrap blocks of {priv.block_seconds:.1f} s._"]
