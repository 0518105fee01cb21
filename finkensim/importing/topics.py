"""The topics file: which bag topic is which copter's tracking or sensor channel.

A small TOML file, one array of tables per role::

    time = "header"              # optional default for every entry: "header" (message stamp) or "receive" (bag time)

    [[tracking]]                 # geometry_msgs/PoseStamped, TransformStamped or nav_msgs/Odometry
    topic = "/vicon/cf1/pose"
    copter = "cf1"
    height = true                # optional: position.z is the copter's height (m; then on every tracking entry)

    [[ultrasonic]]               # sensor_msgs/Range (or any message with `field`)
    topic = "/cf1/sonar/front"
    copter = "cf1"
    index = 0                    # ultrasonic/<index>: position in --sonar-yaw-deg

    [[ranging]]                  # std_msgs/Float64 or Float32, sensor_msgs/Range (or any message with `field`)
    topic = "/cf1/ranging/cf2"
    copter = "cf1"               # the measuring copter
    other = "cf2"                # the copter it measures

    [[imu]]                      # sensor_msgs/Imu: linear_acceleration.x/.y -> imu/acc_x, imu/acc_y; angular_velocity.z -> imu/gyro
    topic = "/cf1/imu"
    copter = "cf1"

Optional keys of every entry: ``time`` ("header" or "receive"; a message without a header always uses the bag's
receive time), ``field`` (dotted path of the float to read, e.g. ``"range"`` or ``"data"``; for a custom message),
``scale`` (a factor applied to the value, for explicit unit conversion, e.g. 0.001 for millimetres; default 1).
Tracking frames: x, y in metres in the arena frame (origin at a corner), yaw from the orientation quaternion
(rotation about z, counter-clockwise from +x). Every mistake is a :class:`~.recording.RecordingError` naming the
entry and key.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..usertext import suggest
from .recording import RecordingError

__all__ = ["TopicEntry", "TopicsSpec", "parse_topics", "ROLES"]

ROLES = ("tracking", "ultrasonic", "ranging", "imu")
_KEYS = {"tracking": {"topic", "copter", "time", "height"}, "ultrasonic": {"topic", "copter", "index", "time", "field", "scale"},
         "ranging": {"topic", "copter", "other", "time", "field", "scale"}, "imu": {"topic", "copter", "time"}}
_REQUIRED = {"tracking": ("topic", "copter"), "ultrasonic": ("topic", "copter", "index"),
             "ranging": ("topic", "copter", "other"), "imu": ("topic", "copter")}


@dataclass(frozen=True)
class TopicEntry:
    """One mapped topic: role (tracking, ultrasonic, ranging, imu), topic, copter, index (ultrasonic), other
    (ranging), time ("header" or "receive"), field (dotted path or ""), scale; height (tracking: position.z is the
    height in m)."""

    role: str
    topic: str
    copter: str
    index: int = -1
    other: str = ""
    time: str = "header"
    field: str = ""
    scale: float = 1.0
    height: bool = False

    @property
    def channels(self) -> tuple[str, ...]:
        """The finkensim channels this topic fills (none for tracking)."""
        if self.role == "ultrasonic":
            return (f"ultrasonic/{self.index}",)
        if self.role == "ranging":
            return (f"ranging/{self.other}",)
        if self.role == "imu":
            return ("imu/acc_x", "imu/acc_y", "imu/gyro")
        return ()


@dataclass(frozen=True)
class TopicsSpec:
    """All entries of a topics file; ``source`` names the file (or "topics")."""

    entries: tuple
    source: str = "topics"

    def by_topic(self) -> dict:
        return {e.topic: e for e in self.entries}


def parse_topics(source) -> TopicsSpec:
    """A :class:`TopicsSpec` from a topics TOML path, TOML text, a parsed dict, or a TopicsSpec (module doc)."""
    if isinstance(source, TopicsSpec):
        return source
    name = "topics"
    if isinstance(source, dict):
        data = source
    else:
        text = None
        if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source and "=" not in source):
            p = Path(source)
            if not p.is_file():
                raise RecordingError(f"topics file {str(p)!r} " + ("is not a file" if p.exists() else "does not exist"))
            name, text = str(p), p.read_text()
        else:
            text = str(source)
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise RecordingError(f"{name}: not valid TOML ({exc})") from None
    default_time = data.get("time", "header")
    unknown = [k for k in data if k not in ROLES and k != "time"]
    if unknown:
        raise RecordingError(f"{name}: unknown key {unknown[0]!r}{suggest(unknown[0], ROLES + ('time',))}; expected "
                             f"[[tracking]], [[ultrasonic]], [[ranging]], [[imu]] and optionally time")
    entries, seen_topics, seen_channels = [], {}, {}
    for role in ROLES:
        items = data.get(role, [])
        if isinstance(items, dict):
            items = [items]
        if not isinstance(items, list):
            raise RecordingError(f"{name}: {role} = {items!r}: expected [[{role}]] tables")
        for i, item in enumerate(items):
            where = f"{name}: [[{role}]] #{i + 1}"
            if not isinstance(item, dict):
                raise RecordingError(f"{where} = {item!r}: expected a table")
            for k in item:
                if k not in _KEYS[role]:
                    raise RecordingError(f"{where}: unknown key {k!r}{suggest(k, _KEYS[role])}; allowed: "
                                         f"{', '.join(sorted(_KEYS[role]))}")
            for k in _REQUIRED[role]:
                if k not in item:
                    raise RecordingError(f"{where}: missing key {k!r} (needs {', '.join(_REQUIRED[role])})")
            for k in ("topic", "copter", "other", "field"):
                if k in item and (not isinstance(item[k], str) or not item[k].strip()):
                    raise RecordingError(f"{where}: {k} = {item[k]!r}: expected a non-empty string")
            time = item.get("time", default_time)
            if time not in ("header", "receive"):
                raise RecordingError(f"{where}: time = {time!r}: expected 'header' or 'receive'")
            index = item.get("index", -1)
            if role == "ultrasonic" and (isinstance(index, bool) or not isinstance(index, int) or index < 0):
                raise RecordingError(f"{where}: index = {index!r}: expected a sonar index 0, 1, 2, ...")
            scale = item.get("scale", 1.0)
            if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale == 0:
                raise RecordingError(f"{where}: scale = {scale!r}: expected a finite non-zero number")
            height = item.get("height", False)
            if not isinstance(height, bool):
                raise RecordingError(f"{where}: height = {height!r}: expected true or false")
            e = TopicEntry(role=role, topic=item["topic"], copter=item["copter"], index=index,
                           other=item.get("other", ""), time=time, field=item.get("field", ""), scale=float(scale),
                           height=height)
            if e.topic in seen_topics:
                raise RecordingError(f"{where}: topic {e.topic!r} is already mapped by {seen_topics[e.topic]}; "
                                     "expected each topic once")
            seen_topics[e.topic] = f"[[{role}]] #{i + 1}"
            for c in e.channels or (f"tracking of {e.copter}",):
                key = (e.copter, c)
                if key in seen_channels:
                    raise RecordingError(f"{where}: copter {e.copter!r} channel {c!r} is already filled by "
                                         f"{seen_channels[key]}; expected one topic per copter and channel")
                seen_channels[key] = f"topic {e.topic!r}"
            entries.append(e)
    if not any(e.role == "tracking" for e in entries):
        raise RecordingError(f"{name}: no [[tracking]] entry; expected one per copter (the diagnosis needs poses)")
    heights = {e.height for e in entries if e.role == "tracking"}
    if len(heights) > 1:
        raise RecordingError(f"{name}: height = true on some [[tracking]] entries but not on others; expected it on "
                             "every tracking entry or on none (a height per copter, or planar tracking)")
    return TopicsSpec(entries=tuple(entries), source=name)
