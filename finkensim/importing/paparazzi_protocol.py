"""Paparazzi message layouts and the map from message fields to finkensim channels.

**Protocol.** A Paparazzi telemetry ``.log`` is an XML ``<configuration>`` that embeds the ground station's
``<protocol>`` (``<msg_class>`` elements holding ``<message name id>`` with ordered ``<field name type unit>``);
a ``messages.xml`` is a bare ``<protocol>``. :func:`read_protocol` reads either (gzip read transparently; tag and
attribute names in any case: the logger writes ``NAME``/``TYPE``, messages.xml ``name``/``type``). A message name
found in several classes is taken from the first of ``telemetry``, ``ground``, ``datalink``, then the others in file
order (the ``.data`` lines carry no class). :meth:`Protocol.extended` adds or replaces layouts from a second file.

**Map** (a small TOML file, :func:`read_map`; the FINken's is shipped as ``finkensim/data/paparazzi_finken.toml``)::

    [aircraft]                 # optional: ac_id -> copter name (default: the .log's aircraft names, else "ac<id>")
    5 = "FINken3_01"

    [[channel]]
    channel = "ultrasonic/0"   # a finkensim channel (see below)
    message = "FINKEN_SENSOR_MODEL"
    field = "distance_d_front"
    unit = "cm"                # the unit the field is recorded in: converted to the channel's SI unit
    yaw_deg = 0.0              # ultrasonic only: mounting yaw relative to the heading (front 0, left 90)
    sign = 1                   # optional: -1 flips a frame convention (e.g. Paparazzi's y right / z down)

Channels: the flight-log channels of :mod:`.recording` (``ultrasonic/<i>``, ``ranging/<copter>`` in m;
``imu/acc_x``, ``imu/acc_y`` in m/s²; ``imu/gyro`` in rad/s) and analysis-only channels that the flight-log format
has no place for: ``down`` (down-facing sonar, m) and ``attitude/roll``, ``attitude/pitch``, ``attitude/yaw`` (rad).
Units: length m, cm, mm; acceleration m/s^2 (or m/s2), g; angle rad, deg; angular rate rad/s, deg/s. Every mistake
is a :class:`~.recording.RecordingError` naming the file, entry and key.
"""
from __future__ import annotations

import gzip
import math
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from ..usertext import strip_bom, suggest
from .recording import RecordingError, parse_channel

__all__ = ["Field", "Message", "Protocol", "read_protocol", "read_text", "ChannelEntry", "PaparazziMap", "read_map",
           "DEFAULT_MAP", "ANALYSIS_CHANNELS", "UNITS", "check_map_against"]

#: the FINken's map (FINKEN_SENSOR_MODEL of the 2015 firmware), shipped with finkensim
DEFAULT_MAP = Path(__file__).resolve().parent.parent / "data" / "paparazzi_finken.toml"
#: channels kept for analysis only (no place in spec/flightlog.md): name -> dimension
ANALYSIS_CHANNELS = {"down": "length", "attitude/roll": "angle", "attitude/pitch": "angle", "attitude/yaw": "angle"}
#: recorded unit -> (dimension, factor to SI)
UNITS = {"m": ("length", 1.0), "cm": ("length", 0.01), "mm": ("length", 0.001),
         "m/s^2": ("acceleration", 1.0), "m/s2": ("acceleration", 1.0), "g": ("acceleration", 9.80665),
         "rad": ("angle", 1.0), "deg": ("angle", math.pi / 180.0),
         "rad/s": ("rate", 1.0), "deg/s": ("rate", math.pi / 180.0)}
_CLASS_ORDER = ("telemetry", "ground", "datalink")
_SI = {"length": "m", "acceleration": "m/s^2", "angle": "rad", "rate": "rad/s"}


def read_text(path) -> str:
    """The text of a file, gunzipped when it starts with the gzip magic bytes (any name)."""
    p = Path(path)
    if not p.is_file():
        raise RecordingError(f"{str(p)!r} " + ("is not a file" if p.exists() else "does not exist"))
    raw = p.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError) as exc:
            raise RecordingError(f"{str(p)!r}: a damaged gzip file ({exc}); expected it to gunzip completely") from None
    try:
        return strip_bom(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{str(p)!r}: not UTF-8 text ({exc})") from None


@dataclass(frozen=True)
class Field:
    """One field of a message: name, Paparazzi type (``int16``, ``float``, ``uint8[]``, ...), unit ("" if none)."""

    name: str
    type: str
    unit: str = ""

    @property
    def is_int(self) -> bool:
        return "int" in self.type and not self.type.endswith("]")


@dataclass(frozen=True)
class Message:
    """A message layout: name, numeric id, class, fields in the order the ``.data`` lines carry them."""

    name: str
    id: int
    msg_class: str
    fields: tuple

    def index(self, field: str, where: str) -> int:
        names = [f.name for f in self.fields]
        if field not in names:
            raise RecordingError(f"{where}: message {self.name!r} has no field {field!r}{suggest(field, names)}; "
                                 f"its fields: {', '.join(names)}")
        return names.index(field)


@dataclass(frozen=True)
class Protocol:
    """Message layouts by name (:func:`read_protocol`); ``aircraft`` maps ac_id -> name (from a ``.log``)."""

    messages: dict
    source: str = "protocol"
    aircraft: dict | None = None

    def extended(self, other: "Protocol") -> "Protocol":
        """This protocol with ``other``'s layouts added (``other`` wins where both define a name)."""
        return Protocol({**self.messages, **other.messages}, f"{self.source} + {other.source}",
                        {**(self.aircraft or {}), **(other.aircraft or {})})


def _attrs(el) -> dict:
    return {k.lower(): v for k, v in el.attrib.items()}


def _tag(el) -> str:
    return str(el.tag).lower()


def read_protocol(source, name: str | None = None) -> Protocol:
    """The :class:`Protocol` of a ``.log`` / ``messages.xml`` path (gzip or not) or of XML text (module doc)."""
    if isinstance(source, Path) or (isinstance(source, str) and not source.lstrip().startswith("<")):
        name = name or str(source)
        text = read_text(source)
    else:
        name, text = name or "protocol", str(source)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RecordingError(f"{name}: not valid XML ({exc}); expected a Paparazzi .log or messages.xml") from None
    classes = [el for el in root.iter() if _tag(el) == "msg_class"]
    if not classes:
        raise RecordingError(f"{name}: no <msg_class> element; expected a Paparazzi messages.xml or a .log with its "
                             "embedded <protocol>")
    rank = {c: i for i, c in enumerate(_CLASS_ORDER)}
    classes.sort(key=lambda el: rank.get(_attrs(el).get("name", "").lower(), len(rank)))
    messages = {}
    for cl in classes:
        cname = _attrs(cl).get("name", "")
        for el in cl:
            if _tag(el) != "message":
                continue
            a = _attrs(el)
            if "name" not in a:
                raise RecordingError(f"{name}: a <message> in class {cname!r} has no name attribute")
            fields = []
            for f in el:
                if _tag(f) == "field":
                    fa = _attrs(f)
                    if "name" not in fa or "type" not in fa:
                        raise RecordingError(f"{name}: message {a['name']!r} has a <field> without name or type")
                    unit = fa.get("unit", "") or ("" if "alt_unit_coef" in fa else fa.get("alt_unit", ""))
                    fields.append(Field(fa["name"], fa["type"], unit))
            try:
                mid = int(a.get("id", "-1"))
            except ValueError:
                raise RecordingError(f"{name}: message {a['name']!r} has id {a.get('id')!r}; expected an integer") \
                    from None
            messages.setdefault(a["name"], Message(a["name"], mid, cname, tuple(fields)))
    aircraft = {}
    for el in root.iter():
        if _tag(el) == "aircraft":
            a = _attrs(el)
            if "ac_id" in a and "name" in a:
                aircraft[str(a["ac_id"]).strip()] = a["name"]
    return Protocol(messages, name, aircraft)


@dataclass(frozen=True)
class ChannelEntry:
    """One mapped field: finkensim channel, message, field, recorded unit, factor to SI (unit and sign), and
    the mounting yaw in rad (ultrasonic channels; NaN otherwise)."""

    channel: str
    message: str
    field: str
    unit: str
    factor: float
    yaw: float = math.nan

    @property
    def in_flight_log(self) -> bool:
        """Whether the flight-log format has the channel (else it is kept for analysis only)."""
        return self.channel not in ANALYSIS_CHANNELS


@dataclass(frozen=True)
class PaparazziMap:
    """All entries of a map file (:func:`read_map`); ``aircraft`` ac_id (str) -> copter name."""

    entries: tuple
    aircraft: dict
    source: str = "map"

    def by_message(self) -> dict:
        out = {}
        for e in self.entries:
            out.setdefault(e.message, []).append(e)
        return out

    def sonar_yaw(self):
        """Mounting yaw (rad) of ultrasonic/0, /1, ... in index order, or None when no sonar is mapped."""
        yaws = {parse_channel(e.channel).index: e.yaw for e in self.entries if e.channel.startswith("ultrasonic/")}
        return [yaws[i] for i in range(len(yaws))] if yaws else None


def _dimension(channel: str) -> str:
    if channel in ANALYSIS_CHANNELS:
        return ANALYSIS_CHANNELS[channel]
    c = parse_channel(channel)
    if c.kind == "imu":
        return "rate" if channel == "imu/gyro" else "acceleration"
    return "length"


def read_map(source=DEFAULT_MAP) -> PaparazziMap:
    """A :class:`PaparazziMap` from a TOML path, TOML text or a parsed dict (module doc)."""
    if isinstance(source, PaparazziMap):
        return source
    name = "map"
    if isinstance(source, dict):
        data = source
    else:
        if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source and "=" not in source):
            name, text = str(source), read_text(source)
        else:
            text = str(source)
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RecordingError(f"{name}: not valid TOML ({exc})") from None
    unknown = [k for k in data if k not in ("aircraft", "channel")]
    if unknown:
        raise RecordingError(f"{name}: unknown key {unknown[0]!r}{suggest(unknown[0], ['aircraft', 'channel'])}; "
                             "expected [aircraft] and [[channel]] tables")
    aircraft = data.get("aircraft", {})
    if not isinstance(aircraft, dict) or not all(isinstance(v, str) and v.strip() for v in aircraft.values()):
        raise RecordingError(f"{name}: [aircraft] = {aircraft!r}: expected ac_id = \"copter name\" pairs")
    items = data.get("channel", [])
    if not isinstance(items, list) or not items:
        raise RecordingError(f"{name}: no [[channel]] entry; expected one per mapped field")
    allowed = {"channel", "message", "field", "unit", "yaw_deg", "sign"}
    entries, seen = [], {}
    for i, item in enumerate(items):
        where = f"{name}: [[channel]] #{i + 1}"
        if not isinstance(item, dict):
            raise RecordingError(f"{where} = {item!r}: expected a table")
        for k in item:
            if k not in allowed:
                raise RecordingError(f"{where}: unknown key {k!r}{suggest(k, allowed)}; allowed: "
                                     f"{', '.join(sorted(allowed))}")
        for k in ("channel", "message", "field", "unit"):
            if not isinstance(item.get(k), str) or not item[k].strip():
                raise RecordingError(f"{where}: {k} = {item.get(k)!r}: expected a non-empty string")
        ch = item["channel"]
        if ch not in ANALYSIS_CHANNELS:
            try:
                parse_channel(ch)
            except RecordingError as exc:
                raise RecordingError(f"{where}: {str(exc).removeprefix('readings: ')}; or one of the analysis channels "
                                     f"{', '.join(ANALYSIS_CHANNELS)}") from None
        dim = _dimension(ch)
        unit = item["unit"]
        if unit not in UNITS:
            raise RecordingError(f"{where}: unit = {unit!r}{suggest(unit, UNITS)}; expected one of {', '.join(UNITS)}")
        if UNITS[unit][0] != dim:
            raise RecordingError(f"{where}: unit = {unit!r} is a unit of {UNITS[unit][0]}, but channel {ch!r} is a "
                                 f"{dim} (in {_SI[dim]})")
        sign = item.get("sign", 1)
        if sign not in (1, -1) or isinstance(sign, bool):
            raise RecordingError(f"{where}: sign = {sign!r}: expected 1 or -1")
        is_sonar = ch.startswith("ultrasonic/")
        yaw = item.get("yaw_deg")
        if is_sonar and (isinstance(yaw, bool) or not isinstance(yaw, (int, float)) or not math.isfinite(yaw)):
            raise RecordingError(f"{where}: yaw_deg = {yaw!r}: an ultrasonic channel needs its mounting yaw in "
                                 "degrees (front 0, left 90)")
        if not is_sonar and yaw is not None:
            raise RecordingError(f"{where}: yaw_deg is only for ultrasonic channels, not {ch!r}")
        if ch in seen:
            raise RecordingError(f"{where}: channel {ch!r} is already filled by {seen[ch]}; expected each channel once")
        seen[ch] = f"[[channel]] #{i + 1}"
        entries.append(ChannelEntry(ch, item["message"], item["field"], unit, UNITS[unit][1] * sign,
                                    math.radians(yaw) if is_sonar else math.nan))
    sonar = sorted(parse_channel(e.channel).index for e in entries if e.channel.startswith("ultrasonic/"))
    if sonar != list(range(len(sonar))):
        raise RecordingError(f"{name}: ultrasonic channels {sonar}: expected ultrasonic/0 ... ultrasonic/"
                             f"{len(sonar) - 1} without gaps")
    return PaparazziMap(tuple(entries), {str(k).strip(): v.strip() for k, v in aircraft.items()}, name)


def check_map_against(pmap: PaparazziMap, protocol: Protocol) -> dict:
    """Each mapped message's layout, checked: every map message and field is in the protocol, and a unit the
    protocol names agrees with the map's. Returns message name -> :class:`Message`."""
    out = {}
    for e in pmap.entries:
        where = f"{pmap.source}: channel {e.channel!r}"
        msg = protocol.messages.get(e.message)
        if msg is None:
            raise RecordingError(f"{where}: message {e.message!r} is not in the protocol ({protocol.source})"
                                 f"{suggest(e.message, protocol.messages)}; give its layout with a messages.xml "
                                 "(--messages)")
        f = msg.fields[msg.index(e.field, where)]
        punit = f.unit.replace("^", "").lower()
        if punit in {u.replace("^", "") for u in UNITS} and punit != e.unit.replace("^", "").lower():
            raise RecordingError(f"{where}: the map says field {e.field!r} is in {e.unit!r}, the protocol "
                                 f"({protocol.source}) says {f.unit!r}; expected them to agree")
        out[e.message] = msg
    return out
