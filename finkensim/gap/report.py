"""Write a gap report: ``report.json`` (``spec/gap-report.md``, to the letter), ``report.md`` and figures.

The JSON has exactly the spec's keys; values that are not finite (an undefined CI) become
``null``. The Markdown report adds what people need to read it: the verdict in words, the
confidence of the gap, near ties between effects, and the figures.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..atomic import write_text_atomic
from ..viz.png import save_png
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
                 f"({', '.join(f'{k}: {n} readings' for k, n in priv.n_readings.items())})")
    lines.append("")
    ci = priv.gap_before_ci
    lines.append("## Verdict")
    lines.append("")
    if not v["significant_gap"]:
        lines.append(f"**No significant gap.** The held-out readings are consistent with the simulator: mean gap "
                     f"{_fmt(report['gap_before'])} (95 % CI {_fmt(ci[0])} … {_fmt(ci[1])}).")
    elif v["unexplained"]:
        lines.append(f"**Significant gap, unexplained.** Mean held-out gap {_fmt(report['gap_before'])} (95 % CI "
                     f"{_fmt(ci[0])} … {_fmt(ci[1])}); no catalogued effect removes at least {100 * priv.unexplained_shrink:.0f} % of it (best single "
                     f"effect: {report['effects'][0]['name'] if report['effects'] else 'none'}, held-out shrink "
                     f"{_fmt(v['shrink_heldout'], 2)}). Where it lies is listed below.")
    else:
        e = next(e for e in report["effects"] if e["name"] == v["effect"])
        params = ", ".join(f"{k} = {_fmt(x, 4)}" for k, x in e["params"].items())
        lines.append(f"**{v['effect']}** explains the gap: fitted on the training flights ({params}), it shrinks the "
                     f"held-out gap by {100 * v['shrink_heldout']:.0f} % (from {_fmt(report['gap_before'])} to "
                     f"{_fmt(e['gap_after_heldout'])}).")
        if priv.ties:
            lines.append("")
            lines.append(f"Near ties (held-out improvement within {priv.tie_tolerance:.0%} of the best): "
                         f"{', '.join(priv.ties)}. Treat the choice between them as ambiguous.")
        if len(priv.added) > 1:
            lines.append("")
            lines.append(f"Forward selection added: {', '.join(priv.added)} (total held-out shrink "
                         f"{100 * priv.total_shrink:.0f} %).")
    lines.append("")
    lines.append(f"Score: `{report['score']}`: per reading, CRPS minus its expectation under the model, divided by "
                 "the sensor's base mean absolute error; 0 when reality could have come from the simulator.")
    lines.append("")
    if "gap" in figs:
        lines += ["## Where", "", f"![gap by condition]({figs['gap']})", ""]
    sig = set(priv.significant_locations)
    lines.append("| sensor | channel | feature | bin | gap | 95 % CI | n | significant |")
    lines.append("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for i, loc in enumerate(report["locations"][:max_locations]):
        lines.append(f"| {loc['sensor']} | {loc['channel']} | {loc['feature']} | [{_fmt(loc['low'], 2)}, "
                     f"{_fmt(loc['high'], 2)}) | {_fmt(loc['gap'])} | {_fmt(loc['ci'][0])} … {_fmt(loc['ci'][1])} | "
                     f"{loc['n']} | {'yes' if i in sig else ''} |")
    lines += ["", "## Which", ""]
    if "effects" in figs:
        lines += [f"![effects]({figs['effects']})", ""]
    lines.append("| effect | fitted parameters | held-out score | gap after (train) | gap after (held-out) | shrink |")
    lines.append("| --- | --- | --- | --- | --- | --- |")
    for e in report["effects"]:
        params = ", ".join(f"{k}={_fmt(x, 3)}" for k, x in e["params"].items())
        lines.append(f"| {e['name']} | {params} | {_fmt(e['score_heldout'], 4)} | {_fmt(e['gap_after_train'])} | "
                     f"{_fmt(e['gap_after_heldout'])} | {_fmt(e['shrink_heldout'], 2)} |")
    if "waterfall" in figs:
        lines += ["", "## How far", "", f"![waterfall]({figs['waterfall']})", ""]
    for w in priv.waterfall:
        lines.append(f"- {w['step']}: held-out gap {_fmt(w['gap_heldout'])}")
    lines.append("")
    lines.append(f"_Computed in {priv.seconds:.0f} s; bootstrap blocks of "
                 f"{priv.block_seconds:.1f} s._")
    return "\n".join(lines) + "\n"


def write_figures(report: GapReport, out: Path) -> dict[str, Path]:
    """gap_by_condition.png, effects.png, waterfall.png (matplotlib, Agg-safe)."""
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        try:
            matplotlib.use("Agg")
        except Exception:  # pragma: no cover
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
        labels = [f"{loc['sensor']}/{loc['channel']} {loc['feature']} [{loc['low']:.2g}, {loc['high']:.2g})"
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
                                 "held-out gap shrink when the effect is added and fitted (1 = gap removed)",
                                 "Candidate effects, best held-out score first", width=7, fontsize=9)
    wf = priv.waterfall
    if wf:
        fig, ax = plt.subplots(figsize=(6, 3.5))
        vals = [w["gap_heldout"] for w in wf]
        ax.bar(range(len(wf)), vals, color=["0.5"] + ["C2"] * (len(wf) - 1))
        for i, w in enumerate(wf):
            if w.get("ci") and w["ci"][0] is not None and np.isfinite(w["ci"][0]):
                ax.errorbar(i, w["gap_heldout"], yerr=[[w["gap_heldout"] - w["ci"][0]], [w["ci"][1] - w["gap_heldout"]]],
                            color="k", lw=1)
        ax.set_xticks(range(len(wf)))
        ax.set_xticklabels([w["step"] for w in wf], rotation=20, ha="right", fontsize=9)
        ax.axhline(0, color="k", lw=0.8)
        ax.set_ylabel("held-out gap")
        ax.set_title("How far the gap shrinks")
        fig.tight_layout()
        paths["waterfall"] = out / "waterfall.png"
        save_png(fig, paths["waterfall"], dpi=110, colors=None)
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
