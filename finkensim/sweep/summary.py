"""Statistics and the plot of a sweep's results: per combination, mean and confidence interval of every
metric over its successful replicates (a Student-t interval cut to the range the metric can take)."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..metrics import METRICS
from .keys import format_value
from .tables import RESULT_COLUMNS


def summarize(results, parameters: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
              confidence: float = 0.95):
    """Per combination: n_runs, n_ok, n_error and ``<metric>_mean``, ``_ci_low``, ``_ci_high``.

    The interval is the Student-t confidence interval of the mean over successful runs with a
    finite value, mean ± t_{(1+confidence)/2, n−1} · s / √n (NaN when n < 2), intersected with the
    range the metric can take (:class:`~finkensim.metrics.MetricInfo` ``low``, ``high``: fractions in
    [0, 1], counts and distances >= 0, groups >= 1). The true mean lies in that range, so cutting the
    interval there never removes it: the coverage stays that of the t interval, and a fraction's
    interval no longer reaches below 0 or above 1.
    """
    import pandas as pd
    from scipy.special import stdtrit  # Student-t quantile (scipy.stats takes a second to import)

    metrics = [m for m in (metrics or METRICS) if m in results.columns]
    if parameters is None:
        fixed = {*RESULT_COLUMNS, *METRICS}
        parameters = [c for c in results.columns if c not in fixed]
    rows = []
    for k, g in results.groupby("combination", sort=True):
        ok = g[g["status"] == "ok"]
        row = {"combination": int(k), **{p: g[p].iloc[0] for p in parameters},
               "n_runs": len(g), "n_ok": len(ok), "n_error": len(g) - len(ok)}
        for m in metrics:
            v = ok[m].to_numpy(dtype=float)
            v = v[np.isfinite(v)]
            mean = float(v.mean()) if v.size else math.nan
            if v.size >= 2:
                half = float(stdtrit(v.size - 1, 0.5 + confidence / 2) * v.std(ddof=1) / math.sqrt(v.size))
            else:
                half = math.nan
            info = METRICS[m]
            row.update({f"{m}_mean": mean, f"{m}_ci_low": max(mean - half, info.low),
                        f"{m}_ci_high": min(mean + half, info.high)})
        rows.append(row)
    return pd.DataFrame(rows)


def factorial_layout(summary, parameters: Sequence[str]):
    """(groups, series) for a full-factorial summary of >= 2 parameters: the last parameter as coloured
    series, the others as x groups (file order), each (group, series) pair exactly one row; else None."""
    if len(parameters) < 2 or len(summary) > 60:
        return None
    *outer, last = parameters
    keys = [tuple(summary[p].iloc[i] for p in outer) for i in range(len(summary))]
    series = list(dict.fromkeys(summary[last].tolist()))
    groups = list(dict.fromkeys(keys))
    pairs = set(zip(keys, summary[last].tolist()))
    if len(series) < 2 or len(pairs) != len(summary) or len(groups) * len(series) != len(summary):
        return None
    return groups, series


def plot_summary(summary, parameters: Sequence[str], metrics: Sequence[str]):
    """A matplotlib Figure: one panel per metric, mean ± CI (error bars) for each combination.

    A full-factorial design of two or more parameters is drawn grouped: the last parameter as
    coloured, side-by-side markers (legend), the other parameters' combinations along x.
    """
    from matplotlib.figure import Figure

    n = len(metrics)
    ncols = min(3, n)
    nrows = math.ceil(n / ncols)
    K = len(summary)
    layout = factorial_layout(summary, parameters)
    n_x = len(layout[0]) if layout else K
    width = max(4.5 * ncols, min(24.0, (0.3 * n_x + 1.5 + (0.6 if layout else 0.0)) * ncols))
    fig = Figure(figsize=(width, 3.4 * nrows + (1.2 if K > 1 else 0.4)), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    if layout:
        groups, series = layout
        *outer, last = parameters
        x_of = np.array([groups.index(tuple(summary[p].iloc[i] for p in outer)) for i in range(K)], dtype=float)
        s_of = np.array([series.index(v) for v in summary[last]])
        span = min(0.7, 0.18 * len(series))
        x_of = x_of + (s_of - (len(series) - 1) / 2) * (span / max(1, len(series) - 1))
        x = np.arange(len(groups))
        labels = [", ".join(format_value(v) for v in g) for g in groups]
        xlabel = ", ".join(outer)
    else:
        x = x_of = np.arange(K)
        s_of = np.zeros(K, dtype=int)
        series = [None]
        if len(parameters) == 1:
            labels = [format_value(v) for v in summary[parameters[0]]]
            xlabel = parameters[0]
        elif parameters:
            labels = [", ".join(format_value(summary[p].iloc[i]) for p in parameters) for i in range(K)]
            xlabel = ", ".join(parameters)
        else:
            labels, xlabel = ["base"], ""
    for i, m in enumerate(metrics):
        ax = axes[i // ncols][i % ncols]
        mean = summary[f"{m}_mean"].to_numpy(dtype=float)
        lo = mean - summary[f"{m}_ci_low"].to_numpy(dtype=float)
        hi = summary[f"{m}_ci_high"].to_numpy(dtype=float) - mean
        for j, value in enumerate(series):
            sel = s_of == j
            label = format_value(value) if value is not None else None
            ax.errorbar(x_of[sel], mean[sel], yerr=np.vstack([np.nan_to_num(lo[sel]), np.nan_to_num(hi[sel])]),
                        fmt="o", capsize=3, ms=4, label=label)
        info = METRICS.get(m)
        ax.set_title(m)
        ax.set_ylabel(info.unit if info else "")
        ax.grid(alpha=0.3)
        if len(x) <= 40:
            slanted = len(x) > 4 or len(parameters) > (2 if layout else 1)
            ax.set_xticks(x, labels, rotation=45 if slanted else 0, ha="right" if slanted else "center",
                          fontsize=7 if len(x) > 12 else 8)
        else:
            ax.set_xlabel("combination")
        if xlabel and len(x) <= 40:
            ax.set_xlabel(xlabel, fontsize=8)
        if layout and i == 0:
            ax.legend(fontsize=7, title=parameters[-1], title_fontsize=7, loc="best")
    for j in range(n, nrows * ncols):
        axes[j // ncols][j % ncols].set_visible(False)
    fig.suptitle("sweep summary: mean ± 95 % CI per combination (Student t, cut to each metric's range)", fontsize=10)
    return fig
