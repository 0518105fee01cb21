"""ROS 1 bags, ROS 2 bags and MCAP files in and out (the ``[import]`` extra: ``rosbags``, ``mcap``).

:func:`read_bag` maps the topics named in a topics file (:mod:`.topics`) to a :class:`~.recording.Recording`;
:func:`write_bag` writes a recording as a bag (for tests, and to try a topics file). Which reader: a directory is a
ROS 2 bag (SQLite or MCAP storage), a ``.bag`` file a ROS 1 bag — both through ``rosbags.highlevel.AnyReader`` — and
a ``.mcap`` file a plain MCAP file with ROS 2 (CDR) messages, read with ``mcap`` and decoded with the ``rosbags``
type system (types from the file's own schemas when they are not standard).

Times: a message's ``header.stamp`` (or, with ``time = "receive"`` or no header, the bag's receive time), in
seconds since the earliest stamp used, computed in integer nanoseconds (no float rounding at epoch scale); the
origin is in ``notes["time_origin_ns"]``. A ``sensor_msgs/Range`` reading of +inf means "nothing within range"
(REP 117) and is recorded as the message's ``max_range`` (−inf: ``min_range``), counted in the notes; nothing
else is changed. Messages of one stream that arrive out of stamp order are sorted (counted in the notes); a
repeated stamp stays an error of :func:`~.recording.check_recording`.
"""
from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from .recording import READING_COLUMNS, TRACKING_COLUMNS, Recording, RecordingError
from .topics import TopicsSpec, parse_topics

__all__ = ["read_bag", "write_bag", "BAG_KINDS"]

BAG_KINDS = ("rosbag1", "rosbag2", "rosbag2-mcap", "mcap")
"""Container kinds :func:`write_bag` writes: ROS 1 bag, ROS 2 bag (SQLite), ROS 2 bag in MCAP, plain MCAP."""
_TRACKING_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/TransformStamped", "nav_msgs/msg/Odometry")
_EXTRA = "reading bags needs the [import] extra: pip install 'finkensim[import]'"


def _typestore(ros1: bool = False):
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ImportError(f"{_EXTRA} ({exc})") from None
    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def _stamp_ns(msg):
    h = getattr(msg, "header", None)
    if h is None:
        return None
    s = h.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _field(msg, path: str, where: str):
    obj = msg
    for part in path.split("."):
        if not hasattr(obj, part):
            have = [f for f in getattr(obj, "__dataclass_fields__", {}) if not f.startswith("_")]
            raise RecordingError(f"{where}: message has no field {path!r} (at {part!r}; fields: {', '.join(have)})")
        obj = getattr(obj, part)
    try:
        return float(obj)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: field {path!r} is {type(obj).__name__}, not a number") from None


def _pose(msg, msgtype):
    """(x, y, yaw, z) of a tracking message."""
    if msgtype == "geometry_msgs/msg/TransformStamped":
        tr = msg.transform
        return tr.translation.x, tr.translation.y, _yaw(tr.rotation), tr.translation.z
    p = msg.pose.pose if msgtype == "nav_msgs/msg/Odometry" else msg.pose
    return p.position.x, p.position.y, _yaw(p.orientation), p.position.z


class _Collector:
    """Rows of the recording as lists, filled message by message (times in ns)."""

    def __init__(self, spec: TopicsSpec):
        self.spec = spec
        self.by_topic = spec.by_topic()
        self.track = defaultdict(list)
        self.read = defaultdict(list)
        self.counts = defaultdict(int)
        self.notes = defaultdict(int)

    def add(self, topic, msgtype, receive_ns, msg):
        e = self.by_topic[topic]
        where = f"topic {topic!r} ([[{e.role}]] of {e.copter!r})"
        stamp = _stamp_ns(msg) if e.time == "header" else None
        ns = stamp if stamp is not None else int(receive_ns)
        self.counts[topic] += 1
        if e.role == "tracking":
            if msgtype not in _TRACKING_TYPES:
                raise RecordingError(f"{where}: message type {msgtype}; expected one of {', '.join(_TRACKING_TYPES)}")
            x, y, yaw, z = _pose(msg, msgtype)
            for k, v in zip(TRACKING_COLUMNS, (ns, e.copter, x, y, yaw)):
                self.track[k].append(v)
            if e.height:
                self.track["z"].append(z)
            return
        if e.role == "imu":
            if msgtype != "sensor_msgs/msg/Imu":
                raise RecordingError(f"{where}: message type {msgtype}; expected sensor_msgs/msg/Imu")
            vals = (msg.linear_acceleration.x, msg.linear_acceleration.y, msg.angular_velocity.z)
            for ch, v in zip(e.channels, vals):
                self._reading(ns, e.copter, ch, float(v))
            return
        if e.field:
            v = _field(msg, e.field, where)
        elif msgtype == "sensor_msgs/msg/Range":
            v = float(msg.range)
            if math.isinf(v):  # REP 117: +inf nothing detected within range, -inf too close
                v = float(msg.max_range if v > 0 else msg.min_range)
                self.notes[f"{e.role}: +-inf Range readings recorded as max_range/min_range"] += 1
        elif msgtype in ("std_msgs/msg/Float64", "std_msgs/msg/Float32"):
            v = float(msg.data)
        else:
            raise RecordingError(f"{where}: message type {msgtype} has no known value field; add field = "
                                 "\"dotted.path\" to the entry")
        self._reading(ns, e.copter, e.channels[0], v * e.scale)

    def _reading(self, ns, copter, channel, value):
        for k, v in zip(READING_COLUMNS, (ns, copter, channel, value)):
            self.read[k].append(v)

    def recording(self, source: str) -> Recording:
        import pandas as pd

        missing = [e.topic for e in self.spec.entries if self.counts[e.topic] == 0]
        if missing:
            raise RecordingError(f"{source}: no messages on topic(s) {', '.join(map(repr, missing))} of the topics "
                                 "file")
        t_ns = np.asarray(self.track["t"], dtype=np.int64)
        r_ns = np.asarray(self.read["t"], dtype=np.int64)
        origin = int(min(t_ns.min(), r_ns.min() if r_ns.size else t_ns.min()))
        track = pd.DataFrame({**{k: self.track[k] for k in TRACKING_COLUMNS[1:]}, "t": (t_ns - origin) * 1e-9})
        read = pd.DataFrame({**{k: self.read[k] for k in READING_COLUMNS[1:]}, "t": (r_ns - origin) * 1e-9})
        out_of_order = 0
        for name, df, key in (("tracking", track, ["copter"]), ("readings", read, ["copter", "channel"])):
            if len(df):
                sorted_df = df.sort_values(key + ["t"], kind="stable")
                out_of_order += int((sorted_df.index.to_numpy() != np.sort(sorted_df.index.to_numpy())).sum())
        if self.track.get("z"):
            track["z"] = np.asarray(self.track["z"], dtype=np.float64)
        columns = list(TRACKING_COLUMNS) + (["z"] if "z" in track.columns else [])
        track = track.sort_values(["copter", "t"], kind="stable")[columns].reset_index(drop=True)
        read = read.sort_values(["copter", "channel", "t"], kind="stable")[list(READING_COLUMNS)].reset_index(drop=True)
        notes = {"topics_file": self.spec.source, "messages": dict(self.counts), "time_origin_ns": origin}
        notes.update({k: v for k, v in self.notes.items()})
        if out_of_order:
            notes["rows sorted by stamp (arrived out of order)"] = out_of_order
        return Recording(tracking=track, readings=read, source=source, notes=notes)


def _bag_kind(p: Path) -> str:
    if p.is_dir():
        return "rosbag2"
    if p.suffix == ".bag":
        return "rosbag1"
    if p.suffix == ".mcap":
        return "mcap"
    raise RecordingError(f"bag {str(p)!r}: expected a ROS 2 bag directory, a ROS 1 .bag file or an .mcap file")


def _present_topics_error(source, wanted, present):
    miss = sorted(set(wanted) - set(present))
    if miss:
        raise RecordingError(f"{source}: topic(s) {', '.join(map(repr, miss))} of the topics file are not in the bag; "
                             f"it has {', '.join(sorted(present)) or 'no topics'}")


def _open_rosbag(p: Path, source: str, kind: str):
    """An opened rosbags ``AnyReader`` of the ROS 1 / ROS 2 bag ``p`` (close it); a RecordingError naming ``source``
    when it cannot be read, an ImportError naming the extra when rosbags is missing."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError as exc:
        raise ImportError(f"{_EXTRA} ({exc})") from None
    try:
        reader = AnyReader([p], default_typestore=_typestore())
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own error types for unreadable bags
        raise RecordingError(f"{source}: cannot be read as a {kind} ({type(exc).__name__}: {exc})") from None
    return reader


def read_bag(path, topics) -> Recording:
    """The :class:`~.recording.Recording` of the topics named in ``topics`` (a topics TOML path/text, dict or
    :class:`~.topics.TopicsSpec`) in the ROS 1 / ROS 2 bag or MCAP file at ``path`` (module doc)."""
    spec = parse_topics(topics)
    p = Path(path)
    if not p.exists():
        raise RecordingError(f"bag {str(p)!r} does not exist")
    kind = _bag_kind(p)
    source = f"{kind}:{p.name}"
    col = _Collector(spec)
    wanted = list(spec.by_topic())
    if kind == "mcap":
        _read_mcap(p, wanted, col, source)
    else:
        reader = _open_rosbag(p, source, kind)
        try:
            present = {c.topic: c.msgtype for c in reader.connections}
            _present_topics_error(source, wanted, present)
            conns = [c for c in reader.connections if c.topic in spec.by_topic()]
            count, topic = 0, None
            try:
                for conn, timestamp, raw in reader.messages(connections=conns):
                    topic = conn.topic
                    msg = reader.deserialize(raw, conn.msgtype)
                    count += 1
                    col.add(conn.topic, conn.msgtype, timestamp, msg)
            except RecordingError:
                raise
            except Exception as exc:  # noqa: BLE001 - rosbags' ReaderError, SerdeError, ... for a corrupt message
                raise _corrupt(source, count, topic, exc) from None
        finally:
            reader.close()
    return col.recording(source)


def list_topics(path) -> dict[str, int]:
    """Topic -> message count of the bag or MCAP file at ``path`` (what ``finkensim check`` shows); a file that
    cannot be read raises RecordingError, a missing [import] extra ImportError."""
    p = Path(path)
    kind = _bag_kind(p)
    source = f"{kind}:{p.name}"
    if kind == "mcap":
        from mcap.reader import make_reader

        with open(p, "rb") as f:
            try:
                summary = make_reader(f).get_summary()
            except Exception as exc:  # noqa: BLE001 - mcap raises its own error types for broken files
                raise RecordingError(f"{source}: cannot be read as MCAP ({type(exc).__name__}: {exc})") from None
            if summary is None:
                raise RecordingError(f"{source}: the MCAP file has no summary (truncated?); re-record or repair it")
            counts = summary.statistics.channel_message_counts if summary.statistics else {}
            return {c.topic: int(counts.get(cid, 0)) for cid, c in summary.channels.items()}
    reader = _open_rosbag(p, source, kind)
    try:
        out: dict[str, int] = {}
        for c in reader.connections:
            out[c.topic] = out.get(c.topic, 0) + int(c.msgcount)
        return out
    finally:
        reader.close()


def _read_mcap(p: Path, wanted, col: _Collector, source: str) -> None:
    try:
        from mcap.reader import make_reader
        from rosbags.typesys import get_types_from_msg
    except ImportError as exc:
        raise ImportError(f"{_EXTRA} ({exc})") from None
    ts = _typestore()
    with open(p, "rb") as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
        except Exception as exc:  # noqa: BLE001 - mcap raises its own error types for broken files
            raise RecordingError(f"{source}: cannot be read as MCAP ({type(exc).__name__}: {exc})") from None
        present = [c.topic for c in summary.channels.values()] if summary else []
        _present_topics_error(source, wanted, present)
        count, topic = 0, None
        try:
            for schema, channel, message in reader.iter_messages(topics=wanted):
                topic = channel.topic
                if schema is None or schema.encoding != "ros2msg" or channel.message_encoding != "cdr":
                    raise RecordingError(f"{source}: topic {channel.topic!r} is encoded as "
                                         f"{channel.message_encoding!r} with schema encoding "
                                         f"{getattr(schema, 'encoding', None)!r}; expected ROS 2 messages (cdr, ros2msg)")
                if schema.name not in ts.types:
                    ts.register(get_types_from_msg(schema.data.decode(), schema.name))
                msg = ts.deserialize_cdr(message.data, schema.name)
                count += 1
                col.add(channel.topic, schema.name, message.log_time, msg)
        except RecordingError:
            raise
        except Exception as exc:  # noqa: BLE001 - mcap / rosbags errors for a corrupt record or message
            raise _corrupt(source, count, topic, exc) from None


def _corrupt(source: str, count: int, topic, exc: BaseException) -> RecordingError:
    """The error for a message that cannot be read after ``count`` good ones (last topic ``topic``)."""
    first = (str(exc).strip().splitlines() or [""])[0]
    return RecordingError(f"{source}: message {count + 1} (after {count} readable, last topic {topic!r}) cannot be "
                          f"read ({type(exc).__name__}: {first}); the file is corrupt or truncated: re-record or "
                          "repair it")


# ------------------------------------------------------------------------------------------------ writing

def _messages(rec: Recording, ts, epoch_ns: int, ros1: bool):
    """(receive ns, topic, msgtype, message) of every row of a recording, and the topics dict."""
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Vec3, Quat, Point = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Point"]
    has_seq = "seq" in Header.__dataclass_fields__

    def header(ns):
        stamp = Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))
        return Header(seq=0, stamp=stamp, frame_id="arena") if has_seq else Header(stamp=stamp, frame_id="arena")

    def nsec(t):
        return epoch_ns + int(round(float(t) * 1e9))

    out, topics = [], defaultdict(list)
    tr = rec.tracking
    with_z = "z" in tr.columns
    for c in dict.fromkeys(tr["copter"]):
        topic = f"/{c}/pose"
        topics["tracking"].append({"topic": topic, "copter": c, **({"height": True} if with_z else {})})
    zs = tr["z"].to_numpy(dtype=np.float64) if with_z else np.zeros(len(tr))
    for (t, c, x, y, yaw), z in zip(tr[list(TRACKING_COLUMNS)].itertuples(index=False), zs):
        ns = nsec(t)
        pose = T["geometry_msgs/msg/Pose"](position=Point(x=float(x), y=float(y), z=float(z)),
                                           orientation=Quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))
        out.append((ns, f"/{c}/pose", "geometry_msgs/msg/PoseStamped",
                    T["geometry_msgs/msg/PoseStamped"](header=header(ns), pose=pose)))
    rd = rec.readings
    imu = defaultdict(dict)
    for t, c, ch, v in rd[list(READING_COLUMNS)].itertuples(index=False):
        ns = nsec(t)
        if ch.startswith("ultrasonic/"):
            topic = f"/{c}/{ch}"
            msg = T["sensor_msgs/msg/Range"](header=header(ns), radiation_type=0, field_of_view=0.5, min_range=0.0,
                                             max_range=float("inf"), range=float(v))
            out.append((ns, topic, "sensor_msgs/msg/Range", msg))
            entry = {"topic": topic, "copter": c, "index": int(ch.split("/")[1])}
            if entry not in topics["ultrasonic"]:
                topics["ultrasonic"].append(entry)
        elif ch.startswith("ranging/"):
            topic = f"/{c}/{ch}"
            out.append((ns, topic, "std_msgs/msg/Float64", T["std_msgs/msg/Float64"](data=float(v))))
            entry = {"topic": topic, "copter": c, "other": ch.split("/", 1)[1]}
            if entry not in topics["ranging"]:
                topics["ranging"].append(entry)
        else:
            imu[(c, ns)][ch] = float(v)
    for (c, ns), vals in imu.items():
        acc = Vec3(x=vals.get("imu/acc_x", math.nan), y=vals.get("imu/acc_y", math.nan), z=0.0)
        gyro = Vec3(x=0.0, y=0.0, z=vals.get("imu/gyro", math.nan))
        msg = T["sensor_msgs/msg/Imu"](header=header(ns), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0),
                                       orientation_covariance=np.zeros(9), angular_velocity=gyro,
                                       angular_velocity_covariance=np.zeros(9), linear_acceleration=acc,
                                       linear_acceleration_covariance=np.zeros(9))
        out.append((ns, f"/{c}/imu", "sensor_msgs/msg/Imu", msg))
        entry = {"topic": f"/{c}/imu", "copter": c}
        if entry not in topics["imu"]:
            topics["imu"].append(entry)
    out.sort(key=lambda m: m[0])
    return out, dict(topics)


def _topics_toml(topics: dict) -> str:
    lines = []
    for role in ("tracking", "ultrasonic", "ranging", "imu"):
        for e in topics.get(role, []):
            lines.append(f"[[{role}]]")
            lines += [f"{k} = {str(v).lower()}" if isinstance(v, bool) else f"{k} = {v!r}" if isinstance(v, int)
                      else f'{k} = "{v}"' for k, v in e.items()]
            lines.append("")
    return "\n".join(lines)


def write_bag(rec: Recording, path, kind: str = "rosbag2", epoch: float = 1.7e9) -> str:
    """Write a recording as a bag of ``kind`` (one of :data:`BAG_KINDS`) at ``path`` and return the text of the
    topics file that reads it back. Times are stamped ``epoch + t`` (s since 1970; a bag has no negative times):
    tracking as ``geometry_msgs/PoseStamped`` on ``/<copter>/pose``, sonars as ``sensor_msgs/Range`` on
    ``/<copter>/ultrasonic/<i>``, ranging as ``std_msgs/Float64`` on ``/<copter>/ranging/<other>`` (no header: the
    receive time is the reading's time), IMU channels at one time as one ``sensor_msgs/Imu`` on ``/<copter>/imu``."""
    if kind not in BAG_KINDS:
        raise RecordingError(f"kind = {kind!r}: expected one of {', '.join(BAG_KINDS)}")
    ros1 = kind == "rosbag1"
    ts = _typestore(ros1)
    msgs, topics = _messages(rec, ts, int(round(epoch)) * 1_000_000_000, ros1)
    p = Path(path)
    if kind == "mcap":
        from mcap.writer import Writer as McapWriter

        with open(p, "wb") as f:
            w = McapWriter(f)
            w.start(profile="ros2", library="finkensim")
            schemas, channels = {}, {}
            for ns, topic, msgtype, msg in msgs:
                if msgtype not in schemas:
                    schemas[msgtype] = w.register_schema(name=msgtype, encoding="ros2msg",
                                                         data=ts.generate_msgdef(msgtype, ros_version=2)[0].encode())
                if topic not in channels:
                    channels[topic] = w.register_channel(topic=topic, message_encoding="cdr",
                                                         schema_id=schemas[msgtype])
                w.add_message(channel_id=channels[topic], log_time=ns, publish_time=ns,
                              data=bytes(ts.serialize_cdr(msg, msgtype)))
            w.finish()
    elif ros1:
        from rosbags.rosbag1 import Writer

        with Writer(p) as w:
            conns = {}
            for ns, topic, msgtype, msg in msgs:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
                w.write(conns[topic], ns, ts.serialize_ros1(msg, msgtype))
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if kind == "rosbag2-mcap" else StoragePlugin.SQLITE3
        with Writer(p, version=9, storage_plugin=plugin) as w:
            conns = {}
            for ns, topic, msgtype, msg in msgs:
                if topic not in conns:
                    conns[topic] = w.add_connection(topic, msgtype, typestore=ts)
                w.write(conns[topic], ns, ts.serialize_cdr(msg, msgtype))
    return _topics_toml(topics)
