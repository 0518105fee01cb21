"""finkensim.importing.read_paparazzi: the FINken's Paparazzi telemetry (.data + .log).

The real 2015 log of FINken3_01 (``../shared/realdata/finken_paparazzi_2015-12-16/`` or ``$FINKENSIM_DATA``; the
tests that need it skip, naming the folder, when it is absent), a simulated flight written as Paparazzi telemetry
and read back equal (several ac_ids → several copters; merged with a tracking CSV through the clock offset), a named
error with the line for every kind of corrupted ``.data`` line, map mistakes, and a sensor-only recording refused as
a flight log with what to add.
"""
from __future__ import annotations

import gzip
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from finkensim.importing import (RecordingError, build_flight, read_csv, read_map, read_paparazzi, read_protocol,
                                 to_recording, write_csv, write_paparazzi)
from finkensim.importing.paparazzi_protocol import DEFAULT_MAP

REAL = "finken_paparazzi_2015-12-16"
STEM = "15_12_16__13_55_00"
FIELDS = (["distance_d_front", "distance_d_rigth", "distance_d_left", "distance_d_back"]
          + "pos_x pos_y pos_z pos_pitch pos_roll pos_yaw velocity_x velocity_y velocity_z velocity_pitch "
            "velocity_roll velocity_yaw acceleration_x acceleration_y acceleration_z".split())
#: the published FINKEN_SENSOR_MODEL layout (19 fields; sonar distances int16 cm)
PROTOCOL = ('<protocol><msg_class name="telemetry"><message name="FINKEN_SENSOR_MODEL" id="217">'
            + "".join(f'<field name="{f}" type="{"int16" if i < 4 else "float"}"{" unit=%r" % "cm" if i < 4 else ""}/>'
                      for i, f in enumerate(FIELDS)).replace("'", '"')
            + '</message><message name="ALIVE" id="2"><field name="md5sum" type="uint8[]"/></message>'
              "</msg_class></protocol>")


def realdata_dir() -> Path | None:
    """The folder of real recordings: $FINKENSIM_DATA, else ../shared/realdata next to the repository."""
    env = os.environ.get("FINKENSIM_DATA")
    cands = [Path(env)] if env else []
    cands.append(Path(__file__).resolve().parents[1].parent / "shared" / "realdata")
    for c in cands:
        if (c / REAL).is_dir():
            return c / REAL
    return None


@pytest.fixture(scope="module")
def real():
    d = realdata_dir()
    if d is None:
        pytest.skip(f"the real FINken log '{REAL}/' is absent: set FINKENSIM_DATA to the folder holding it (the "
                    "project's shared realdata folder, ../shared/realdata)")
    return d


# ---------------------------------------------------------------------------------------- the real log

def test_real_log_reads_with_its_embedded_protocol_and_with_the_given_messages_xml(real):
    pp = read_paparazzi(real / f"{STEM}.data.gz")
    assert pp.copters == ["FINken3_01"] and pp.ac_ids == ["5"]
    assert pp.notes["messages"]["FINKEN_SENSOR_MODEL"] == 15907  # the folder's README
    assert pp.notes["not mapped"]["AHRS_EULER_INT"] == 19460     # counted, not silently dropped
    np.testing.assert_allclose(pp.sonar_yaw, np.radians([0, -90, 90, 180]))
    r = pp.readings
    sonar = r[r.channel.str.startswith("ultrasonic/")].value.to_numpy()
    assert sonar.size == 4 * (15907 - 1)                         # one line sent twice is kept once
    assert math.isclose(sonar.min(), 0.21) and math.isclose(sonar.max(), 2.99)  # 21-299 cm, read in m
    given = read_paparazzi(real / f"{STEM}.data.gz", messages=real / "finken_messages.xml")
    pd.testing.assert_frame_equal(given.readings, r)


def test_real_log_bursts_are_kept_once_or_counted(real):
    from finkensim.importing import check_recording

    pp = read_paparazzi(real / f"{STEM}.data.gz")
    # line 15637 repeats line 15636 (348.110 s); line 15639 is another message stamped 348.110 s
    assert list(pp.notes["repeated lines (identical to the previous one of the aircraft and message, kept once)"]
                .values()) == [1]
    t = np.arange(0.0, 990.0, 0.01)
    tracking = pd.DataFrame({"t": t, "copter": "FINken3_01", "x": 2.0, "y": 1.5, "yaw": 0.0})
    rec = pp.recording(tracking)
    assert rec.notes["same time as a later message of the channel (not used)"] == 7   # 4 sonars + 3 IMU channels
    assert check_recording(rec).rd_t.size == 7 * (15907 - 1 - 1)


def test_real_log_is_sensor_only_and_build_flight_says_what_to_add(real):
    rec = read_paparazzi(real / f"{STEM}.data.gz").recording()
    with pytest.raises(RecordingError, match="sensor-only.*needs each copter's poses.*tracking CSV"):
        build_flight(rec, (4, 3), sonar_yaw=np.radians([0, -90, 90, 180]), sonar_offset=0.1)


def test_cli_reads_the_real_log_with_the_given_layout_and_asks_for_tracking(real, tmp_path, capsys):
    from finkensim.cli import main

    rc = main(["import", "--paparazzi", str(real / f"{STEM}.data.gz"), "--messages", str(real / "finken_messages.xml"),
               "--arena", "4,3", "--sonar-offset", "0.1", "--out", str(tmp_path / "f.npz")])
    out, err = capsys.readouterr()
    assert rc == 2 and not (tmp_path / "f.npz").exists()
    assert "read FINken3_01 ultrasonic/3: 15906 readings" in out and "0.21 to 2.99" in out
    assert "sensor-only recording" in err and "--tracking TRACK.csv" in err


# ---------------------------------------------------------------------------------------- round trip

@pytest.fixture(scope="module")
def simulated():
    import finkensim as fs

    cfg = fs.load_config({"simulation": {"dt": 0.01}, "sonar": {"crosstalk": "off"}})
    log, _, _ = fs.simulate_flight(cfg, duration=4.0, seed=5)
    return log


def test_a_simulated_flight_written_as_telemetry_reads_back_equal(simulated, tmp_path):
    log = simulated
    ids = [10 + 3 * n for n in range(log.n_copters)]
    out = write_paparazzi(log, tmp_path / "f.data", tmp_path / "f.log", PROTOCOL, ac_ids=ids, clock_offset=0.25)
    assert sorted(out["zero"]) == ["attitude/pitch", "attitude/roll", "attitude/yaw", "down"]
    gz = tmp_path / "g.data.gz"                                        # gzip read transparently, any name
    gz.write_bytes(gzip.compress((tmp_path / "f.data").read_bytes()))
    (tmp_path / "g.log").write_bytes((tmp_path / "f.log").read_bytes())
    pp = read_paparazzi(gz)
    assert pp.copters == [str(c) for c in log.copter_ids] and pp.ac_ids == [str(i) for i in ids]
    r = pp.readings
    for n, name in enumerate(pp.copters):
        def got(ch):
            return r[(r.copter == name) & (r.channel == ch)]

        np.testing.assert_array_equal(got("imu/acc_x").t.to_numpy(), log.t - 0.25)
        for i, yaw in enumerate(pp.sonar_yaw):               # the map's order: front, right, left, back
            s = int(np.argmin(np.abs(np.angle(np.exp(1j * (log.ultrasonic_yaw - yaw))))))
            want = np.round(log.ultrasonic[:, n, s] / 0.01) * 0.01         # int16 cm: 1 cm resolution
            np.testing.assert_array_equal(got(f"ultrasonic/{i}").value.to_numpy(), want)
        np.testing.assert_array_equal(got("imu/acc_x").value.to_numpy(), log.imu_acc[:, n, 0])  # floats: exact
        np.testing.assert_array_equal(got("imu/acc_y").value.to_numpy(), log.imu_acc[:, n, 1])
        np.testing.assert_array_equal(got("imu/gyro").value.to_numpy(), log.imu_gyro[:, n])
        assert (got("down").value == 0).all()


def test_telemetry_merged_with_a_tracking_csv_through_the_clock_offset(simulated, tmp_path):
    from finkensim.cli import main
    from finkensim.flightlog import load

    log = simulated
    write_paparazzi(log, tmp_path / "f.data", tmp_path / "f.log", PROTOCOL, clock_offset=0.25)
    write_csv(to_recording(log, tracking_rate=100), tmp_path / "track.csv", tmp_path / "unused.csv")
    rec = read_paparazzi(tmp_path / "f.data").recording(read_csv(tmp_path / "track.csv").tracking)
    pp_yaw = read_map(DEFAULT_MAP).sonar_yaw()
    flight = build_flight(rec, (3, 4), sonar_yaw=pp_yaw, sonar_offset=log.ultrasonic_offset, clock_offset=0.25)
    assert flight.n_copters == log.n_copters and "dropped" in flight.meta["import"]
    k = np.flatnonzero(np.isin(np.round(log.t, 6), np.round(flight.t, 6)))
    s = [int(np.argmin(np.abs(np.angle(np.exp(1j * (log.ultrasonic_yaw - y)))))) for y in pp_yaw]
    np.testing.assert_array_equal(flight.ultrasonic[:, :, :], np.round(log.ultrasonic[k][:, :, s] / 0.01) * 0.01)
    rc = main(["import", "--paparazzi", str(tmp_path / "f.data"), "--tracking", str(tmp_path / "track.csv"),
               "--arena", "3,4", "--sonar-offset", str(log.ultrasonic_offset), "--clock-offset", "0.25",
               "--out", str(tmp_path / "f.npz")])
    assert rc == 0
    np.testing.assert_array_equal(load(tmp_path / "f.npz").ultrasonic, flight.ultrasonic)


# ---------------------------------------------------------------------------------------- named errors

GOOD = "1.000 5 FINKEN_SENSOR_MODEL 183 97 182 106" + " 0." * 15


@pytest.mark.parametrize("bad, match", [
    ("1.020 5 FINKEN_SENSOR_MODEL 183 97 182", r"line 2: message 'FINKEN_SENSOR_MODEL' has 3 field\(s\) \(the file "
                                               r"ends mid-line: cut short\); the protocol .* gives it 19"),
    ("1.020 5 FINKEN_SENSOR_MODEL 183 97 182 106" + " 0." * 16 + "\n", r"line 2: .* has 20 field\(s\)"),
    ("1.020 5 FINKEN_SENSOR_MODL 1\n", r"line 2: message 'FINKEN_SENSOR_MODL' is not in the protocol .*did you mean "
                                       r"'FINKEN_SENSOR_MODEL'.*--messages"),
    ("1.020 5 AHRS_EULER_INT 1 2 3 4 5 6\n", r"line 2: message 'AHRS_EULER_INT' is not in the protocol"),
    ("1.020 5", r"line 2: '1.020 5' is cut short \(the file ends mid-line\)"),
    ("1.0x 5 ALIVE 1,2\n", r"line 2: time is '1.0x'; expected a number"),
    ("1.020 five ALIVE 1,2\n", r"line 2: ac_id is 'five'; expected an integer"),
    ("1.020 5 FINKEN_SENSOR_MODEL 183 9x7 182 106" + " 0." * 15 + "\n",
     r"line 2: field 'distance_d_rigth' is '9x7'; expected a number"),
])
def test_a_corrupted_data_line_is_named_with_its_line(tmp_path, bad, match):
    (tmp_path / "f.data").write_text(GOOD + "\n" + bad)
    with pytest.raises(RecordingError, match=match):
        read_paparazzi(tmp_path / "f.data", messages=PROTOCOL)


def test_a_map_message_missing_from_the_protocol_is_named(tmp_path):
    (tmp_path / "f.data").write_text(GOOD + "\n")
    proto = PROTOCOL.replace("FINKEN_SENSOR_MODEL", "OTHER")
    with pytest.raises(RecordingError, match=r"channel 'ultrasonic/0': message 'FINKEN_SENSOR_MODEL' is not in the "
                                             r"protocol .*messages.xml"):
        read_paparazzi(tmp_path / "f.data", messages=proto)


def test_no_layouts_at_all_is_named(tmp_path):
    (tmp_path / "f.data").write_text(GOOD + "\n")
    with pytest.raises(RecordingError, match=r"no .log next to it and no messages.xml"):
        read_paparazzi(tmp_path / "f.data")


ENTRY = '[[channel]]\nchannel = "{ch}"\nmessage = "FINKEN_SENSOR_MODEL"\nfield = "{f}"\nunit = "{u}"\n{extra}'


@pytest.mark.parametrize("entry, match", [
    (dict(ch="ultrasonic/0", f="distance_d_front", u="cm", extra=""), r"needs its mounting yaw"),
    (dict(ch="ultrasonic/0", f="distance_d_front", u="rad", extra="yaw_deg = 0"), r"'rad' is a unit of angle, but "
                                                                                  r"channel 'ultrasonic/0' is a length"),
    (dict(ch="ultrasonic/0", f="distance_d_front", u="inch", extra="yaw_deg = 0"), r"unit = 'inch'"),
    (dict(ch="ultrasonic/0", f="distance_d_front", u="m", extra="yaw_deg = 0"), r"the map says field "
                                                                               r"'distance_d_front' is in 'm', the "
                                                                               r"protocol .* says 'cm'"),
    (dict(ch="ultrasonic/0", f="distance_front", u="cm", extra="yaw_deg = 0"), r"has no field 'distance_front' "
                                                                              r"\(did you mean 'distance_d_front'"),
    (dict(ch="sonar/0", f="distance_d_front", u="cm", extra=""), r"#1: unknown channel 'sonar/0'.*analysis channels down"),
    (dict(ch="imu/gyro", f="velocity_yaw", u="rad/s", extra="sign = 2"), r"sign = 2: expected 1 or -1"),
])
def test_map_mistakes_are_named(tmp_path, entry, match):
    (tmp_path / "f.data").write_text(GOOD + "\n")
    with pytest.raises(RecordingError, match=match):
        read_paparazzi(tmp_path / "f.data", messages=PROTOCOL, map=ENTRY.format(**entry))


def test_log_protocol_classes_and_aircraft():
    xml = ('<configuration><conf><aircraft name="A" ac_id="7"/></conf><protocol>'
           '<msg_class NAME="datalink"><message NAME="M" ID="1"><field NAME="a" TYPE="float"/></message></msg_class>'
           '<msg_class NAME="telemetry"><message NAME="M" ID="2"><field NAME="a" TYPE="float"/>'
           '<field NAME="b" TYPE="int16" ALT_UNIT="cm"/></message></msg_class></protocol></configuration>')
    p = read_protocol(xml)
    assert p.aircraft == {"7": "A"}
    assert p.messages["M"].msg_class == "telemetry" and len(p.messages["M"].fields) == 2
    assert p.messages["M"].fields[1].unit == "cm"
    with pytest.raises(RecordingError, match="not valid XML"):
        read_protocol("<protocol>")
