"""Write a gap report: ``report.json`` (``docs/formats/gap-report.md``, to the letter), ``report.md`` and figures.

The JSON has exactly the spec's keys; values that are not finite (an undefined CI) become
``null``. The Markdown report (:mod:`~finkensim.gap.report.markdown`) adds what people need to read it: the verdict
in words, the confidence of the gap, near ties between effects, and the figures.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ...atomic import write_text_atomic
from ...viz.png import save_png
from .markdown import CATEGORIES, bin_text, markdown
from .result import SPEC_KEYS, GapReport

__all__ = ["SPEC_KEYS", "spec_report", "write_report", "write_figures"]


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
