"""The flight-log record and its array schema (format ``finkensim-flightlog/1``).

The format is specified in ``docs/formats/flightlog.md`` (the format the project publishes). This module holds the
:class:`FlightLog` record, the names of the standard arrays and the error type; checking
a log is :mod:`~finkensim.flightlog.validation`, files are :mod:`.npz` and :mod:`.csv`.

Arrays (all float64 unless stated; T samples, N copters, S sonars)::

    format             str, 0-d      exactly "finkensim-flightlog/1"
    t                  (T,)      s   sample times, strictly increasing
    arena              (2,)      m   width (x extent), length (y extent)
    pose               (T, N, 3) m, m, rad   x, y, yaw (yaw counter-clockwise from +x)
    copter_ids         (N,)  str     unique names
    ultrasonic         (T, N, S) m   optional; NaN = no reading; measured from the sonar
    ultrasonic_yaw     (S,)      rad with ultrasonic; mounting yaw relative to the heading
    ultrasonic_offset  ()        m   with ultrasonic; sonar distance from the copter centre
    ranging            (T, N, N) m   optional; row = measuring copter; NaN = no reading; diagonal 0
    imu_acc            (T, N, 2) m/s^2  optional; body-frame acceleration
    imu_gyro           (T, N)    rad/s  with imu_acc; yaw rate
    meta               str, 0-d      optional JSON object (copter_radius, altitude, source,
                                     tracking_sigma_xy, tracking_sigma_yaw, anything else)
    z                  (T, N)    m   optional extra (a version-1 extra array, so every reader keeps it): each
                                     copter's height; ranging is then compared with 3-D distances

Frame: origin at one arena corner, x along the width, y along the length. Missing readings are
NaN and stay NaN: nothing in this package drops, fills, interpolates or rescales data.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "FORMAT",
    "SONAR_NAMES",
    "DEFAULT_SONAR_YAW",
    "DEFAULT_COPTER_RADIUS",
    "REQUIRED",
    "OPTIONAL",
    "NUMERIC",
    "STANDARD",
    "BLOCKS",
    "RESERVED_EXTRAS",
    "HEIGHTS",
    "FlightLogError",
    "FlightLog",
    "heights",
]

FORMAT = "finkensim-flightlog/1"
"""The value of the ``format`` array of every version-1 flight log."""

SONAR_NAMES = ("front", "left", "back", "right")
"""Conventional order of the four horizontal sonars."""

DEFAULT_SONAR_YAW = (0.0, math.pi / 2, math.pi, -math.pi / 2)
"""Mounting yaw (rad, relative to the heading) of front, left, back, right."""

DEFAULT_COPTER_RADIUS = 0.15
"""Copter radius (m) used by the arena check when ``meta`` has no ``copter_radius``."""

REQUIRED = ("t", "arena", "pose", "copter_ids")
"""Arrays every flight log has (besides ``format``)."""

OPTIONAL = ("ultrasonic", "ultrasonic_yaw", "ultrasonic_offset", "ranging", "imu_acc", "imu_gyro")
"""Optional sensor arrays, in the order they are stored."""

NUMERIC = ("t", "arena", "pose") + OPTIONAL
"""Arrays that must hold real numbers (stored as float64)."""

STANDARD = ("format",) + REQUIRED + OPTIONAL + ("meta",)
"""Every array name the format defines; any other array is an extra."""

BLOCKS = {
    "ultrasonic": ("ultrasonic", "ultrasonic_yaw", "ultrasonic_offset"),
    "imu": ("imu_acc", "imu_gyro"),
}
"""All-or-nothing blocks: block name -> the arrays that are present together or not at all."""

RESERVED_EXTRAS = ("file", "allow_pickle")
"""Keyword names of ``np.savez_compressed`` itself: an extra array cannot be called like this."""


HEIGHTS = "z"
"""Name of the optional extra array of heights (T, N) m (version 1 allows extra arrays, so logs stay readable)."""


def heights(log: "FlightLog") -> np.ndarray | None:
    """The log's heights (T, N) m as float64, or None when it has no ``z`` extra (a planar flight)."""
    z = (log.extras or {}).get(HEIGHTS)
    return None if z is None else np.asarray(z, dtype=np.float64)


class FlightLogError(ValueError):
    """A flight log (file or object) is wrong. The message names the array, the problem and what was expected.

    A :class:`ValueError`; the command line reports it in one line (exit code 2), without a traceback.
    """


def _nan_equal(a: Any, b: Any) -> bool:
    """Array equality where NaN equals NaN; shapes must match; numbers compare by value (not dtype)."""
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return False
    num_a = a.dtype.kind in "biuf"
    num_b = b.dtype.kind in "biuf"
    if num_a and num_b:
        return bool(np.array_equal(a, b, equal_nan=True))
    if num_a != num_b:
        return False
    return bool(np.array_equal(a, b))


@dataclass(eq=False)
class FlightLog:
    """One flight: sample times, arena, ground-truth poses and (optionally) sensor readings.

    Shapes use T = ``len(t)`` samples, N = ``len(copter_ids)`` copters, S = ``len(ultrasonic_yaw)``
    sonars. Units are SI. Building a ``FlightLog`` does not check it: call :func:`validate`
    (:func:`save`, :func:`load` and :func:`from_csv` do). Equality (``==`` / :meth:`equals`)
    compares every array by value with NaN equal to NaN, ``meta`` and ``extras`` included.

    Parameters
    ----------
    t : ndarray, shape (T,)
        Sample times, s, strictly increasing.
    arena : ndarray, shape (2,)
        Arena width (x extent) and length (y extent), m.
    pose : ndarray, shape (T, N, 3)
        Ground-truth x (m), y (m), yaw (rad, counter-clockwise from +x) of each copter, in the arena frame
        (origin at a corner, positions in [0, width] x [0, length]).
    copter_ids : ndarray of str, shape (N,)
        Unique copter names.
    ultrasonic : ndarray, shape (T, N, S), optional
        The flight-log array ``ultrasonic`` (the spec's name): sonar readings, m, measured from the sonar; NaN = no reading.
    ultrasonic_yaw : ndarray, shape (S,), optional
        Mounting yaw relative to the heading, rad (front 0, left +pi/2, back pi, right -pi/2); present
        exactly when ``ultrasonic`` is.
    ultrasonic_offset : float, optional
        Distance from the copter centre to each sonar, m; present exactly when ``ultrasonic`` is.
    ranging : ndarray, shape (T, N, N), optional
        Virtual-ranging distances, m; row = measuring copter; NaN = no reading; diagonal exactly 0.
    imu_acc : ndarray, shape (T, N, 2), optional
        Body-frame acceleration, m/s² (present with ``imu_gyro``).
    imu_gyro : ndarray, shape (T, N), optional
        Yaw rate, rad/s (present with ``imu_acc``).
    meta : dict
        JSON object: ``copter_radius`` (m), ``altitude`` (m), ``source``, ``tracking_sigma_xy`` (m),
        ``tracking_sigma_yaw`` (rad), anything else.
    extras : dict of str to ndarray
        Any other arrays by name; saved and loaded unchanged.
    """

    t: np.ndarray
    arena: np.ndarray
    pose: np.ndarray
    copter_ids: np.ndarray
    ultrasonic: np.ndarray | None = None
    ultrasonic_yaw: np.ndarray | None = None
    ultrasonic_offset: float | None = None
    ranging: np.ndarray | None = None
    imu_acc: np.ndarray | None = None
    imu_gyro: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)

    def __post_init__(self):
        # Lists become arrays and integers float64 (copter_ids: names, kept as given so that validate() names
        # their real dtype); other dtypes are kept for validate() to judge.
        for name in REQUIRED + OPTIONAL:
            value = getattr(self, name)
            if value is None or name == "ultrasonic_offset":
                continue
            try:
                a = np.asarray(value)
                setattr(self, name, a.astype(np.float64) if a.dtype.kind in "iu" and name != "copter_ids" else a)
            except (ValueError, TypeError) as exc:
                raise FlightLogError(f"{name} cannot be converted to an array ({exc}); expected a rectangular array") from None
        if self.meta is None:
            self.meta = {}
        if self.extras is None:
            self.extras = {}

    # -- sizes and blocks --------------------------------------------------------------------
    @property
    def n_steps(self) -> int:
        """T, the number of samples."""
        return int(np.shape(self.t)[0]) if np.ndim(self.t) else 0

    @property
    def n_copters(self) -> int:
        """N, the number of copters."""
        return int(np.shape(self.copter_ids)[0]) if np.ndim(self.copter_ids) else 0

    @property
    def n_sonars(self) -> int:
        """S, the number of sonars per copter (0 if the log has no ultrasonic block)."""
        if self.ultrasonic is None or np.ndim(self.ultrasonic) < 3:
            return 0
        return int(np.shape(self.ultrasonic)[2])

    @property
    def has_ultrasonic(self) -> bool:
        """True if the log carries sonar readings."""
        return self.ultrasonic is not None

    @property
    def has_ranging(self) -> bool:
        """True if the log carries virtual-ranging readings."""
        return self.ranging is not None

    @property
    def has_imu(self) -> bool:
        """True if the log carries IMU readings."""
        return self.imu_acc is not None

    # -- time windows -------------------------------------------------------------------------
    def between(self, start: float, stop: float) -> "FlightLog":
        """The part of the flight with ``start`` <= t < ``stop``: a new log of those samples (times unchanged).

        Every array with a time axis is cut along it: ``t``, ``pose`` and the sensor readings, and each extra whose
        first axis has T entries (heights ``z``, ideal values, …); the other arrays (``arena``, mounting, an
        extra of another length), ``meta`` and the copters are kept. Nothing is re-sampled or shifted.

        Parameters
        ----------
        start : float
            First time kept, s (inclusive).
        stop : float
            End of the window, s (exclusive).

        Returns
        -------
        FlightLog
            The samples in the window (copies).

        Raises
        ------
        FlightLogError
            A window that is not a pair of numbers with start < stop, or that holds fewer than 2 samples.
        """
        try:
            a, b = float(start), float(stop)
        except (TypeError, ValueError):
            raise FlightLogError(f"time window ({start!r}, {stop!r}): expected two numbers in s") from None
        if not a < b:
            raise FlightLogError(f"time window ({start!r}, {stop!r}) s: expected start < stop")
        t = np.asarray(self.t, dtype=np.float64)
        keep = (t >= a) & (t < b)
        if keep.sum() < 2:
            raise FlightLogError(f"time window [{a:g}, {b:g}) s holds {int(keep.sum())} of the log's {t.size} samples "
                                 f"(t = {t[0]:g} .. {t[-1]:g} s): expected at least 2")
        T = t.size

        def cut(value):
            return None if value is None else np.asarray(value)[keep].copy()

        extras = {k: (np.asarray(v)[keep].copy() if np.ndim(v) and np.shape(v)[0] == T else v)
                  for k, v in (self.extras or {}).items()}
        return FlightLog(t=t[keep].copy(), arena=self.arena, pose=cut(self.pose), copter_ids=self.copter_ids,
                         ultrasonic=cut(self.ultrasonic), ultrasonic_yaw=self.ultrasonic_yaw,
                         ultrasonic_offset=self.ultrasonic_offset, ranging=cut(self.ranging),
                         imu_acc=cut(self.imu_acc), imu_gyro=cut(self.imu_gyro), meta=dict(self.meta or {}),
                         extras=extras)

    # -- comparison ---------------------------------------------------------------------------
    def equals(self, other: "FlightLog") -> bool:
        """True if every array, ``meta`` and ``extras`` are equal (NaN equals NaN, values not dtypes).

        Parameters
        ----------
        other : FlightLog
            The log to compare with (anything else compares unequal).

        Returns
        -------
        bool
        """
        if not isinstance(other, FlightLog):
            return False
        for name in REQUIRED + OPTIONAL:
            if not _nan_equal(getattr(self, name), getattr(other, name)):
                return False
        if self.meta != other.meta:
            return False
        if set(self.extras) != set(other.extras):
            return False
        return all(_nan_equal(self.extras[k], other.extras[k]) for k in self.extras)

    def __eq__(self, other):
        if not isinstance(other, FlightLog):
            return NotImplemented
        return self.equals(other)

    __hash__ = None  # mutable arrays inside
