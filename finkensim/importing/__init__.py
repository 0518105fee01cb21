"""Import asynchronous arena recordings (CSV, ROS 1/ROS 2 bags, MCAP) into ``spec/flightlog.md`` flights.

:class:`Recording` is the common long-form form every reader produces (see :mod:`.recording`).
"""
from __future__ import annotations

from .recording import IMU_CHANNELS, READING_COLUMNS, TRACKING_COLUMNS, Recording

__all__ = ["Recording", "TRACKING_COLUMNS", "READING_COLUMNS", "IMU_CHANNELS"]
