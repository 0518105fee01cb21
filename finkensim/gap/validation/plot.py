"""The pairs matrix of ``finkensim gap-validate`` as a picture: one cell per pair of withheld effects."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .tables import pair_count, pair_tally

__all__ = ["pair_grid_figure"]


def pair_grid_figure(rows: list[dict], path: str | Path, target: float = 0.9) -> Path | None:
    """Draw the pair trials of ``rows`` (result rows of gap-validate) as an effect × effect grid to ``path`` (PNG):
    each cell coloured by the share of trials in which both effects were named and labelled k/n, cells below
    ``target`` outlined. None when ``rows`` hold no pair trial."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from ...viz.png import save_png

    effects, tally = pair_tally(rows)
    if not tally:
        return None
    m = len(effects)
    share = np.full((m - 1, m - 1), np.nan)
    fig, ax = plt.subplots(figsize=(1.0 + 0.62 * m, 0.9 + 0.5 * m))
    for i, a in enumerate(effects[:-1]):
        for j, b in enumerate(effects[1:], start=1):
            if j <= i:
                continue
            k, n = pair_count(tally, a, b)
            if not n:
                ax.text(j - 1, i, "—", ha="center", va="center", color="0.5", fontsize=8)
                continue
            share[i, j - 1] = k / n
            ax.text(j - 1, i, f"{k}/{n}", ha="center", va="center", fontsize=7)
            if k / n < target:
                ax.add_patch(plt.Rectangle((j - 1.5, i - 0.5), 1, 1, fill=False, edgecolor="k", lw=1.5))
    im = ax.imshow(np.ma.masked_invalid(share), cmap="RdYlGn", vmin=0.5, vmax=1.0)
    ax.set_xticks(range(m - 1), effects[1:], rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(m - 1), effects[:-1], fontsize=8)
    n_trials = sum(n for _, n in tally.values())
    met = sum(k / n >= target for k, n in tally.values())
    ax.set_title(f"Both withheld effects named: {met} of {len(tally)} pairs at ≥ {target:.0%} ({n_trials} trials)",
                 fontsize=9)
    fig.colorbar(im, ax=ax, shrink=0.7, label="share of trials, both named")
    fig.tight_layout()
    out = save_png(fig, path)
    plt.close(fig)
    return out
