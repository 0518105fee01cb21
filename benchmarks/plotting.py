"""The log-log cost-against-N figure shared by the scaling benchmarks (``scaling.png``, ``engine_scaling.png``)."""
from __future__ import annotations

from pathlib import Path


def loglog_figure(path, draw, xlabel: str, ylabel: str, title: str, dpi: int = 120) -> Path | None:
    """Draw ``draw(ax)`` on log-log axes with the given labels, a grid and a legend, save to ``path`` (PNG) and
    return it; None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    draw(ax)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
