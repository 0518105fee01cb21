"""Write a gap report: ``report.json`` (``docs/formats/gap-report.md``, to the letter), ``report.md`` and figures.

The JSON has exactly the spec's keys; values that are not finite (an undefined CI) become
``null``. The Markdown report adds what people need to read it: the verdict in words, the
confidence of the gap, near ties between effects, and the figures.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...atomic import write_text_atomic
from ...viz.png import save_png
from ..detect.locations import MIN_BIN_READINGS
from .result import SPEC_KEYS, GapReport

__all__ = ["SPEC_KEYS", "spec_report", "write_report", "markdown", "write_figures"]

def spec_report(report: GapReport) -> dict:
    """The report reduced to the spec's keys, JSON-safe (same as ``report.to_spec()``)."""
    return report.to_spec()


def write_report(report: GapReport, out: str | Path, max_locations_md: int = 15) -> dict[str, Path]:
    """Write report.json, report.md and the figures into ``out``; returns the written paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "report.json", "md": out / "report.md"}
    write_text_atomic(paths["json"], report.to_json())
    figs = write_figures(report, out)
    paths.update(figs)
    write_text_atomic(paths["md"], markdown(report, {k: v.name for k, v in figs.items()}, max_locations_md))
    return paths


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
    """The report for people (Markdown): verdict in words, locations, effects, waterfall; figs: name → file."""
    priv = report.details
    v = report["verdict"]
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
    lines.append("## Verdict")
    lines.append("")
    cal, cal_ci = priv.calibration_gap, priv.calibration_ci
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
        lines.append(f"**No significant gap.** The held-out readings are consistent with the simulator: mean "
                     f"calibration gap {_fmt(cal)} (95 % CI {_fmt(cal_ci[0])} … {_fmt(cal_ci[1])})"
                     + (" — as far as these few readings can tell." if priv.too_little_data else "."))
    elif v["unexplained"]:
        gs = priv.gap_sensors
        head = ("Significant gap; too little data to decide what explains it" if gs and all(
            s in priv.too_little_data for s in gs) else "Significant gap, unexplained")
        lines.append(f"**{head}.** Held-out gap {_fmt(report['gap_before'])} on {', '.join(gs)} "
                     f"(per sensor above); no catalogued effect "
                     f"explains at least {100 * priv.unexplained_shrink:.0f} % of it (best single effect: "
                     f"{report['effects'][0]['name'] if report['effects'] else 'none'}; selected effects together: "
                     f"shrink {_fmt(v['shrink_heldout'], 2)}). Where it lies is listed below.")
        c = report.correction
        if c is not None:
            lines += ["", f"A data-driven correction of {c['sensor']} ({c['method']}) removes "
                          f"{100 * c['shrink_heldout']:.0f} % of the held-out gap: reality departs from the "
                          "simulator in a way the catalogue does not describe (see its partial dependence below)."]
        for s, why in priv.correction_skipped.items():
            lines += ["", f"No data-driven correction{'' if s == 'all' else ' of ' + s}: {why}."]
    if v["significant_gap"] and not v["unexplained"]:
        e = next(e for e in report["effects"] if e["name"] == v["effect"])
        params = ", ".join(f"{k} = {_fmt(x, 4)}" for k, x in e["params"].items())
        lines.append(f"**{v['effect']}** explains the gap: fitted on the training flights ({params}), it removes "
                     f"{100 * e['shrink_heldout']:.0f} % of the held-out gap (from {_fmt(report['gap_before'])} "
                     f"to {_fmt(e['gap_after_heldout'])}).")
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
    lines.append("")
    lines.append(f"Scores: `{report['score']}`. Per reading, the threshold-weighted CRPS (readings at a range limit "
                 "are censored, so how a tool records a lost echo cannot make a gap; limits: "
                 + "; ".join(f"{k} [{_fmt(c['lo'], 2)}, {_fmt(c['hi'], 2)}] m"
                             + (f", no-echo value(s) {c['no_echo']}" if c["no_echo"] else "")
                             for k, c in priv.censoring.items())
                 + ") divided by the sensor's base mean absolute error. The gap is the calibration gap "
                 "CRPS − E_F[CRPS] (0 on average when reality could have come from the simulator). An effect's shrink "
                 "is the smaller of 1 − |gap after| / gap before and its share of the best held-out score improvement "
                 "any predictive achieved, so a wider predictive distribution cannot pass for an explanation.")
    lines.append("")
    lines += ["## Where", ""]
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
    lines += ["", "## Which", ""]
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
    if "waterfall" in figs:
        lines += ["", "## How far", "", f"![waterfall]({figs['waterfall']})", ""]
    for w in priv.waterfall:
        lines.append(f"- {w['step']}: held-out gap {_fmt(w['gap_heldout'])} (its calibration part "
                     f"{_fmt(w.get('calibration_gap'))})")
    for t in report["verdict"].get("tried", ()):
        lines.append(f"- tried {t['effect']} beside {t['beside']}: held-out improvement {_fmt(t['improvement'], 4)} "
                     f"(needs {_fmt(t['bar'], 4)}), p = {t['p']:.3g} (needs < {t['threshold']:.3g}): "
                     f"{'kept' if t['kept'] else 'dropped'}"
                     f"{' (without it the gap is unexplained)' if t.get('needed_to_explain') else ''}")
    if "correction" in figs:
        lines += ["", "## Data-driven correction", "", f"![correction]({figs['correction']})"]
    lines.append("")
    lines.append(f"_Computed in {priv.seconds:.0f} s; bootstrap blocks of "
                 f"{priv.block_seconds:.1f} s._")
    return "\n".join(lines) + "\n"


def write_figures(report: GapReport, out: Path) -> dict[str, Path]:
    """gap_by_condition.png, effects.png, waterfall.png and, with a correction, correction.png (Agg-safe)."""
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        try:
            matplotlib.use("Agg")
        except Exception:  # noqa: BLE001 (pragma: no cover; a headless backend is best effort)
            pass
    import matplotlib.pyplot as plt

    paths = {}
    priv = report.details
    sig = set(priv.significant_locations)
    locs = report["locations"][:15]
    if locs:
        g = np.array([loc["gap"] for loc in locs], float)
        lo = np.array([loc["ci"][0] if loc["ci"][0] is not None else np.nan for loc in locs], float)
        hi = np.array([loc["ci"][1] if loc["ci"][1] is not None else np.nan for loc in locs], float)
        labels = [f"{loc['sensor']}/{loc['channel']} "
                  + (bin_text(loc) if loc["feature"] in CATEGORIES else f"{loc['feature']} {bin_text(loc)}")
                  for loc in locs]
        colors = ["C3" if i in sig else "0.6" for i in range(len(locs))]
        paths["gap"] = _barh(out / "gap_by_condition.png", labels, g, colors,
                             "normalised gap per reading (95 % CI); red = significant after FDR control",
                             "Where the simulator disagrees with the logs", width=8, fontsize=8,
                             xerr=[np.nan_to_num(g - lo), np.nan_to_num(hi - g)])
    effs = report["effects"]
    if effs:
        paths["effects"] = _barh(out / "effects.png", [e["name"] for e in effs],
                                 [e["shrink_heldout"] if e["shrink_heldout"] is not None else 0.0 for e in effs],
                                 ["C2" if e["name"] == report["verdict"]["effect"] else "C0" for e in effs],
                                 "held-out shrink when the effect is added and fitted (1 = gap removed)",
                                 "Candidate effects, best held-out score first", width=7, fontsize=9)
    wf = priv.waterfall
    if wf:
        fig, ax = plt.subplots(figsize=(6, 3.5))
        vals = [w["gap_heldout"] for w in wf]
        ax.bar(range(len(wf)), vals, color=["0.5"] + ["C2"] * (len(wf) - 1), label="held-out gap left")
        # the interval belongs to the calibration gap (the significance test's quantity), not to the bar: a bar
        # outside its own "interval" made matplotlib refuse negative error lengths
        calib = [(i, w) for i, w in enumerate(wf) if w.get("ci") and w["ci"][0] is not None
                 and np.isfinite(w["ci"][0]) and w.get("calibration_gap") is not None]
        if calib:
            ax.errorbar([i for i, _ in calib], [w["calibration_gap"] for _, w in calib],
                        yerr=[[max(0.0, w["calibration_gap"] - w["ci"][0]) for _, w in calib],
                              [max(0.0, w["ci"][1] - w["calibration_gap"]) for _, w in calib]],
                        fmt="o", color="k", ms=3, lw=1, label="calibration gap, 95 % CI")
            ax.legend(fontsize=7)
        ax.set_xticks(range(len(wf)))
        ax.set_xticklabels([w["step"] for w in wf], rotation=20, ha="right", fontsize=9)
        ax.axhline(0, color="k", lw=0.8)
        ax.set_ylabel("held-out gap left")
        ax.set_title("How far the gap shrinks")
        fig.tight_layout()
        paths["waterfall"] = out / "waterfall.png"
        save_png(fig, paths["waterfall"], dpi=110, colors=None)
        plt.close(fig)
    corr = priv.correction
    if report.correction is not None and corr is not None and corr.partial_dependence.get(corr.sensor):
        pd = corr.partial_dependence[corr.sensor]
        fig, axes = plt.subplots(1, len(pd), figsize=(4 * len(pd), 3.2), squeeze=False)
        for ax, (feat, (grid, avg)) in zip(axes[0], pd.items()):
            ax.plot(grid, avg, "C3-")
            ax.axhline(0, color="k", lw=0.8)
            ax.set_xlabel(feat)
            ax.set_ylabel(f"median correction of {corr.sensor}")
        fig.suptitle("Data-driven correction: partial dependence on the located features", fontsize=10)
        fig.tight_layout()
        paths["correction"] = out / "correction.png"
        fig.savefig(paths["correction"], dpi=110)
        plt.close(fig)
    return paths


def _barh(path: Path, labels, values, colors, xlabel: str, title: str, width: float, fontsize: int, xerr=None) -> Path:
    """A horizontal bar chart, first label on top, saved to ``path``."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(width, 0.35 * len(labels) + 1.2))
    y = np.arange(len(labels))[::-1]
    ax.barh(y, values, color=colors)
    if xerr is not None:
        ax.errorbar(values, y, xerr=xerr, fmt="none", ecolor="k", lw=1)
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=fontsize)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    fig.tight_layout()
    save_png(fig, path, dpi=110, colors=None)
    plt.close(fig)
    return path
