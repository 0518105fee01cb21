"""Range limits against the logs: readings beyond the configured ``max_range`` are a named error, or, when the user
asks (``limits="from-log"``, ``finkensim gap --limits from-log``), the limit is taken from the logs.

The simulator reads exactly ``max_range`` beyond its range, so a log whose readings lie beyond it cannot be compared:
scored as they are, real radio ranges of 4.7 m against a 2.5 m limit once made a gap of 5.7·10⁷ with no word about
why. Readings somewhat above the limit are the error model's own spread (a true range just inside the limit plus
a radio error: simulated flights reach 2.9 m against 2.5 m) or a sonar's no-echo value plus jitter: only a share
above :data:`MAX_SHARE` of readings beyond ``(1 + REL_TOL) · max_range + ABS_TOL`` counts.
"""
from __future__ import annotations

import math

import numpy as np

from ...flightlog.messages import fmt
from ..model.replay import GapInputError

__all__ = ["LIMIT_MODES", "range_limits", "MAX_SHARE"]

LIMIT_MODES = ("config", "from-log")
#: share of a sensor's readings beyond its limit (with the tolerances) that makes the limit wrong for the logs
MAX_SHARE = 0.05
REL_TOL, ABS_TOL = 0.2, 0.1
#: "from-log" sets max_range to the largest reading times this, rounded up to 0.1 m
FROM_LOG_FACTOR = 1.05


def _readings(sensor, log):
    if sensor == "ultrasonic":
        return None if log.ultrasonic is None else np.asarray(log.ultrasonic).ravel()
    if log.ranging is None:
        return None
    r = np.asarray(log.ranging)
    off = ~np.eye(r.shape[1], dtype=bool)
    return r[:, off].ravel()


#: sensor -> (config section, dotted key of its range limit)
SENSOR_KEYS = {"ultrasonic": ("sonar", "sonar.max_range"), "ranging": ("ranging", "ranging.max_range")}


def range_limits(cfg, logs, names, mode: str = "config"):
    """(config, notes): ``cfg`` unchanged when every sensor's readings fit its ``max_range``; with ``mode`` =
    "from-log", a config whose too-small limits are raised to the logs' largest reading (× 1.05, rounded up to
    0.1 m); notes: sensor → what was decided, in words. With ``mode`` = "config", readings beyond a limit are a
    :class:`~finkensim.gap.model.inputs.GapInputError` naming the sensor, the limit, how many readings and the largest."""
    if mode not in LIMIT_MODES:
        raise GapInputError(f"limits = {mode!r}: expected one of {', '.join(LIMIT_MODES)}")
    notes, changes = {}, {}
    for sensor, (section, key) in SENSOR_KEYS.items():
        parts = [v for v in (_readings(sensor, log) for log in logs) if v is not None]
        if not parts:
            continue
        v = np.concatenate(parts)
        v = v[np.isfinite(v)]
        if v.size == 0:
            continue
        limit = float(getattr(cfg, section).max_range)
        beyond = v > (1 + REL_TOL) * limit + ABS_TOL
        top = float(v.max())
        if beyond.mean() <= MAX_SHARE:
            continue
        if mode == "config":
            raise GapInputError(
                f"{sensor}: {100 * beyond.mean():.0f} % of the readings ({int(beyond.sum())} of {v.size}, in "
                f"{', '.join(names)}) lie beyond {key} = {fmt(limit)} m (largest {fmt(top)} m); the simulator reads "
                f"exactly max_range there, so they cannot be compared: set {key} in the config, or take the limit "
                "from the logs (finkensim gap --limits from-log)")
        new = math.ceil(FROM_LOG_FACTOR * top * 10.0) / 10.0
        changes[key] = new
        notes[sensor] = (f"{key} = {fmt(new)} m taken from the logs (largest reading {fmt(top)} m; configured "
                         f"{fmt(limit)} m, {100 * beyond.mean():.0f} % of the readings beyond it)")
    return (cfg.replace(changes) if changes else cfg), notes
