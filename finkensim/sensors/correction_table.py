"""The learned correction as a sensor model: conditional quantiles of a reading's residual on a grid.

When the effect catalogue leaves a gap, the diagnosis fits the distribution of the real reading around its model's
median (:mod:`finkensim.gap.quantify.correction`). ``finkensim gap --out DIR`` exports it as a table, ``DIR/correction.json``,
referenced from ``calibrated.toml`` (``sonar.correction_file``), which the simulator applies to each reading:

    reading = clamp(ref + Q_g(u)),   ref = range_scale · d + bias (the echo without its error),

with g the bin of ``ref`` among the table's edges, Q_g the residual's quantile function in that bin (linear between
its quantile levels, constant beyond the first and last) and u uniform, keyed per (seed, environment, step, copter,
sonar) on its own stream (``finkensim.kernels.rng.STREAM_CORRECTION``). The correction's distribution replaces
the error model's for every reading with an echo (the table was fitted on the readings the model explained
badly, noise included); readings without an echo stay ``max_range``.

The ranging readings (``ranging.correction_file``, :func:`~finkensim.sensors.ranging_radio.corrected_reading`) and
the IMU (``imu.correction_file``, :mod:`finkensim.sensors.imu_correction`) apply their tables the same way, each on
its own random stream.

**File format** (JSON, version 2; version 1 files are read as they are)::

    {"format": "finkensim-correction", "version": 2,
     "sensors": {"ultrasonic": {"feature": "model_median", "unit": "m",
                                "edges": [G + 1 increasing numbers],
                                "levels": [Q increasing numbers in (0, 1)],
                                "quantiles": [G rows of Q non-decreasing numbers]},
                 "ranging": {... one table as above ...},
                 "imu": {"window": W, "channels": {"dv_x": {...}, "dv_y": {...}, "dyaw": {...}}}},
     "source": {...free-form: the diagnosis it came from}}

Version 2 adds a sensor entry with one table per channel (:class:`ChannelTables`: the IMU's window integrals,
whose channels have different units and scales) and the optional ``unit`` of a table; a file without such an entry
is written as version 1, so older readers still read it. Every entry is checked on read, and a bad one is a
:class:`CorrectionFileError` naming the file, the key, the value and what was expected.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from ..config import ConfigError
from ..kernels.raycast import HIT_NONE
from ..kernels.rng import STREAM_CORRECTION, counter_key, uniform

__all__ = ["FORMAT", "VERSION", "READS", "ChannelTables", "CorrectionTable", "CorrectionFileError", "read_correction",
           "write_correction", "correction_quantile", "correct_readings_env", "corrected_reference", "NO_TABLE"]

FORMAT = "finkensim-correction"
VERSION = 2
#: the file versions this finkensim reads (1: one table per sensor; 2: also a table per channel)
READS = (1, 2)
#: the packed form of "no correction" (a kernel's record field when the config names no file)
NO_TABLE = np.zeros((0, 0))
NO_TABLE.setflags(write=False)


class CorrectionFileError(ConfigError):
    """A correction table file is missing, unreadable or has a bad entry (the message names it)."""


class CorrectionTable(NamedTuple):
    """One sensor's table: edges (G + 1,) of the feature ``model_median`` (in ``unit``: m for the sonars and the
    ranging), levels (Q,) in (0, 1), quantiles (G, Q) of the residual in each bin (same unit)."""

    edges: np.ndarray
    levels: np.ndarray
    quantiles: np.ndarray
    unit: str = "m"

    def packed(self) -> np.ndarray:
        """The table as one (G + 1, Q + 1) array for the kernels: column 0 the edges, row 0 from column 1 the
        levels, rows 1 … G from column 1 the quantiles."""
        G, Q = self.quantiles.shape
        out = np.zeros((G + 1, Q + 1))
        out[:, 0] = self.edges
        out[0, 1:] = self.levels
        out[1:, 1:] = self.quantiles
        return out

    def to_json(self) -> dict:
        """The table's entry of the file format."""
        return {"feature": "model_median", "unit": self.unit, "edges": self.edges.tolist(),
                "levels": self.levels.tolist(), "quantiles": self.quantiles.tolist()}


class ChannelTables(NamedTuple):
    """A sensor's tables per channel (file format version 2): ``channels`` {name: :class:`CorrectionTable`} and
    ``window`` s, the span each of its readings integrates (the IMU's window integrals; 0 = single readings)."""

    channels: dict
    window: float = 0.0

    def to_json(self) -> dict:
        """The entry of the file format."""
        return {"window": float(self.window), "channels": {k: t.to_json() for k, t in self.channels.items()}}


def _numbers(where: str, value, shape_text: str, ndim: int) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CorrectionFileError(f"{where} = {str(value)[:60]}: expected {shape_text} of numbers") from None
    if a.ndim != ndim or a.size == 0:
        raise CorrectionFileError(f"{where} has shape {a.shape}: expected {shape_text}")
    if not np.isfinite(a).all():
        raise CorrectionFileError(f"{where} holds a non-finite value: expected finite numbers")
    return a


def _entry(where: str, entry):
    """A sensor's entry: a :class:`CorrectionTable` or, with ``channels``, a :class:`ChannelTables`."""
    if not (isinstance(entry, dict) and "channels" in entry):
        return _table(where, entry)
    chans = entry["channels"]
    if not isinstance(chans, dict) or not chans:
        raise CorrectionFileError(f"{where}.channels = {str(chans)[:60]}: expected a table per channel")
    window = entry.get("window", 0.0)
    if isinstance(window, bool) or not isinstance(window, (int, float)) or not (0.0 <= window < float("inf")):
        raise CorrectionFileError(f"{where}.window = {window!r}: expected a finite number >= 0 s")
    return ChannelTables({k: _table(f"{where}.channels.{k}", t) for k, t in chans.items()}, float(window))


def _table(where: str, entry) -> CorrectionTable:
    if not isinstance(entry, dict):
        raise CorrectionFileError(f"{where} = {str(entry)[:60]}: expected a table (edges, levels, quantiles)")
    for key in ("edges", "levels", "quantiles"):
        if key not in entry:
            raise CorrectionFileError(f"{where}: the key {key!r} is missing")
    if entry.get("feature", "model_median") != "model_median":
        raise CorrectionFileError(f"{where}.feature = {entry['feature']!r}: expected 'model_median'")
    edges = _numbers(f"{where}.edges", entry["edges"], "a list of G + 1 >= 2", 1)
    levels = _numbers(f"{where}.levels", entry["levels"], "a list of Q >= 1", 1)
    q = _numbers(f"{where}.quantiles", entry["quantiles"], "G rows of Q", 2)
    if edges.size < 2 or not (np.diff(edges) > 0).all():
        raise CorrectionFileError(f"{where}.edges = {edges.tolist()[:6]}: expected at least 2 increasing numbers")
    if not ((levels > 0) & (levels < 1)).all() or not (np.diff(levels) > 0).all():
        raise CorrectionFileError(f"{where}.levels = {levels.tolist()[:6]}: expected increasing numbers in (0, 1)")
    if q.shape != (edges.size - 1, levels.size):
        raise CorrectionFileError(f"{where}.quantiles has shape {q.shape}: expected (G, Q) = "
                                  f"({edges.size - 1}, {levels.size}) for its edges and levels")
    if not (np.diff(q, axis=1) >= 0).all():
        raise CorrectionFileError(f"{where}.quantiles: a row decreases; expected non-decreasing quantiles per bin")
    unit = entry.get("unit", "m")
    if not isinstance(unit, str):
        raise CorrectionFileError(f"{where}.unit = {unit!r}: expected a string")
    return CorrectionTable(np.ascontiguousarray(edges), np.ascontiguousarray(levels), np.ascontiguousarray(q), unit)


def read_correction(path: str | Path, sensor: str | None = None, key: str = "correction file", channels=None):
    """The tables of the correction file ``path``: {sensor: :class:`CorrectionTable` or :class:`ChannelTables`}, or
    one sensor's entry when ``sensor`` is given (a :class:`CorrectionFileError` when the file has none). ``key``
    names the setting the path came from in messages. ``channels`` (names): the sensor's entry must be a
    :class:`ChannelTables` with exactly these channels (None: a single :class:`CorrectionTable`)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise CorrectionFileError(f"{key} = {str(path)!r}: no such file") from None
    except (OSError, ValueError) as exc:
        raise CorrectionFileError(f"{key} = {str(path)!r}: not a readable JSON file ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        got = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise CorrectionFileError(f"{path}: format = {got!r}: expected {FORMAT!r}")
    if data.get("version") not in READS:
        raise CorrectionFileError(f"{path}: version = {data.get('version')!r}: expected one of "
                                  f"{', '.join(map(str, READS))} (the versions this finkensim reads)")
    sensors = data.get("sensors")
    if not isinstance(sensors, dict) or not sensors:
        raise CorrectionFileError(f"{path}: sensors = {str(sensors)[:60]}: expected a table per sensor")
    if data["version"] == 1 and any(isinstance(e, dict) and "channels" in e for e in sensors.values()):
        raise CorrectionFileError(f"{path}: version = 1 with a table per channel: expected version 2")
    tables = {name: _entry(f"{path}: sensors.{name}", entry) for name, entry in sensors.items()}
    if sensor is None:
        return tables
    if sensor not in tables:
        raise CorrectionFileError(f"{key} = {str(path)!r}: the file has no {sensor!r} table (it has "
                                  f"{', '.join(sorted(tables))})")
    got = tables[sensor]
    if channels is None and isinstance(got, ChannelTables):
        raise CorrectionFileError(f"{key} = {str(path)!r}: sensors.{sensor} holds a table per channel "
                                  f"({', '.join(got.channels)}): expected one table")
    if channels is not None:
        have = f"channels {', '.join(got.channels)}" if isinstance(got, ChannelTables) else "one table"
        if not isinstance(got, ChannelTables) or sorted(got.channels) != sorted(channels):
            raise CorrectionFileError(f"{key} = {str(path)!r}: sensors.{sensor} holds {have}: expected a table for "
                                      f"each of {', '.join(channels)}")
    return got


def write_correction(path: str | Path, tables: dict, source: dict | None = None) -> Path:
    """Write {sensor: :class:`CorrectionTable` or :class:`ChannelTables`} as a correction file (atomically; version 1
    when no entry has channels, else 2); returns the path."""
    path = Path(path)
    version = VERSION if any(isinstance(t, ChannelTables) for t in tables.values()) else 1
    data = {"format": FORMAT, "version": version, "sensors": {k: t.to_json() for k, t in tables.items()},
            "source": source or {}}
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)
    return path


@njit(cache=True, inline="always")
def correction_quantile(table, ref, u):
    """The residual (m) at probability u in the bin of ``ref`` (m) of a packed table (G + 1, Q + 1)
    (:meth:`CorrectionTable.packed`): linear between the levels, the end quantiles beyond them; ``ref`` outside
    the edges takes the first or last bin."""
    G = table.shape[0] - 1
    Q = table.shape[1] - 1
    g = 0
    while g < G - 1 and ref >= table[g + 1, 0]:
        g += 1
    row = g + 1
    if u <= table[0, 1]:
        return table[row, 1]
    for j in range(1, Q):
        lo, hi = table[0, j], table[0, j + 1]
        if u <= hi:
            w = (u - lo) / (hi - lo)
            return table[row, j] + w * (table[row, j + 1] - table[row, j])
    return table[row, Q]


@njit(cache=True, inline="always", error_model="numpy")
def correct_readings_env(out, dist, kind, table, sonar, counter):
    """Replace each reading out (N, S) m that has an echo (dist (N, S) m below max_range, kind (N, S) not HIT_NONE)
    by ``clamp(range_scale·dist + bias + Q(u))`` (:func:`correction_quantile`; u keyed per (seed, env, step, copter,
    stream) and the sonar index as the block). sonar: a record with the sonar's range_scale, bias, min_range and
    max_range (m; :class:`~finkensim.sensors.sonar_model.SonarScalars`); counter = (seed, env, step) of the random
    numbers."""
    range_scale, bias, min_range, max_range = sonar.range_scale, sonar.bias, sonar.min_range, sonar.max_range
    seed, env, step = counter
    for n in range(out.shape[0]):
        key = counter_key(seed, env, step, n, STREAM_CORRECTION)
        for k in range(out.shape[1]):
            if kind[n, k] == HIT_NONE or dist[n, k] >= max_range:
                continue
            ref = range_scale * dist[n, k] + bias
            r = ref + correction_quantile(table, ref, uniform(key, k))
            out[n, k] = min(max_range, max(min_range, r))


def corrected_reference(ref: np.ndarray, u: np.ndarray, table: CorrectionTable) -> np.ndarray:
    """NumPy reference of :func:`correction_quantile`: ref + Q(u) for arrays ref, u of one shape (m)."""
    ref = np.asarray(ref, dtype=float)
    g = np.clip(np.searchsorted(table.edges, ref, side="right") - 1, 0, table.quantiles.shape[0] - 1)
    out = np.empty_like(ref)
    for i in np.ndindex(ref.shape):
        out[i] = ref[i] + np.interp(u[i], table.levels, table.quantiles[g[i]])
    return out
