"""Whether the held-out readings can decide anything: no absurd gap, no confident verdict from too few readings
(what a gap report must not claim; a fitted value at a bound is flagged by :mod:`finkensim.gap.quantify.bounds`).

- :func:`check_plausible`: every sensor's held-out gap is a finite number of plausible size (in units of the
  configured model's own mean absolute error) or the diagnosis stops with a named error: scored readings that the
  model cannot describe at all (units, limits, readings nobody expected) once printed a gap of 5.7·10⁷.
- :func:`sample_sizes`: per sensor, the held-out readings and the bootstrap blocks that hold them; where they are
  fewer than :data:`MIN_HELDOUT_READINGS` / :data:`MIN_BLOCKS`, the report says "too little data to decide" what
  it cannot decide (whether there is a gap, which effect explains it) instead of a confident verdict.
"""
from __future__ import annotations

import math

import numpy as np

from ..model.replay import GapInputError

__all__ = ["MAX_PLAUSIBLE_GAP", "MIN_HELDOUT_READINGS", "MIN_BLOCKS", "check_plausible", "sample_sizes",
           "too_little_data"]

#: a held-out gap beyond this many times the configured model's mean absolute error is not a measurement
MAX_PLAUSIBLE_GAP = 100.0
#: below this many held-out readings of a sensor, its held-out comparison cannot decide an effect or a gap
MIN_HELDOUT_READINGS = 100
#: below this many bootstrap blocks holding held-out readings, the block bootstrap's interval is not trusted
MIN_BLOCKS = 20


def check_plausible(per_sensor: dict) -> None:
    """Raise a :class:`~finkensim.gap.model.inputs.GapInputError` naming the sensor when its held-out gap (``per_sensor[s]["gap"]``,
    normalised) is not finite or exceeds :data:`MAX_PLAUSIBLE_GAP` in magnitude."""
    for s, v in per_sensor.items():
        g = float(v["gap"])
        if not (math.isfinite(g) and abs(g) <= MAX_PLAUSIBLE_GAP):
            raise GapInputError(
                f"{s}: the held-out gap came out as {g:.3g}, not a finite number of plausible size (|gap| <= "
                f"{MAX_PLAUSIBLE_GAP:g} times the configured model's mean absolute error): the readings cannot be "
                "compared with the model; check their units, the range limits (--limits from-log) and which "
                "readings were expected (NaN = no reading)")


def sample_sizes(diag, rows_ho: dict) -> dict:
    """sensor -> {"heldout": held-out readings with a value, "train": training readings with a value, "blocks":
    bootstrap blocks holding held-out readings}."""
    out = {}
    for s, rows in rows_ho.items():
        tab = diag.tables[s]
        ok = np.isfinite(tab.y[rows])
        fit = diag.rows_fit[s]
        out[s] = {"heldout": int(ok.sum()), "train": int(np.isfinite(tab.y[fit]).sum()),
                  "blocks": int(np.unique(diag.block_ids(s, rows[ok])).size)}
    return out


def too_little_data(sizes: dict, significant: dict) -> dict:
    """sensor -> the sentence "too little data to decide ..." for each sensor whose held-out readings or blocks are
    too few; ``significant`` (sensor -> bool) says whether a gap was found there (then what cannot be decided is
    which effect explains it, else whether there is a gap)."""
    out = {}
    for s, n in sizes.items():
        if n["heldout"] >= MIN_HELDOUT_READINGS and n["blocks"] >= MIN_BLOCKS:
            continue
        what = (f"which effect explains the {s} gap and how much of it" if significant.get(s)
                else f"whether {s} has a gap")
        out[s] = (f"too little data to decide {what}: {n['heldout']} held-out readings in {n['blocks']} bootstrap "
                  f"blocks ({n['train']} for training); a decision needs at least {MIN_HELDOUT_READINGS} readings in "
                  f"{MIN_BLOCKS} blocks")
    return out
