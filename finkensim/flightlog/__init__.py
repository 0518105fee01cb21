"""Flight logs: one flight in one ``.npz`` file (format ``finkensim-flightlog/1``).

The format is specified in ``docs/formats/flightlog.md`` (the format the project publishes); this package is its
reference implementation. The simulator writes logs with :func:`save`, real arena recordings are
converted with :func:`from_csv` (or by any external tool writing the same arrays), and every
consumer reads them with :func:`load`. Every problem is a :class:`FlightLogError` whose message
names the array, what is wrong and what was expected.

Modules: :mod:`.format` (the :class:`FlightLog` record and the array schema, documented there),
:mod:`.messages` (wording of error messages), :mod:`.encoding` (str arrays and the JSON
``meta``), :mod:`~finkensim.flightlog.validation` (:func:`validate`), :mod:`.npz` (:func:`save`, :func:`load`),
:mod:`.csv` (:func:`from_csv`).

Frame: origin at one arena corner, x along the width, y along the length. Missing readings are
NaN and stay NaN: nothing in this package drops, fills, interpolates or rescales data.
"""
from __future__ import annotations

from .csv import from_csv
from .format import (DEFAULT_COPTER_RADIUS, DEFAULT_SONAR_YAW, FORMAT, HEIGHTS, SONAR_NAMES, FlightLog, FlightLogError,
                     heights)
from .npz import load, save
from .validation import validate

__all__ = ["FORMAT", "HEIGHTS", "heights", "SONAR_NAMES", "DEFAULT_SONAR_YAW", "DEFAULT_COPTER_RADIUS", "FlightLogError", "FlightLog",
           "validate", "save", "load", "from_csv"]
