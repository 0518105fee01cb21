"""Write a (simulated) flight as Paparazzi telemetry: the inverse of :func:`~.paparazzi.read_paparazzi`.

:func:`write_paparazzi` writes one line per sample, copter and mapped message into a ``.data`` file and a ``.log``
whose embedded protocol holds those messages' layouts, as the Paparazzi logger does. Each value is converted from
its SI unit to the unit the map names and written in its field's type: integer fields are rounded to whole units
(1 cm for the FINken's sonars; reading them back gives the value rounded to that resolution), float fields at full
precision (read back exactly). Fields no map entry names, and map channels the flight lacks, are written as 0. Sonars are matched by their
mounting yaw (the map's front/right/left/back to the flight's sonar with that yaw). For tests, and to try a map on a
simulated flight before flying.
"""
from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET

import numpy as np

from .paparazzi_protocol import DEFAULT_MAP, Protocol, check_map_against, read_map, read_protocol
from .recording import RecordingError, parse_channel

__all__ = ["write_paparazzi", "channel_values"]


def channel_values(flight, channel: str, yaw: float = math.nan):
    """(T, N) values of a finkensim channel in a flight log (SI units), or None when the log lacks it. A sonar is
    found by its mounting ``yaw`` (rad; the map's and the flight's sonar order may differ), else by its index."""
    if channel.startswith("ultrasonic/"):
        if flight.ultrasonic is None:
            return None
        if math.isfinite(yaw):
            d = np.abs(np.angle(np.exp(1j * (np.asarray(flight.ultrasonic_yaw) - yaw))))
            return flight.ultrasonic[:, :, int(np.argmin(d))] if d.min() < 1e-6 else None
        i = parse_channel(channel).index
        return None if i >= flight.n_sonars else flight.ultrasonic[:, :, i]
    if channel in ("imu/acc_x", "imu/acc_y"):
        return None if flight.imu_acc is None else flight.imu_acc[:, :, int(channel == "imu/acc_y")]
    if channel == "imu/gyro":
        return flight.imu_gyro
    if channel.startswith("ranging/"):
        ids = [str(c) for c in flight.copter_ids]
        other = channel[len("ranging/"):]
        return None if flight.ranging is None or other not in ids else flight.ranging[:, :, ids.index(other)]
    return None


def _log_xml(protocol: Protocol, messages, names: dict) -> str:
    root = ET.Element("configuration", data_file="written by finkensim")
    conf = ET.SubElement(root, "conf")
    for ac, name in names.items():
        ET.SubElement(conf, "aircraft", name=name, ac_id=str(ac))
    cl = ET.SubElement(ET.SubElement(root, "protocol"), "msg_class", NAME="telemetry")
    for m in messages:
        el = ET.SubElement(cl, "message", NAME=m.name, ID=str(m.id))
        for f in m.fields:
            ET.SubElement(el, "field", TYPE=f.type, NAME=f.name, **({"UNIT": f.unit} if f.unit else {}))
    return ET.tostring(root, encoding="unicode") + "\n"


def write_paparazzi(flight, data_path: str | os.PathLike, log_path: str | os.PathLike, protocol, *,
                    map=DEFAULT_MAP, ac_ids=None, clock_offset: float = 0.0) -> dict:
    """Write ``flight`` (a :class:`~finkensim.flightlog.FlightLog`) as a ``.data`` and a ``.log`` file.

    Args:
        protocol: a :class:`~.paparazzi_protocol.Protocol` or messages.xml path / text with the mapped messages.
        map: the map (default: the FINken's); its ``[aircraft]`` names are ignored: the flight's copter ids are.
        ac_ids: one integer per copter (default 1, 2, ...).
        clock_offset: s; times are written as ``t − clock_offset`` (what the import must add back).
    Returns: {"written": channels written, "zero": map channels the flight lacks, written as 0}.
    """
    proto = protocol if isinstance(protocol, Protocol) else read_protocol(protocol)
    pmap = read_map(map)
    layouts = check_map_against(pmap, proto)
    N = flight.n_copters
    ac_ids = list(range(1, N + 1)) if ac_ids is None else [int(a) for a in ac_ids]
    if len(ac_ids) != N or len(set(ac_ids)) != N:
        raise RecordingError(f"ac_ids = {ac_ids!r}: expected {N} distinct integers, one per copter")
    written, zero = [], []
    tables = {}  # message -> (T, N, fields) array of strings
    T = flight.n_steps
    for name, msg in layouts.items():
        cells = np.full((T, N, len(msg.fields)), "0", dtype=object)
        for e in pmap.by_message()[name]:
            k = msg.index(e.field, pmap.source)
            v = channel_values(flight, e.channel, e.yaw)
            if v is None:
                zero.append(e.channel)
                continue
            raw = np.asarray(v, dtype=np.float64) / e.factor
            if msg.fields[k].is_int:
                if not np.all(np.isfinite(raw)):
                    raise RecordingError(f"channel {e.channel!r} has lost (NaN) readings, which the integer field "
                                         f"{name}.{e.field} cannot hold")
                cells[:, :, k] = np.vectorize(lambda x: str(int(round(x))), otypes=[object])(raw)
            else:
                cells[:, :, k] = np.vectorize(repr, otypes=[object])(raw.astype(float))
            written.append(e.channel)
        tables[name] = cells
    t = np.asarray(flight.t, dtype=np.float64) - clock_offset
    with open(data_path, "w") as fh:
        for k in range(T):
            for n in range(N):
                for name, cells in tables.items():
                    fh.write(f"{float(t[k])!r} {ac_ids[n]} {name} {' '.join(cells[k, n])}\n")
    names = {a: str(c) for a, c in zip(ac_ids, flight.copter_ids)}
    with open(log_path, "w") as fh:
        fh.write(_log_xml(proto, layouts.values(), names))
    return {"written": written, "zero": zero}
