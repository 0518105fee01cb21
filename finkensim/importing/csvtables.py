"""Read a recording from two long-form CSV files: tracking and readings.

``TRACK.csv``: header ``t, copter, x, y, yaw`` (s, name, m, m, rad) and optionally ``z`` (m, height), one row per pose, each copter at its own
times. ``READ.csv``: header ``t, copter, channel, value`` (s, measuring copter, channel, value in the channel's
unit; NaN or an empty cell = lost reading), channels as in :mod:`finkensim.importing.recording`. Rows may
interleave copters and channels; within one copter (tracking) or one copter and channel (readings) they must be
in increasing time — :func:`~finkensim.importing.recording.check_recording` says where they are not.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..flightlog.csv import numeric_column, read_table
from .recording import OPTIONAL_TRACKING_COLUMNS, READING_COLUMNS, TRACKING_COLUMNS, Recording

__all__ = ["read_csv"]


def read_csv(tracking: str | os.PathLike, readings: str | os.PathLike | None = None) -> Recording:
    """The :class:`Recording` of a tracking CSV and (optionally) a readings CSV; errors name the file, column and
    line. Nothing is checked beyond the cells here: :func:`~finkensim.importing.build_flight` checks the whole."""
    import pandas as pd

    tp = Path(tracking)
    where = f"tracking CSV {str(tp)!r}"
    df, lines = read_table(tp, TRACKING_COLUMNS, where, optional=OPTIONAL_TRACKING_COLUMNS)
    copter = df["copter"].str.strip().to_numpy()
    track = pd.DataFrame({"t": numeric_column(df, "t", lines, where, copter, "poses are not interpolated here"),
                          "copter": copter})
    for c in ("x", "y", "yaw") + tuple(c for c in OPTIONAL_TRACKING_COLUMNS if c in df.columns):
        track[c] = numeric_column(df, c, lines, where, copter, "remove rows without a pose")
    source = f"csv:{tp.name}"
    if readings is None:
        read = pd.DataFrame({c: [] for c in READING_COLUMNS})
    else:
        rp = Path(readings)
        where = f"readings CSV {str(rp)!r}"
        df, lines = read_table(rp, READING_COLUMNS, where)
        copter = df["copter"].str.strip().to_numpy()
        read = pd.DataFrame({"t": numeric_column(df, "t", lines, where, copter, "every reading needs its time"),
                             "copter": copter, "channel": df["channel"].str.strip().to_numpy(),
                             "value": numeric_column(df, "value", lines, where, copter, "NaN marks a lost reading",
                                                     allow_nan=True)})
        source += f"+{rp.name}"
    return Recording(tracking=track, readings=read, source=source,
                     notes={"files": [str(tp)] + ([str(readings)] if readings is not None else [])})
