"""Import asynchronous arena recordings (CSV, ROS 1/ROS 2 bags, MCAP, Paparazzi telemetry) into
``docs/formats/flightlog.md`` flights.

    from finkensim.importing import read_csv, build_flight
    rec = read_csv("track.csv", "read.csv")              # a Recording: long-form tables, nothing resampled
    log = build_flight(rec, arena=(3, 4), sonar_yaw=np.radians([0, 90, 180, -90]), sonar_offset=0.1)

:class:`Recording` is the common long-form form every reader produces (:mod:`.recording`); :func:`build_flight`
checks it, estimates or applies the clock offset (:mod:`.clock`), places every reading unchanged on a common time
base and interpolates the poses to it (:mod:`.align`, :mod:`.poses`). :func:`to_recording` / :func:`write_csv`
(:mod:`.export`) turn a simulated flight into an asynchronous recording, for tests and demonstrations.
:func:`read_paparazzi` reads the FINken's own Paparazzi telemetry (``.data`` + ``.log``, :mod:`.paparazzi`);
:func:`write_paparazzi` writes a simulated flight as such telemetry (:mod:`.paparazzi_export`).
"""
from __future__ import annotations

from ..lazy import lazy_exports

# each name is imported from its module on first use: the command line's argument parser imports this package's
# `cli` without loading pandas and the readers
_EXPORTS = {
    **dict.fromkeys(["build_flight", "place_readings"], ".align"), **dict.fromkeys(["read_bag", "write_bag"], ".bags"),
    **dict.fromkeys(["ClockEstimate", "ClockOffsetError", "estimate_offset"], ".clock"), "read_csv": ".csvtables",
    **dict.fromkeys(["to_recording", "write_csv"], ".export"),
    **dict.fromkeys(["PaparazziLog", "read_paparazzi"], ".paparazzi"), "write_paparazzi": ".paparazzi_export",
    **dict.fromkeys(["PaparazziMap", "Protocol", "read_map", "read_protocol"], ".paparazzi_protocol"),
    **dict.fromkeys(["IMU_CHANNELS", "READING_COLUMNS", "TRACKING_COLUMNS", "Recording", "RecordingError",
                     "check_recording", "parse_channel"], ".recording"),
}
__all__ = ["Recording", "RecordingError", "TRACKING_COLUMNS", "READING_COLUMNS", "IMU_CHANNELS", "read_csv",
           "build_flight", "place_readings", "check_recording", "parse_channel", "estimate_offset", "ClockEstimate",
           "ClockOffsetError", "to_recording", "write_csv", "read_bag", "write_bag", "read_paparazzi", "PaparazziLog",
           "write_paparazzi", "read_protocol", "Protocol", "read_map", "PaparazziMap"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
