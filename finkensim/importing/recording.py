"""The asynchronous recording every importer produces: long-form tables, each sample at its own time.

A :class:`Recording` is what a CSV pair, a ROS 1 / ROS 2 bag or an MCAP file holds once its messages are
mapped to finkensim's channels, before any alignment: every copter's tracking at its own times, every
reading at its own time. :func:`finkensim.importing.build_flight` turns it into one ``spec/flightlog.md``
flight on a common time base.

Channels (column ``channel`` of :attr:`Recording.readings`):

==========================  ======  ==========================================================
``ultrasonic/<i>``          m       sonar ``i`` (index into the sonar yaw list), measured from the sonar
``ranging/<copter name>``   m       virtual-ranging reading of the named other copter
``imu/acc_x``, ``imu/acc_y`` m/s²   body-frame acceleration
``imu/gyro``                rad/s   yaw rate
==========================  ======  ==========================================================
"""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Recording", "TRACKING_COLUMNS", "READING_COLUMNS", "IMU_CHANNELS"]

#: columns of :attr:`Recording.tracking`: t (s), copter (name), x, y (m), yaw (rad)
TRACKING_COLUMNS = ("t", "copter", "x", "y", "yaw")
#: columns of :attr:`Recording.readings`: t (s), copter (name), channel (see module doc), value (channel's unit)
READING_COLUMNS = ("t", "copter", "channel", "value")
IMU_CHANNELS = ("imu/acc_x", "imu/acc_y", "imu/gyro")


@dataclass(frozen=True)
class Recording:
    """One recorded flight as long-form tables (pandas DataFrames), nothing resampled.

    Attributes:
        tracking: columns :data:`TRACKING_COLUMNS`; t float64 (s, tracking clock), copter str, x/y float64 (m,
            arena frame), yaw float64 (rad, counter-clockwise from +x, any wrapping). Each copter at its own times.
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
