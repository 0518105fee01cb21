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

__all__ = ["CSV_COLUMNS", "from_csv", "read_table", "numeric_column"]

CSV_COLUMNS = ("t", "copter", "x", "y", "yaw")
"""The columns of a tracking CSV: time (s), copter name, x (m), y (m), yaw (rad)."""


def _natural_key(s: str):
    """Sort key that orders the digit runs of ``s`` by value: ``cf2`` before ``cf10``."""
    return [(0, int(tok), "") if tok.isdigit() else (1, 0, tok) for tok in re.split(r"(\d+)", s) if tok != ""]


def read_table(path: Path, columns, where: str, optional=()):
    """(df, lines): the CSV at ``path`` as a DataFrame of stripped strings with exactly the header ``columns`` (in
    any order; plus any of the ``optional`` columns), blank rows removed, and the 1-based file line of each row. Errors name ``where``: a missing or
    empty file, unparseable text, missing / unknown / repeated columns, no data rows."""
    import pandas as pd

    if not path.exists():
        raise FlightLogError(f"{where}: file does not exist")
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, skip_blank_lines=False)
    except pd.errors.EmptyDataError:
        raise FlightLogError(f"{where}: file is empty; expected a header row {', '.join(columns)} and data rows") from None
    except (pd.errors.ParserError, UnicodeDecodeError, OSError) as exc:
        raise FlightLogError(f"{where}: cannot be parsed as CSV ({exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    cols = list(df.columns)
    missing = [c for c in columns if c not in cols]
    unknown = [c for c in cols if c not in columns and c not in optional]
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
            f"{where}: {'; '.join(parts)}; expected a header row with exactly the columns {', '.join(columns)}"
            + (f" (optional: {', '.join(optional)})" if optional else "")
        )
    lines = np.arange(len(df)) + 2  # 1-based file line numbers (line 1 is the header)
    blank = (df.fillna("").apply(lambda col: col.str.strip()) == "").all(axis=1).to_numpy()
    df, lines = df[~blank], lines[~blank]
    if len(df) == 0:
        raise FlightLogError(f"{where}: no data rows; expected rows {', '.join(columns)}")
    return df, lines


def numeric_column(df, column: str, lines, where: str, copter, why: str, allow_nan: bool = False) -> np.ndarray:
    """Column ``column`` of the string DataFrame ``df`` as float64 (n,); a cell that is not a finite number (or,
    with ``allow_nan``, NaN / an empty cell) is an error naming the column, line, copter and the bad cell count."""
    import pandas as pd

    s = df[column].str.strip()
    num = pd.to_numeric(s, errors="coerce").to_numpy(dtype=np.float64)
    if allow_nan:
        lost = s.str.lower().isin(["", "nan"]).to_numpy()
        bad = ~np.isfinite(num) & ~lost
    else:
        bad = ~np.isfinite(num)
    if bad.any():
        i = int(np.argmax(bad))
        expected = "a finite number" + (" (NaN or empty = no reading)" if allow_nan else "")
        raise FlightLogError(
            f"{where}: column {column!r} at line {lines[i]} (copter {copter[i]!r}) is {df[column].iloc[i]!r}; "
            f"expected {expected} ({plural(int(bad.sum()), 'bad cell')}; {why})"
        )
    return num


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
    p = Path(path)
    where = f"flight log CSV {str(p)!r}"
    df, lines = read_table(p, CSV_COLUMNS, where)
    copter = [str(c) for c in df["copter"].str.strip()]
    if "" in copter:
        i = copter.index("")
        raise FlightLogError(f"{where}: column 'copter' is empty at line {lines[i]}; expected a copter name")
    values = {c: numeric_column(df, c, lines, where, copter, "missing poses are not interpolated")
              for c in ("t", "x", "y", "yaw")}

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
