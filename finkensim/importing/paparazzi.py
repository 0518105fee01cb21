"""Paparazzi telemetry logs (``.data`` + ``.log``) in: the FINken's own recordings.

    from finkensim.importing import read_paparazzi, read_csv, build_flight
    pp = read_paparazzi("15_12_16__13_55_00.data.gz")         # the .log next to it gives the layouts
    pp.readings                                               # long form: t, copter, channel, value (SI units)
    rec = pp.recording(read_csv("track.csv").tracking)        # merged with the arena's tracking
    log = build_flight(rec, arena=(4, 3), sonar_yaw=pp.sonar_yaw, sonar_offset=0.1)   # clock offset "auto"

A ``.data`` file has one message per line, ``time ac_id NAME field field ...`` (time in s since the logger started;
an array field is one comma-separated token). The field layout comes from the ``.log``'s embedded protocol, extended
or overridden by a given ``messages.xml`` (:mod:`.paparazzi_protocol`); the map (:func:`~.paparazzi_protocol.read_map`,
default: the FINken's) says which field is which finkensim channel and in which unit it is recorded; values are
converted to SI units, nothing else is changed (held sonar values stay as the telemetry repeated them), except
that a mapped line identical to the previous line of its aircraft and message (the same message twice, same time)
is kept once, counted in the notes. Each ``ac_id`` is one copter. Every line is checked, mapped or not: a line that is cut short, a message the protocol lacks,
a field count that disagrees with the layout, a time, ac_id or mapped value that is not a number — each is a
:class:`~.recording.RecordingError` naming the file and line. Messages that are well formed but not mapped are
counted in :attr:`PaparazziLog.notes` (``"not mapped"``), never silently dropped.

A recording without poses (Paparazzi telemetry alone) can be analysed as it is (:attr:`PaparazziLog.readings`), but a
flight log needs poses: :meth:`PaparazziLog.recording` without tracking gives a sensor-only recording that
:func:`~.align.build_flight` refuses, saying to add the arena's tracking.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..usertext import suggest
from .paparazzi_protocol import (DEFAULT_MAP, Protocol, check_map_against, read_map, read_protocol,
                                 read_text)
from .recording import READING_COLUMNS, TRACKING_COLUMNS, Recording, RecordingError

__all__ = ["PaparazziLog", "read_paparazzi", "companion_log"]


@dataclass(frozen=True)
class PaparazziLog:
    """A Paparazzi telemetry log mapped to finkensim channels (module doc).

    Attributes:
        readings: DataFrame with columns t (s, the logger's clock), copter (name), channel, value (the channel's SI
            unit), sorted by copter, channel and time; flight-log channels and analysis-only ones (``down``,
            ``attitude/*``).
        copters: copter names in ac_id order; ``ac_ids`` the matching ac_id strings.
        sonar_yaw: mounting yaw (rad) of ultrasonic/0, /1, ... from the map, or None.
        source: the files read. notes: what was read (message counts, mapped and not, units converted).
    """

    readings: object
    copters: list
    ac_ids: list
    sonar_yaw: list | None
    source: str
    notes: dict = field(default_factory=dict)

    def recording(self, tracking=None) -> Recording:
        """A :class:`~.recording.Recording` of the flight-log channels, with ``tracking`` (a DataFrame with
        columns t, copter, x, y, yaw, e.g. ``read_csv("track.csv").tracking``) or without it (sensor-only: it can be
        checked and analysed, but :func:`~.align.build_flight` refuses it, as a flight log needs poses). Where the
        logger stamped two different messages of a channel with one time (a burst), the later one is used and the
        others are counted in the notes (a stream's times must increase)."""
        import pandas as pd

        from .paparazzi_protocol import ANALYSIS_CHANNELS

        rd = self.readings[~self.readings["channel"].isin(list(ANALYSIS_CHANNELS))]
        keep = ~rd.duplicated(subset=["copter", "channel", "t"], keep="last")
        rd = rd[keep].reset_index(drop=True)
        notes = dict(self.notes)
        if not keep.all():  # the logger stamped two different messages with one time: the later one is used
            notes["same time as a later message of the channel (not used)"] = int((~keep).sum())
        if tracking is None:
            tracking = pd.DataFrame({c: pd.Series([], dtype=object if c == "copter" else float)
                                     for c in TRACKING_COLUMNS})
            notes["sensor_only"] = True
        return Recording(tracking=tracking[list(TRACKING_COLUMNS)], readings=rd[list(READING_COLUMNS)],
                         source=f"paparazzi:{self.source}", notes=notes)


def companion_log(data_path) -> Path | None:
    """The ``.log`` written with a ``.data`` file (same stem; ``.log`` or ``.log.gz``), or None."""
    p = Path(data_path)
    stem = p.name[:-len(".data.gz")] if p.name.endswith(".data.gz") else p.name.rsplit(".", 1)[0]
    for name in (stem + ".log", stem + ".log.gz"):
        if (p.parent / name).is_file():
            return p.parent / name
    return None


def _protocol(data_path, log, messages) -> Protocol:
    log = companion_log(data_path) if log is None else log
    proto = read_protocol(log) if log is not None else None
    if messages is not None:
        extra = read_protocol(messages)
        proto = extra if proto is None else proto.extended(extra)
    if proto is None:
        raise RecordingError(f"{str(data_path)!r}: no .log next to it and no messages.xml given; expected the "
                             "message layouts from the .log (same name) or --messages messages.xml")
    return proto


def _number(text, kind, where):
    try:
        v = int(text) if kind == "ac_id" else float(text)
    except ValueError:
        raise RecordingError(f"{where}: {kind} is {text!r}; expected " + ("an integer aircraft id" if kind == "ac_id"
                             else "a number")) from None
    if kind != "ac_id" and not math.isfinite(v):
        raise RecordingError(f"{where}: {kind} is {text!r}; expected a finite number")
    return v


def read_paparazzi(data, *, log=None, messages=None, map=DEFAULT_MAP) -> PaparazziLog:
    """Read a Paparazzi ``.data`` file (gzip or not) into a :class:`PaparazziLog` (module doc).

    Args:
        data: the ``.data`` path.
        log: the ``.log`` whose embedded protocol gives the layouts (default: the one next to ``data``).
        messages: a ``messages.xml`` adding or replacing layouts (e.g. a message the log's protocol lacks).
        map: the map file, TOML text or :class:`~.paparazzi_protocol.PaparazziMap` (default: the FINken's).
    """
    import pandas as pd

    path = Path(data)
    text = read_text(path)
    proto = _protocol(path, log, messages)
    pmap = read_map(map)
    layouts = check_map_against(pmap, proto)
    mapped = {m: [(e, layouts[m].index(e.field, pmap.source)) for e in es] for m, es in pmap.by_message().items()}
    lines = text.split("\n")
    ends_cut = not text.endswith("\n")
    counts, blank, repeated = {}, 0, {}
    last = {}  # (ac_id, message) -> the fields of its previous line, with its time
    cols = {}  # (ac_id, channel) -> ([t], [value])
    for i, line in enumerate(lines, start=1):
        tok = line.split()
        if not tok:
            blank += line != "" or i < len(lines)
            continue
        where = f"{path.name} line {i}"
        cut = ends_cut and i == len(lines)
        if len(tok) < 3:
            raise RecordingError(f"{where}: {line.strip()!r} is " + ("cut short (the file ends mid-line)" if cut else
                                 "too short") + "; expected 'time ac_id MESSAGE fields...'")
        t = _number(tok[0], "time", where)
        ac = str(_number(tok[1], "ac_id", where))
        name = tok[2]
        msg = proto.messages.get(name)
        if msg is None:
            raise RecordingError(f"{where}: message {name!r} is not in the protocol ({proto.source})"
                                 f"{suggest(name, proto.messages)}; give its layout with a messages.xml (--messages)")
        n = len(tok) - 3
        if n != len(msg.fields):
            how = " (the file ends mid-line: cut short)" if cut and n < len(msg.fields) else ""
            raise RecordingError(f"{where}: message {name!r} has {n} field(s){how}; the protocol ({proto.source}) "
                                 f"gives it {len(msg.fields)}: {', '.join(f.name for f in msg.fields)}")
        counts[name] = counts.get(name, 0) + 1
        if name in mapped:
            if last.get((ac, name)) == tok:  # the same message again at the same time: sent twice, kept once
                repeated[name] = repeated.get(name, 0) + 1
                continue
            last[(ac, name)] = tok
        for e, k in mapped.get(name, ()):
            v = _number(tok[3 + k], f"field {e.field!r}", where)
            ts, vs = cols.setdefault((ac, e.channel), ([], []))
            ts.append(t)
            vs.append(v * e.factor)
    if not counts:
        raise RecordingError(f"{path.name}: no messages; expected lines 'time ac_id MESSAGE fields...'")
    names = {**proto.aircraft, **pmap.aircraft} if proto.aircraft else dict(pmap.aircraft)
    ac_ids = sorted({ac for ac, _ in cols}, key=int)
    if not ac_ids:
        raise RecordingError(f"{path.name}: none of the mapped messages ({', '.join(mapped)}) occurs; messages in "
                             f"the file: {', '.join(sorted(counts))}")
    copter = {ac: names.get(ac, f"ac{ac}") for ac in ac_ids}
    parts = [pd.DataFrame({"t": np.asarray(ts, dtype=np.float64), "copter": copter[ac], "channel": ch,
                           "value": np.asarray(vs, dtype=np.float64)})
             for (ac, ch), (ts, vs) in sorted(cols.items(), key=lambda kv: (int(kv[0][0]), kv[0][1]))]
    readings = pd.concat(parts, ignore_index=True)
    notes = {"messages": counts, "mapped": {m: counts.get(m, 0) for m in mapped},
             "not mapped": {m: c for m, c in counts.items() if m not in mapped},
             "units": {e.channel: f"{e.field} in {e.unit}" + (" (sign flipped)" if e.factor < 0 else "")
                       for e in pmap.entries},
             "aircraft": copter, "protocol": proto.source, "map": pmap.source, "blank_lines": blank,
             "repeated lines (identical to the previous one of the aircraft and message, kept once)": repeated}
    src = path.name + (f"+{Path(messages).name}" if messages is not None else "")
    return PaparazziLog(readings, [copter[a] for a in ac_ids], ac_ids, pmap.sonar_yaw(), src, notes)
