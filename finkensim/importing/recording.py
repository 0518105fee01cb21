"""The asynchronous recording every importer produces: long-form tables, each sample at its own time.

A :class:`Recording` is what a CSV pair, a ROS 1 / ROS 2 bag or an MCAP file holds once its messages are
mapped to finkensim's channels, before any alignment: every copter's tracking at its own times, every
reading at its own time. :func:`finkensim.importing.build_flight` turns it into one ``docs/formats/flightlog.md``
flight on a common time base.

Channels (column ``channel`` of :attr:`Recording.readings`):

=============================  ======  ==========================================================
``ultrasonic/<i>``             m       sonar ``i`` (index into the sonar yaw list), measured from the sonar
``ranging/<copter name>``      m       virtual-ranging reading of the named other copter
``imu/acc_x``, ``imu/acc_y``   m/s²    body-frame acceleration (x forward, y left)
``imu/gyro``                   rad/s   yaw rate
=============================  ======  ==========================================================

:func:`check_recording` is the one place that checks a recording, whatever file it came from: every error is a
:class:`RecordingError` naming the table, the column or channel, the value and what was expected.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..usertext import suggest
from ..flightlog import FlightLogError
from ..flightlog.messages import fmt

__all__ = ["Recording", "RecordingError", "TRACKING_COLUMNS", "OPTIONAL_TRACKING_COLUMNS", "READING_COLUMNS", "IMU_CHANNELS", "Channel",
           "parse_channel", "check_recording", "CheckedRecording"]

#: columns of :attr:`Recording.tracking`: t (s), copter (name), x, y (m), yaw (rad)
TRACKING_COLUMNS = ("t", "copter", "x", "y", "yaw")
#: optional columns of :attr:`Recording.tracking`: z (m, height above the floor; ranging then uses 3-D distances)
OPTIONAL_TRACKING_COLUMNS = ("z",)
#: columns of :attr:`Recording.readings`: t (s), copter (name), channel (see module doc), value (channel's unit)
READING_COLUMNS = ("t", "copter", "channel", "value")
IMU_CHANNELS = ("imu/acc_x", "imu/acc_y", "imu/gyro")
_CHANNEL_FORMS = ("ultrasonic/<i>", "ranging/<copter>") + IMU_CHANNELS

#: Times that look like milliseconds are judged per stream (one copter's tracking, one copter's channel), never
#: over a whole file, so one copter in ms among others in s is caught and a slow stream is not mistaken for ms:
#: a copter's tracking whose median interval is at least this (s) looks like ms (tracking systems record at
#: 50-500 Hz; window means of 1 Hz are the slowest seen; 500 Hz in ms reads 2 s)
TRACKING_MS_INTERVAL = 1.5
#: a reading stream whose median interval is at least this (s) looks like ms: sensors record at 5-200 Hz (ms:
#: 5-200 s), but a radio link on a shared channel may report only every 0.5-5 s (0.2-2 Hz), which is normal
READING_MS_INTERVAL = 20.0
#: a stream (tracking or readings) whose time span is more than this many times the copters' median tracking span
#: looks like ms while the others are in s (the span does not depend on a clock offset)
MS_SPAN_RATIO = 50.0


class RecordingError(FlightLogError):
    """A recording (CSV pair, bag, tables) cannot be imported; the message names what and where."""


@dataclass(frozen=True)
class Recording:
    """One recorded flight as long-form tables (pandas DataFrames), nothing resampled.

    Attributes:
        tracking: columns :data:`TRACKING_COLUMNS`; t float64 (s, tracking clock), copter str, x/y float64 (m,
            arena frame), yaw float64 (rad, counter-clockwise from +x, any wrapping); optionally z float64 (m,
            height). Each copter at its own times.
        readings: columns :data:`READING_COLUMNS`; t float64 (s, the sensors' clock, which may be offset from the
            tracking clock), copter str (the measuring copter), channel str, value float64. A lost reading may be
            absent or NaN.
        source: where it came from, e.g. ``"csv:track.csv+read.csv"`` or ``"rosbag2:flight/"``.
        notes: what the reader decided (topics used, messages skipped and why), copied into the flight's ``meta``.
    """

    tracking: object
    readings: object
    source: str = ""
    notes: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Channel:
    """A parsed channel name: kind 'ultrasonic' (index = sonar index), 'ranging' (other = copter name) or 'imu'
    (axis = 0 acc_x, 1 acc_y, 2 gyro)."""

    kind: str
    index: int = -1
    other: str = ""
    axis: int = -1


_ULTRA = re.compile(r"^ultrasonic/(\d+)$")


def parse_channel(name: str) -> Channel:
    """The :class:`Channel` of a channel name, or a RecordingError with the nearest valid form."""
    m = _ULTRA.match(name)
    if m:
        return Channel("ultrasonic", index=int(m.group(1)))
    if name.startswith("ranging/") and len(name) > len("ranging/"):
        return Channel("ranging", other=name[len("ranging/"):])
    if name in IMU_CHANNELS:
        return Channel("imu", axis=IMU_CHANNELS.index(name))
    hint = suggest(name, ["ultrasonic/0", "ranging/", *IMU_CHANNELS])
    raise RecordingError(f"readings: unknown channel {name!r}{hint}; expected one of {', '.join(_CHANNEL_FORMS)}")


@dataclass
class CheckedRecording:
    """A checked recording as arrays, rows grouped by stream and sorted by time within it.

    copters: copter names, tracking first-seen order. Tracking (rows sorted by copter, then t): tr_copter (n,)
    int index into copters, tr_t, tr_x, tr_y, tr_yaw (n,) float64. Readings (rows sorted by stream, then t):
    rd_copter (m,) int, rd_kind (m,) int (0 ultrasonic, 1 ranging, 2 imu), rd_slot (m,) int (sonar index, index
    of the other copter, or IMU axis), rd_t (m,) s, rd_value (m,) with NaN = lost; rd_stream (m,) int, one per
    (copter, channel); stream_names: the channel name of each stream as ``"copter:channel"``.
    dropped: reason -> number of rows not used. tr_z (n,) m: the tracking's heights, None without a z column.
    """

    copters: list
    tr_copter: np.ndarray
    tr_t: np.ndarray
    tr_x: np.ndarray
    tr_y: np.ndarray
    tr_yaw: np.ndarray
    rd_copter: np.ndarray
    rd_kind: np.ndarray
    rd_slot: np.ndarray
    rd_t: np.ndarray
    rd_value: np.ndarray
    rd_stream: np.ndarray
    stream_names: list
    dropped: dict
    tr_z: np.ndarray | None = None


KIND_ULTRASONIC, KIND_RANGING, KIND_IMU = 0, 1, 2
KIND_NAMES = ("ultrasonic", "ranging", "imu")


def _columns(df, columns, table):
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise RecordingError(f"{table}: missing column(s) {', '.join(map(repr, missing))}; expected the columns "
                             f"{', '.join(columns)}")


def _floats(df, column, table, allow_nan=False):
    import pandas as pd

    col = df[column]
    v = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64)
    if not allow_nan:
        lost = np.zeros(v.size, dtype=bool)
    elif col.dtype.kind == "f":
        lost = np.isnan(v)
    else:
        lost = col.isna().to_numpy() | col.astype(str).str.strip().str.lower().isin(["", "nan"]).to_numpy()
    bad = ~np.isfinite(v) & ~lost
    if bad.any():
        i = int(np.argmax(bad))
        exp = "a finite number" + (" (NaN = lost reading)" if allow_nan else "")
        raise RecordingError(f"{table}: column {column!r} row {i} is {col.iloc[i]!r}; expected {exp} "
                             f"({int(bad.sum())} bad value(s))")
    return v


def _names(df, column, table):
    """(codes (n,) int64, names list) of a name column, in first-seen order; empty names are an error."""
    import pandas as pd

    col = df[column]
    empty = (col.isna() | (col.astype(str).str.strip() == "")).to_numpy()
    if empty.any():
        i = int(np.argmax(empty))
        raise RecordingError(f"{table}: column {column!r} row {i} is empty; expected a name")
    codes, uniques = pd.factorize(col.astype(str).str.strip(), sort=False)
    return codes.astype(np.int64), [str(u) for u in uniques]


def _increasing(stream, t, table, label, names, rows):
    """Times strictly increasing within each stream, in the rows' own order: otherwise a named error."""
    same = stream[1:] == stream[:-1]
    dt = np.diff(t)
    bad = same & (dt <= 0)
    if bad.any():
        i = int(np.argmax(bad))
        what = "repeated" if dt[i] == 0 else "not increasing"
        raise RecordingError(
            f"{table}: {label} {names[stream[i + 1]]!r} times are {what} at row {rows[i + 1]} (t = {fmt(t[i + 1])} s "
            f"after {fmt(t[i])} s; {int(bad.sum())} such row(s)); expected each {label}'s rows in strictly "
            "increasing time (sort them by time; remove duplicated samples)")


def _spans(stream, t, n_streams):
    """(span (n_streams,), median interval (n_streams,)) per stream of rows grouped by stream; NaN interval for a
    stream with one row."""
    bounds = np.searchsorted(stream, np.arange(n_streams + 1))
    span, step = np.zeros(n_streams), np.full(n_streams, math.nan)
    for s in range(n_streams):
        ts = t[bounds[s]:bounds[s + 1]]
        if ts.size:
            span[s] = ts[-1] - ts[0]
        if ts.size > 1:
            step[s] = float(np.median(np.diff(ts)))
    return span, step


def _check_times(stream, t, table, label, names, rows, rates, limit, reference_span=None):
    """Strictly increasing times within each stream (:func:`_increasing`); per stream, a median interval below
    ``limit`` s and a span at most :data:`MS_SPAN_RATIO` times ``reference_span`` (default: the median span of
    these streams) (else that stream's times look like milliseconds; ``rates`` says what is usual). Returns the
    spans (n_streams,) s."""
    _increasing(stream, t, table, label, names, rows)
    span, step = _spans(stream, t, len(names))
    slow = np.flatnonzero(step >= limit)
    if slow.size:
        s = int(slow[0])
        raise RecordingError(f"{table}: the median interval between {label} {names[s]!r}'s samples is "
                             f"{fmt(step[s])} s; that looks like milliseconds ({rates}): convert t to seconds"
                             + (f" ({slow.size} of {len(names)} {label}s)" if len(names) > 1 else ""))
    _check_spans(span, reference_span if reference_span is not None else float(np.median(span)), table, label, names)
    return span


def _check_spans(span, reference_span, table, label, names):
    """Each stream's span at most :data:`MS_SPAN_RATIO` times ``reference_span`` s (else a named error)."""
    if not reference_span > 0:
        return
    long = np.flatnonzero(span > MS_SPAN_RATIO * reference_span)
    if long.size:
        s = int(long[0])
        raise RecordingError(f"{table}: {label} {names[s]!r} spans {fmt(span[s])} s, "
                             f"{fmt(span[s] / reference_span)} times the copters' median tracking span "
                             f"({fmt(reference_span)} s); that looks like milliseconds while the others are in "
                             f"seconds: convert that {label}'s t to seconds")


def check_recording(rec: Recording) -> CheckedRecording:
    """Check a :class:`Recording` and return it as arrays (:class:`CheckedRecording`).

    Errors (:class:`RecordingError`): missing columns; non-numeric or non-finite times, positions, yaw (readings may
    be NaN = lost); empty names; unknown channels; a stream (copter, or copter and channel) whose times are not
    strictly increasing in the order given; a copter with readings but no tracking; ranging to an unknown copter;
    times that look like milliseconds (per stream: :data:`TRACKING_MS_INTERVAL`, :data:`READING_MS_INTERVAL`,
    :data:`MS_SPAN_RATIO`); yaw that looks like degrees. Positions and ranges
    that look like centimetres or millimetres are judged against the arena in :func:`build_flight`.
    """
    tr, rd = rec.tracking, rec.readings
    _columns(tr, TRACKING_COLUMNS, "tracking")
    _columns(rd, READING_COLUMNS, "readings")
    if len(tr) == 0:
        what = "this is a sensor-only recording (no poses); " if rec.notes.get("sensor_only") else ""
        raise RecordingError(f"tracking: no rows; {what}a flight log needs each copter's poses (spec/flightlog.md: "
                             "pose (T, N, 3)): add the arena's tracking, a tracking CSV with columns t, copter, x, y, "
                             "yaw (--tracking TRACK.csv); the readings alone can be analysed but not diagnosed")
    ci, copters = _names(tr, "copter", "tracking")
    t = _floats(tr, "t", "tracking")
    x, y, yaw = (_floats(tr, c, "tracking") for c in ("x", "y", "yaw"))
    index = {c: k for k, c in enumerate(copters)}
    order = np.argsort(ci, kind="stable")
    rows = np.arange(ci.size)[order]
    ci, t, x, y, yaw = ci[order], t[order], x[order], y[order], yaw[order]
    reference = float(np.median(_check_times(ci, t, "tracking", "copter", copters, rows,
                                             "tracking systems record at 50-500 Hz", TRACKING_MS_INTERVAL)))
    _check_yaw(ci, t, yaw)
    z = None
    if "z" in tr.columns:
        z = _floats(tr, "z", "tracking")[order]

    n = len(rd)
    dropped = {}
    if n == 0:
        empty_i, empty_f = np.zeros(0, dtype=np.int64), np.zeros(0)
        return CheckedRecording(copters, ci, t, x, y, yaw, empty_i, empty_i, empty_i, empty_f, empty_f, empty_i, [],
                                dropped, tr_z=z)
    rcode, rnames = _names(rd, "copter", "readings")
    chi, names = _names(rd, "channel", "readings")
    rt = _floats(rd, "t", "readings")
    val = _floats(rd, "value", "readings", allow_nan=True)
    unknown_copters = sorted(set(rnames) - set(copters))
    if unknown_copters:
        raise RecordingError(f"readings: copter {unknown_copters[0]!r} has readings but no tracking "
                             f"({len(unknown_copters)} such copter(s)); tracked copters: {', '.join(copters)}")
    parsed = {nm: parse_channel(nm) for nm in names}
    for nm, c in parsed.items():
        if c.kind == "ranging" and c.other not in index:
            hint = suggest(c.other, copters, show=lambda name: f"'ranging/{name}'")
            raise RecordingError(f"readings: channel {nm!r} ranges to {c.other!r}, which has no tracking{hint}; "
                                 f"tracked copters: {', '.join(copters)}")
    kind_of = {nm: KIND_NAMES.index(c.kind) for nm, c in parsed.items()}
    slot_of = {nm: (c.index if c.kind == "ultrasonic" else index[c.other] if c.kind == "ranging" else c.axis)
               for nm, c in parsed.items()}
    rci = np.array([index[c] for c in rnames], dtype=np.int64)[rcode]
    stream_key = rci * len(names) + chi
    keys, stream = np.unique(stream_key, return_inverse=True)
    stream_names = [f"{copters[k // len(names)]}:{names[k % len(names)]}" for k in keys]
    order = np.argsort(stream, kind="stable")
    rows = order.copy()
    stream, rt, val, rci, chi = stream[order], rt[order], val[order], rci[order], chi[order]
    _check_times(stream, rt, "readings", "stream", stream_names, rows, "sensors record at 5-200 Hz, radio links "
                 "at 0.2-2 Hz", READING_MS_INTERVAL, reference)
    kinds = np.array([kind_of[nm] for nm in names], dtype=np.int64)[chi]
    slots = np.array([slot_of[nm] for nm in names], dtype=np.int64)[chi]
    self_range = (kinds == KIND_RANGING) & (slots == rci)
    if self_range.any():
        i = int(np.argmax(self_range))
        raise RecordingError(f"readings: copter {copters[rci[i]]!r} has a ranging channel to itself at row {rows[i]}; "
                             "expected ranging/<another copter> (the diagonal of ranging is 0 by definition)")
    return CheckedRecording(copters, ci, t, x, y, yaw, rci, kinds, slots, rt, val, stream, stream_names, dropped,
                            tr_z=z)


def _check_yaw(ci, t, yaw):
    """Yaw in degrees: beyond 2π in magnitude, and either mostly beyond it (a heading in degrees almost always is)
    or turning faster than 20 per second at the 90th percentile (20 rad/s is over three turns a second, common in
    degrees). Wrap jumps (2π or 360) are not turns."""
    top = float(np.max(np.abs(yaw))) if yaw.size else 0.0
    if top <= 2 * math.pi + 1e-9:
        return
    same = ci[1:] == ci[:-1]
    d = np.abs(np.diff(yaw))[same]
    dt = np.diff(t)[same]
    turn = ~((np.abs(d - 2 * math.pi) < 0.5) | (np.abs(d - 360.0) < 5.0))
    rate = d[turn] / dt[turn]
    p90 = float(np.quantile(rate, 0.9)) if rate.size else 0.0
    med = float(np.median(np.abs(yaw)))
    if med > 2 * math.pi or p90 > 20.0:
        raise RecordingError(f"tracking: yaw reaches {fmt(top)} (median |yaw| {fmt(med)}, 90th-percentile turn rate "
                             f"{fmt(p90)} per s); that looks like degrees: convert yaw to radians (counter-clockwise "
                             "from +x); if it is radians accumulated over many turns, wrap it to [-pi, pi)")
