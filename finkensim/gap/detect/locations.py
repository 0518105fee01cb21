"""Where the gap lies: per sensor, channel and context feature, quantile bins of the readings with block-bootstrap
intervals, ranked by gap, Benjamini–Hochberg across all bins."""
from __future__ import annotations

import math

import numpy as np

from .stats import BlockBootstrap, fdr_significant

__all__ = ["MIN_BIN_READINGS", "DISCRETE_FEATURES", "locate_gap"]

#: a location (one bin of one feature) needs at least this many readings
MIN_BIN_READINGS = 30
DISCRETE_FEATURES = {"hit_type", "neighbor_in_beam", "axis"}


def locate_gap(diag, p):
    """Gap per (sensor, channel, feature, bin) on all flights under p, sorted by gap; each bin also carries
    ``_residual``, the median of reading − model median in the sensor's own unit (m for the range sensors).

    Parameters
    ----------
    diag : Diagnosis
        The prepared diagnosis (:class:`~finkensim.gap.diagnosis.Diagnosis`).
    p : ModelParams
        The model scored.

    Returns
    -------
    list of dict
        One per bin: sensor, channel, feature, low, high, gap, ci, n, and the private ``_p``, ``_significant``,
        ``_residual``.
    """
    cfg = diag.cfg.gap
    res, rows = diag.evaluate(p, "all")
    locs = []
    for s, (_, gap) in res.items():
        tab = diag.tables[s]
        r = rows[s]
        D, y, _ = diag.censored_draws(s, p, r)
        resid = y - np.median(D, axis=1)
        bb = BlockBootstrap(diag.block_ids(s, r), n_boot=cfg.n_boot, seed=diag.seed)
        chans = [("all", np.ones(r.size, bool))]
        if s == "ultrasonic" and len(tab.channel_names) > 1:
            chans += [(nm, tab.channel[r] == k) for k, nm in enumerate(tab.channel_names)]
        for cname, cmask in chans:
            for feat, fv in tab.features.items():
                v = fv[r]
                ok = np.isfinite(v) & cmask
                if ok.sum() < MIN_BIN_READINGS:
                    continue
                for lo, hi in _bins(v[ok], feat, cfg.n_bins):
                    m = ok & (v >= lo) & (v < hi)
                    if m.sum() < MIN_BIN_READINGS:
                        continue
                    st = bb.stats(gap, m)
                    rm = resid[m & np.isfinite(resid)]
                    locs.append({"sensor": s, "channel": cname, "feature": feat, "low": float(lo),
                                 "high": float(hi) if np.isfinite(hi) else 1e9, "gap": st.mean,
                                 "ci": [st.ci[0], st.ci[1]], "n": st.n, "_p": st.p_positive,
                                 "_residual": float(np.median(rm)) if rm.size else math.nan})
    sig = fdr_significant([loc["_p"] for loc in locs], cfg.alpha)
    for loc, sg in zip(locs, sig):
        loc["_significant"] = bool(sg) and loc["gap"] > cfg.margin
    locs.sort(key=lambda d: -d["gap"] if np.isfinite(d["gap"]) else math.inf)
    return locs


def _bins(v, feat, n_bins):
    """[low, high) bins of a feature's values: categories for discrete features, else quantiles."""
    if feat in DISCRETE_FEATURES or np.unique(v).size <= 3:
        return [(u, u + 0.5 if feat in DISCRETE_FEATURES else np.nextafter(u, np.inf)) for u in np.unique(v)]
    edges = np.unique(np.quantile(v, np.linspace(0, 1, n_bins + 1)))
    if edges.size < 2:
        return []
    out = [(edges[i], edges[i + 1]) for i in range(edges.size - 2)]
    out.append((edges[-2], np.nextafter(edges[-1], np.inf)))
    return out
