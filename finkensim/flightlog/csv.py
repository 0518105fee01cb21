"""Import tracking data from a CSV file into a :class:`~finkensim.flightlog.format.FlightLog`.

One row per copter and sample: header ``t, copter, x, y, yaw`` (s, name, m, m, rad). See
:func:`from_csv`.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .format import DEFAULT_COPTER_RADIUS, FlightLog, FlightLogError
from .messages import fmt, plural
from .validation import validate

__all__ = ["CSV_COLUMNS", "from_csv"]

CSV_COLUMNS = ("t", "copter", "x", "y", "yaw")
"""The columns of a tracking CSV: time (s), copter name, x (m), y (m), yaw (rad)."""


def _natural_key(s: str):
    """Sort key that orders the digit runs of ``s`` by value: ``cf2`` before ``cf10``."""
    return [(0, int(tok), "") if tok.isdigit() else (1, 0, tok) for tok in re.split(r"(\d+)", s) if tok != ""]


def from_csv(path: str | os.PathLike, arena, *, copter_radius: float = DEFAULT_COPTER_RADIUS,
             meta: Mapping[str, Any] | None = None) -> FlightLog:
    """Import tracking data: a CSV with header ``t, copter, x, y, yaw`` (s, name, m, m, rad).

    Rows may come in any order. The result has one sample per distinct ``t`` value (sorted;
    times match exactly as parsed), copters in natural sort order of their names (``cf2``
    before ``cf10``), and ``meta`` = ``meta`` + ``copter_radius`` + ``source`` (``csv:<file
    name>`` unless given). Every copter must have exactly one row at every time: a missing or
    duplicated (copter, t) row is an error naming both, nothing is interpolated. Missing or
    unknown columns, empty or non-numeric cells are errors naming the column and line. The
    log is validated (units included) before it is returned.
    """
    import pandas as pd

    p = Path(path)
    where = f"flight log CSV {str(p)!r}"
    if not p.exists():
        raise FlightLogError(f"{where}: file does not exist")
    try:
        df = pd.read_csv(p, dtype=str, keep_default_na=False, skipinitialspace=True, skip_blank_lines=False)
    except pd.errors.EmptyDataError:
        raise FlightLogError(f"{where}: file is empty; expected a header row {', '.join(CSV_COLUMNS)} and data rows") from None
    except (pd.errors.ParserError, UnicodeDecodeError, OSError) as exc:
        raise FlightLogError(f"{where}: cannot be parsed as CSV ({exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    cols = list(df.columns)
    missing = [c for c in CSV_COLUMNS if c not in cols]
    unknown = [c for c in cols if c not in CSV_COLUMNS]
    dup_cols = sorted({c for c in cols if cols.count(c) > 1})
    if missing or unknown or dup_cols:
        parts = []
        if missing:
            parts.append(f"missing column(s) {', '.join(map(repr, missing))}")
        if unknown:
            parts.append(f"unknown column(s) {', '.join(map(repr, unknown))}")
        if dup_cols:
            parts.append(f"repeated column(s) {', '.join(map(repr, dup_cols))}")
        raise FlightLogError(
            f"{where}: {'; '.join(parts)}; expected a header row with exactly the columns {', '.join(CSV_COLUMNS)}"
        )
    lines = np.arange(len(df)) + 2  # 1-based file line numbers (line 1 is the header)
    blank = (df.fillna("").apply(lambda col: col.str.strip()) == "").all(axis=1).to_numpy()
    df, lines = df[~blank], lines[~blank]
    if len(df) == 0:
        raise FlightLogError(f"{where}: no data rows; expected rows t, copter, x, y, yaw")
    copter = [str(c) for c in df["copter"].str.strip()]
    if "" in copter:
        i = copter.index("")
        raise FlightLogError(f"{where}: column 'copter' is empty at line {lines[i]}; expected a copter name")
    values = {}
    for c in ("t", "x", "y", "yaw"):
        s = df[c].str.strip()
        num = pd.to_numeric(s, errors="coerce").to_numpy(dtype=np.float64)
        bad = ~np.isfinite(num)
        if bad.any():
            i = int(np.argmax(bad))
            raise FlightLogError(
                f"{where}: column {c!r} at line {lines[i]} (copter {copter[i]!r}) is {df[c].iloc[i]!r}; "
                f"expected a finite number ({plural(int(bad.sum()), 'bad cell')}; missing poses are not interpolated)"
            )
        values[c] = num

    times = np.unique(values["t"])
    ids = sorted(set(copter), key=lambda s: (_natural_key(s), s))
    ti = np.searchsorted(times, values["t"])
    index = {c: k for k, c in enumerate(ids)}
    ci = np.fromiter((index[c] for c in copter), dtype=np.int64, count=len(copter))
    T, N = len(times), len(ids)
    flat = ti * N + ci
    order = np.argsort(flat, kind="stable")
    sorted_flat = flat[order]
    dup = np.flatnonzero(sorted_flat[1:] == sorted_flat[:-1])
    if dup.size:
        a, b = order[dup[0]], order[dup[0] + 1]
        raise FlightLogError(
            f"{where}: copter {copter[a]!r} has more than one row at t = {fmt(values['t'][a])} s "
            f"(lines {min(lines[a], lines[b])} and {max(lines[a], lines[b])}); expected one pose per copter and time"
        )
    seen = np.zeros(T * N, dtype=bool)
    seen[flat] = True
    if not seen.all():
        miss = np.flatnonzero(~seen)
        k = int(miss[0])
        more = f" (and {miss.size - 1} more missing (copter, t) pair(s))" if miss.size > 1 else ""
        raise FlightLogError(
            f"{where}: copter {ids[k % N]!r} has no row at t = {fmt(times[k // N])} s{more}; "
            "expected every copter at every time (rows are not interpolated)"
        )
    pose = np.empty((T * N, 3), dtype=np.float64)
    pose[flat] = np.stack([values["x"], values["y"], values["yaw"]], axis=1)

    m = dict(meta or {})
    if "copter_radius" in m and m["copter_radius"] != copter_radius:
        raise FlightLogError(
            f"meta['copter_radius'] = {m['copter_radius']!r} disagrees with copter_radius = {copter_radius!r}; give it once"
        )
    m["copter_radius"] = copter_radius
    m.setdefault("source", f"csv:{p.name}")
    log = FlightLog(
        t=times,
        arena=np.asarray(arena),
        pose=pose.reshape(T, N, 3),
        copter_ids=np.array(ids, dtype=str),
        meta=m,
    )
    try:
        validate(log)
    except FlightLogError as exc:
        raise FlightLogError(f"{where}: {exc}") from None
    return log
