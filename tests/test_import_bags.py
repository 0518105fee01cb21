"""ROS 1 / ROS 2 bags and MCAP (finkensim.importing.bags, .topics): bags written with ``rosbags`` / ``mcap`` read back
to the same recording; every topics-file and bag mistake gets a named error; and from the CLI, a simulated flight
exported asynchronously imports from each bag kind to the same flight log as from CSV, and (ROS 2, auto offset)
diagnoses with no significant gap."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.importing import Recording, RecordingError, to_recording, write_csv
from finkensim.importing.bags import BAG_KINDS, read_bag, write_bag
from finkensim.importing.topics import parse_topics
from tests.stats import assert_within_se

FILE = {"rosbag1": "f.bag", "rosbag2": "bag2", "rosbag2-mcap": "bag2m", "mcap": "f.mcap"}


def small_recording(seed=0, n_copters=2):
    rng = np.random.default_rng(seed)
    ids = [f"cf{c + 1}" for c in range(n_copters)]
    tr = pd.concat([pd.DataFrame({"t": np.arange(40) * 0.01 - 0.2 + 0.003 * c, "copter": ids[c],
                                  "x": rng.uniform(0, 3, 40), "y": rng.uniform(0, 4, 40),
                                  "yaw": rng.uniform(-3, 3, 40)}) for c in range(n_copters)], ignore_index=True)
    rows = []
    for c in ids:
        others = [f"ranging/{o}" for o in ids if o != c]
        for ch in ["ultrasonic/0", "ultrasonic/1"] + others:
            t = np.unique(rng.uniform(-0.3, 0.4, 7))
            rows += [(ti, c, ch, v) for ti, v in zip(t, rng.uniform(0.1, 3, t.size))]
        t = np.arange(5) * 0.02 + 0.001
        for ch in ("imu/acc_x", "imu/acc_y", "imu/gyro"):
            rows += [(ti, c, ch, v) for ti, v in zip(t, rng.normal(size=5))]
    return Recording(tr, pd.DataFrame(rows, columns=["t", "copter", "channel", "value"]), "test")


def same_recording(back: Recording, rec: Recording):
    """The tables of a bag read back equal the input, times shifted to the earliest one (integer ns), sonar values
    to float32 (sensor_msgs/Range stores float32)."""
    origin = min(rec.tracking.t.min(), rec.readings.t.min())
    for got, want, key in ((back.tracking, rec.tracking, ["copter", "t"]),
                           (back.readings, rec.readings, ["copter", "channel", "t"])):
        got = got.sort_values(key).reset_index(drop=True)
        want = want.assign(t=want.t - origin).sort_values(key).reset_index(drop=True)
        assert len(got) == len(want)
        assert (got.copter == want.copter).all()
        np.testing.assert_allclose(got.t, want.t, atol=2e-9, rtol=0)
        if "channel" in key:
            assert (got.channel == want.channel).all()
            sonar = got.channel.str.startswith("ultrasonic/").to_numpy()
            np.testing.assert_array_equal(got.value[~sonar], want.value[~sonar])
            np.testing.assert_allclose(got.value[sonar], want.value[sonar].astype(np.float32), rtol=0, atol=0)
        else:
            np.testing.assert_array_equal(got[["x", "y"]].to_numpy(), want[["x", "y"]].to_numpy())
            np.testing.assert_allclose(got.yaw, want.yaw, atol=1e-12)


@pytest.mark.parametrize("kind", BAG_KINDS)
def test_each_bag_kind_reads_back_what_was_written(tmp_path, kind):
    rec = small_recording()
    topics = write_bag(rec, tmp_path / FILE[kind], kind)
    back = read_bag(tmp_path / FILE[kind], topics)
    same_recording(back, rec)
    assert back.notes["messages"]["/cf1/pose"] == 40


def test_heights_round_trip_through_a_bag(tmp_path):
    """A tracking with a z column goes into position.z with height = true in the topics file, and comes back."""
    rec = small_recording()
    rec = Recording(rec.tracking.assign(z=np.linspace(0.4, 1.8, len(rec.tracking))), rec.readings, "test")
    topics = write_bag(rec, tmp_path / "bag2", "rosbag2")
    assert "height = true" in topics
    back = read_bag(tmp_path / "bag2", topics)
    want = rec.tracking.sort_values(["copter", "t"]).reset_index(drop=True)
    np.testing.assert_array_equal(back.tracking.sort_values(["copter", "t"]).z.to_numpy(), want.z.to_numpy())
    mixed = topics.replace("height = true", "height = false", 1)
    with pytest.raises(RecordingError, match="height = true on some"):
        read_bag(tmp_path / "bag2", mixed)


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 3))
def test_rosbag2_round_trip_property(tmp_path_factory, seed, n):
    rec = small_recording(seed, n)
    path = tmp_path_factory.mktemp("bag") / "b"
    same_recording(read_bag(path, write_bag(rec, path, "rosbag2")), rec)


@pytest.fixture(scope="module")
def bag2(tmp_path_factory):
    path = tmp_path_factory.mktemp("bags") / "b"
    return path, write_bag(small_recording(), path, "rosbag2")


def test_topic_missing_from_the_bag_lists_what_is_there(bag2):
    path, topics = bag2
    with pytest.raises(RecordingError, match=r"'/cf9/pose' of the topics file are not in the bag; it has /cf1/imu"):
        read_bag(path, topics + '[[tracking]]\ntopic = "/cf9/pose"\ncopter = "cf9"\n')


def test_wrong_message_type_for_the_role(bag2):
    path, _ = bag2
    spec = '[[tracking]]\ntopic = "/cf1/ranging/cf2"\ncopter = "cf1"\n'
    with pytest.raises(RecordingError, match=r"topic '/cf1/ranging/cf2' \(\[\[tracking\]\] of 'cf1'\): message type "
                                             r"std_msgs/msg/Float64; expected one of geometry_msgs/msg/PoseStamped"):
        read_bag(path, spec)


def test_field_not_found_and_receive_time(bag2):
    path, _ = bag2
    spec = ('[[tracking]]\ntopic = "/cf1/pose"\ncopter = "cf1"\n[[ranging]]\ntopic = "/cf1/ranging/cf2"\n'
            'copter = "cf1"\nother = "cf2"\nfield = "value"\n')
    with pytest.raises(RecordingError, match=r"message has no field 'value' \(at 'value'; fields: data\)"):
        read_bag(path, spec)
    spec = ('time = "receive"\n[[tracking]]\ntopic = "/cf1/pose"\ncopter = "cf1"\n[[ranging]]\n'
            'topic = "/cf1/ranging/cf2"\ncopter = "cf1"\nother = "cf2"\nfield = "data"\nscale = 2.0\n')
    back = read_bag(path, spec)
    rec = small_recording()
    want = rec.readings[(rec.readings.copter == "cf1") & (rec.readings.channel == "ranging/cf2")]
    np.testing.assert_array_equal(np.sort(back.readings.value), np.sort(2.0 * want.value))


@pytest.mark.parametrize("text, match", [
    ('[[trackng]]\ntopic = "/a"\ncopter = "a"\n', r"unknown key 'trackng' \(did you mean 'tracking'\?\)"),
    ('[[tracking]]\ntopic = "/a"\n', r"\[\[tracking\]\] #1: missing key 'copter'"),
    ('[[tracking]]\ntopic = "/a"\ncopter = "a"\n[[ultrasonic]]\ntopic = "/s"\ncopter = "a"\nindx = 0\n',
     r"unknown key 'indx' \(did you mean 'index'\?\)"),
    ('[[tracking]]\ntopic = "/a"\ncopter = "a"\n[[ultrasonic]]\ntopic = "/s"\ncopter = "a"\nindex = -1\n',
     r"index = -1: expected a sonar index"),
    ('[[tracking]]\ntopic = "/a"\ncopter = "a"\n[[ultrasonic]]\ntopic = "/s"\ncopter = "a"\nindex = 0\n'
     '[[ultrasonic]]\ntopic = "/t"\ncopter = "a"\nindex = 0\n', r"channel 'ultrasonic/0' is already filled"),
    ('[[tracking]]\ntopic = "/a"\ncopter = "a"\n[[imu]]\ntopic = "/a"\ncopter = "b"\n', r"topic '/a' is already mapped"),
    ('[[tracking]]\ntopic = "/a"\ncopter = "a"\ntime = "now"\n', r"time = 'now': expected 'header' or 'receive'"),
    ('[[ranging]]\ntopic = "/r"\ncopter = "a"\nother = "b"\n', r"no \[\[tracking\]\] entry"),
    ('[[tracking]]\ntopic = "/a"\ncopter = "a"\n[[ranging]]\ntopic = "/r"\ncopter = "a"\nother = "b"\nscale = 0\n',
     r"scale = 0: expected a finite non-zero number"),
    ("[[tracking]\n", r"not valid TOML"),
])
def test_topics_file_errors(text, match):
    with pytest.raises(RecordingError, match=match):
        parse_topics(text)


def test_infinite_range_is_the_max_range(tmp_path):
    """REP 117: +inf = nothing within range; recorded as the message's max_range, counted in the notes."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    path = tmp_path / "b"
    with Writer(path, version=9) as w:
        cp = w.add_connection("/a/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
        cs = w.add_connection("/a/sonar", "sensor_msgs/msg/Range", typestore=ts)
        for k, r in enumerate([1.0, float("inf"), 2.0]):
            ns = 10**18 + k * 10**7
            hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                           frame_id="")
            pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=1.0, y=1.0, z=0.0),
                                               orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
            w.write(cp, ns, ts.serialize_cdr(T["geometry_msgs/msg/PoseStamped"](header=hdr, pose=pose),
                                             "geometry_msgs/msg/PoseStamped"))
            rng_msg = T["sensor_msgs/msg/Range"](header=hdr, radiation_type=0, field_of_view=0.5, min_range=0.02,
                                                 max_range=3.5, range=r)
            w.write(cs, ns, ts.serialize_cdr(rng_msg, "sensor_msgs/msg/Range"))
    rec = read_bag(path, '[[tracking]]\ntopic = "/a/pose"\ncopter = "a"\n[[ultrasonic]]\ntopic = "/a/sonar"\n'
                         'copter = "a"\nindex = 0\n')
    assert rec.readings.value.tolist() == [1.0, 3.5, 2.0]
    assert rec.notes["ultrasonic: +-inf Range readings recorded as max_range/min_range"] == 1


def test_not_a_bag_and_missing_extra(tmp_path, monkeypatch):
    with pytest.raises(RecordingError, match="expected a ROS 2 bag directory, a ROS 1 .bag file or an .mcap file"):
        (tmp_path / "x.txt").write_text("hi")
        read_bag(tmp_path / "x.txt", '[[tracking]]\ntopic = "/a"\ncopter = "a"\n')
    (tmp_path / "broken.mcap").write_bytes(b"not an mcap file")
    with pytest.raises(RecordingError, match="cannot be read as MCAP"):
        read_bag(tmp_path / "broken.mcap", '[[tracking]]\ntopic = "/a"\ncopter = "a"\n')
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    (tmp_path / "b").mkdir()
    with pytest.raises(ImportError, match=r"pip install 'finkensim\[import\]'"):
        read_bag(tmp_path / "b", '[[tracking]]\ntopic = "/a"\ncopter = "a"\n')


# ------------------------------------------------------------------------------- from the CLI, every format

@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    import finkensim as fs

    cfg = fs.load_config({"simulation": {"dt": 0.01}, "sonar": {"crosstalk": "off"}})
    log, _, _ = fs.simulate_flight(cfg, duration=20.0, seed=5)
    rec = to_recording(log, clock_offset=0.3, seed=2)
    d = tmp_path_factory.mktemp("exported")
    write_csv(rec, d / "track.csv", d / "read.csv")
    (d / "scenario.toml").write_text("[simulation]\ndt = 0.01\n[sonar]\ncrosstalk = \"off\"\n")
    return cfg, log, rec, d


def _cli(log, d, source_args, out, offset="0.3"):
    cmd = [sys.executable, "-m", "finkensim.cli", "import", *source_args, "--arena", "3,4", "--sonar-yaw-deg",
           "0,90,180,-90", "--sonar-offset", str(log.ultrasonic_offset), "--copter-radius",
           str(log.meta["copter_radius"]), "--clock-offset", offset, "--config", str(d / "scenario.toml"),
           "--out", str(out)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    from finkensim.flightlog import load

    return load(out)


@pytest.fixture(scope="module")
def from_csv(exported):
    """The exported flight imported from its CSV files (once: every format is compared with it)."""
    _, log, _, d = exported
    return _cli(log, d, ["--tracking", str(d / "track.csv"), "--readings", str(d / "read.csv")], d / "csv.npz")


@pytest.mark.parametrize("kind", BAG_KINDS)
def test_every_format_imports_to_the_csv_flight(exported, from_csv, kind):
    _, log, rec, d = exported
    bag = d / FILE[kind]
    if not bag.exists():
        (d / f"{kind}.toml").write_text(write_bag(rec, bag, kind))
    from_bag = _cli(log, d, ["--bag", str(bag), "--topics", str(d / f"{kind}.toml")], d / f"{kind}.npz")
    assert from_bag.n_steps == from_csv.n_steps
    np.testing.assert_allclose(from_bag.t - from_bag.t[0], from_csv.t - from_csv.t[0], atol=1e-9)
    np.testing.assert_allclose(from_bag.pose, from_csv.pose, atol=1e-9)
    np.testing.assert_array_equal(np.isnan(from_bag.ultrasonic), np.isnan(from_csv.ultrasonic))
    np.testing.assert_allclose(from_bag.ultrasonic, from_csv.ultrasonic.astype(np.float32), rtol=0, atol=0)
    np.testing.assert_array_equal(from_bag.ranging, from_csv.ranging)
    np.testing.assert_array_equal(from_bag.imu_gyro, from_csv.imu_gyro)
    auto = _cli(log, d, ["--bag", str(bag), "--topics", str(d / f"{kind}.toml")], d / f"{kind}-auto.npz", offset="auto")
    c = auto.meta["import"]["clock_offset"]
    assert abs(c["seconds"] - 0.3) < 0.05  # within one sonar sample: docs/user-guide/import.md's claim
    # and within 5 of its own standard errors (the importer's bootstrap SD of the loss minimum)
    assert_within_se(c["seconds"], 0.3, c["uncertainty"], what=f"auto clock offset from a {kind} bag (s)")


def test_rosbag2_cli_auto_offset_diagnoses_clean(exported):
    import finkensim as fs

    cfg, log, rec, d = exported
    bag = d / "auto-bag2"
    (d / "auto.toml").write_text(write_bag(rec, bag, "rosbag2"))
    flight = _cli(log, d, ["--bag", str(bag), "--topics", str(d / "auto.toml")], d / "auto.npz", offset="auto")
    c = flight.meta["import"]["clock_offset"]
    assert abs(c["seconds"] - 0.3) < 0.05  # within one sonar sample
    assert_within_se(c["seconds"], 0.3, c["uncertainty"], what="auto clock offset from a rosbag2 (s)")
    verdict = fs.diagnose([flight], ["bag"], cfg).to_spec()["verdict"]
    assert not verdict["significant_gap"], verdict


def test_example_topics_file_parses():
    from pathlib import Path

    spec = parse_topics(Path(__file__).resolve().parent.parent / "examples" / "topics.toml")
    by = {e.topic: e for e in spec.entries}
    assert by["/cf2/uwb"].scale == 0.001 and by["/cf2/uwb"].time == "receive" and by["/cf2/uwb"].field == "distance_mm"
    assert by["/cf1/sonar/left"].channels == ("ultrasonic/1",)
