"""Flight logs: one flight in one ``.npz`` file (format ``finkensim-flightlog/1``).

The format is specified in ``/work/shared/spec/flightlog.md``; this module is its reference
implementation. The simulator writes logs with :func:`save`, real arena recordings are
converted with :func:`from_csv` (or by any external tool writing the same arrays), and every
consumer reads them with :func:`load`. Every problem is a :class:`FlightLogError` whose message
names the array, what is wrong and what was expected.

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

Frame: origin at one arena corner, x along the width, y along the length. Missing readings are
NaN and stay NaN: nothing in this module drops, fills, interpolates or rescales data.
"""
from __future__ import annotations

import json
import math
import os
import re
import secrets
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = [
    "FORMAT",
    "SONAR_NAMES",
    "DEFAULT_SONAR_YAW",
    "DEFAULT_COPTER_RADIUS",
    "FlightLogError",
    "FlightLog",
    "validate",
    "save",
    "load",
    "from_csv",
]

FORMAT = "finkensim-flightlog/1"
"""The value of the ``format`` array of every version-1 flight log."""

SONAR_NAMES = ("front", "left", "back", "right")
"""Conventional order of the four horizontal sonars."""

DEFAULT_SONAR_YAW = (0.0, math.pi / 2, math.pi, -math.pi / 2)
"""Mounting yaw (rad, relative to the heading) of front, left, back, right."""

DEFAULT_COPTER_RADIUS = 0.15
"""Copter radius (m) used by the arena check when ``meta`` has no ``copter_radius``."""

# --- unit heuristics (documented in :func:`validate`) -------------------------------------
ARENA_CM_ABOVE = 100.0       # an arena side > 100 "m" is a side in cm ...
ARENA_MM_ABOVE = 1000.0      # ... and > 1000 "m" a side in mm
RANGE_CM_ABOVE = 50.0        # median sonar / ranging reading > 50 "m": cm ...
RANGE_MM_ABOVE = 500.0       # ... > 500 "m": mm
ACC_CM_ABOVE = 50.0          # median |imu_acc| > 50 "m/s^2": cm/s^2 ...
ACC_MM_ABOVE = 500.0         # ... > 500: mm/s^2
POSE_SCALE_FACTOR = 10.0     # poses > 10x the arena that fit it after /100 (/1000): cm (mm)
SCALAR_LIMITS = {            # scalar lengths above these limits (m) look like cm or mm
    "ultrasonic_offset": 1.0,
    "meta['copter_radius']": 2.0,
    "meta['altitude']": 20.0,
    "meta['tracking_sigma_xy']": 1.0,
}

_REQUIRED = ("t", "arena", "pose", "copter_ids")
_OPTIONAL = ("ultrasonic", "ultrasonic_yaw", "ultrasonic_offset", "ranging", "imu_acc", "imu_gyro")
_NUMERIC = ("t", "arena", "pose") + _OPTIONAL
_STANDARD = ("format",) + _REQUIRED + _OPTIONAL + ("meta",)
_BLOCKS = {
    "ultrasonic": ("ultrasonic", "ultrasonic_yaw", "ultrasonic_offset"),
    "imu": ("imu_acc", "imu_gyro"),
}
# keyword names of np.savez_compressed itself: an extra array cannot be called like this
_RESERVED_EXTRAS = ("file", "allow_pickle")


class FlightLogError(ValueError):
    """A flight log (file or object) is wrong. The message names the array, the problem and what was expected."""


# ------------------------------------------------------------------------------------------
# the log object
# ------------------------------------------------------------------------------------------

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

    Attributes:
        t: (T,) sample times in s, strictly increasing.
        arena: (2,) arena width (x extent) and length (y extent) in m.
        pose: (T, N, 3) ground-truth x (m), y (m), yaw (rad, counter-clockwise from +x) of each
            copter, in the arena frame (origin at a corner, positions in [0, width] x [0, length]).
        copter_ids: (N,) unique copter names (str array).
        ultrasonic: optional (T, N, S) sonar readings in m, measured from the sonar; NaN = no reading.
        ultrasonic_yaw: (S,) mounting yaw in rad relative to the heading (front 0, left +pi/2,
            back pi, right -pi/2); present exactly when ``ultrasonic`` is.
        ultrasonic_offset: distance in m from the copter centre to each sonar; present exactly
            when ``ultrasonic`` is.
        ranging: optional (T, N, N) virtual-ranging distances in m; row = measuring copter;
            NaN = no reading; diagonal exactly 0.
        imu_acc: optional (T, N, 2) body-frame acceleration in m/s^2 (present with ``imu_gyro``).
        imu_gyro: optional (T, N) yaw rate in rad/s (present with ``imu_acc``).
        meta: JSON object: ``copter_radius`` (m), ``altitude`` (m), ``source``,
            ``tracking_sigma_xy`` (m), ``tracking_sigma_yaw`` (rad), anything else.
        extras: any other arrays by name; saved and loaded unchanged.
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
        # Lists become arrays and integers float64; other dtypes are kept for validate() to judge.
        for name in _REQUIRED + _OPTIONAL:
            value = getattr(self, name)
            if value is None or name == "ultrasonic_offset":
                continue
            try:
                a = np.asarray(value)
                setattr(self, name, a.astype(np.float64) if a.dtype.kind in "iu" else a)
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

    # -- comparison ---------------------------------------------------------------------------
    def equals(self, other: "FlightLog") -> bool:
        """True if every array, ``meta`` and ``extras`` are equal (NaN equals NaN, values not dtypes)."""
        if not isinstance(other, FlightLog):
            return False
        for name in _REQUIRED + _OPTIONAL:
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


# ------------------------------------------------------------------------------------------
# validation
# ------------------------------------------------------------------------------------------

def _fmt(x: float) -> str:
    return f"{x:.6g}"


def _shape(shape: tuple) -> str:
    return "(" + ", ".join(str(int(s)) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _where(log_t, ids, index: tuple, axes: str) -> str:
    """Describe an index like (step, copter, sonar) for error messages."""
    parts = []
    for ax, i in zip(axes, index):
        i = int(i)
        if ax == "t":
            t = float(log_t[i]) if log_t is not None and i < len(log_t) else float("nan")
            parts.append(f"t = {_fmt(t)} s (step {i})")
        elif ax == "c":
            parts.append(f"copter {str(ids[i])!r}" if ids is not None and i < len(ids) else f"copter {i}")
        elif ax == "o":
            parts.append(f"target copter {str(ids[i])!r}" if ids is not None and i < len(ids) else f"target copter {i}")
        elif ax == "s":
            parts.append(f"sonar {i}")
        elif ax == "a":
            parts.append(f"axis {i}")
    return ", ".join(parts)


def _unit_hint(value: float, cm_above: float, mm_above: float, unit: str = "m") -> str | None:
    """'looks like centimetres: divide by 100' (or mm) if ``value`` exceeds the thresholds."""
    cm, mm = ("centimetres", "millimetres") if unit == "m" else (unit.replace("m", "cm", 1), unit.replace("m", "mm", 1))
    if value > mm_above:
        return f"looks like {mm}: divide by 1000"
    if value > cm_above:
        return f"looks like {cm}: divide by 100"
    return None


def _n(count: int, word: str) -> str:
    return f"{count} {word}" + ("" if count == 1 else "s")


def _check_numeric(name: str, arr: Any) -> np.ndarray:
    """Return ``arr`` as an array, or raise if its dtype is not a real number type."""
    a = np.asarray(arr)
    if a.dtype.kind not in "iuf":
        kind = {"b": "bool", "c": "complex", "O": "object (pickled)", "U": "str", "S": "bytes"}.get(a.dtype.kind, str(a.dtype))
        raise FlightLogError(f"{name} has dtype {a.dtype} ({kind}); expected float64 numbers")
    return a


def _check_nonfinite_readings(name: str, a: np.ndarray, t, ids, axes: str) -> None:
    bad = np.isinf(a)
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        raise FlightLogError(
            f"{name} has {_n(int(bad.sum()), 'infinite value')} (first {_fmt(float(a[idx]))} at {_where(t, ids, idx, axes)}); "
            "expected finite values, NaN for a missing reading"
        )


def _check_negative(name: str, a: np.ndarray, mask, t, ids, axes: str) -> None:
    with np.errstate(invalid="ignore"):
        bad = a < 0  # NaN compares False: missing readings are ignored
    if mask is not None:
        bad &= mask
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        raise FlightLogError(
            f"{name} has {_n(int(bad.sum()), 'negative reading')} (first {_fmt(float(a[idx]))} m at {_where(t, ids, idx, axes)}); "
            "expected distances >= 0 m, NaN for a missing reading"
        )


def _check_median_units(name: str, values: np.ndarray, cm_above: float, mm_above: float, unit: str = "m") -> None:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return
    med = float(np.median(np.abs(finite)))
    hint = _unit_hint(med, cm_above, mm_above, unit)
    if hint:
        raise FlightLogError(
            f"{name} has median |value| {_fmt(med)}, implausibly large for {unit} (> {_fmt(cm_above)}); "
            f"expected {unit}: {name} {hint}"
        )


def _check_scalar_length(name: str, value: float) -> None:
    limit = SCALAR_LIMITS[name]
    if value > limit:
        raise FlightLogError(
            f"{name} = {_fmt(value)} is implausibly large for m (> {_fmt(limit)}); expected metres: "
            "looks like centimetres (divide by 100) or millimetres (divide by 1000)"
        )


def _as_text(name: str, arr: Any, *, scalar: bool) -> Any:
    """A str (0-d) or str array from a unicode/bytes array; raise if it is not text."""
    a = np.asarray(arr)
    if a.dtype.kind == "S":
        try:
            a = np.char.decode(a, "utf-8")
        except UnicodeDecodeError:
            raise FlightLogError(f"{name} holds bytes that are not UTF-8; expected str") from None
    if a.dtype.kind != "U":
        raise FlightLogError(f"{name} has dtype {a.dtype}; expected str")
    if scalar:
        if a.shape != ():
            raise FlightLogError(f"{name} has shape {_shape(a.shape)}; expected a 0-d str array, shape ()")
        return str(a[()])
    return a


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")


def _meta_to_json(meta: Any) -> str:
    if not isinstance(meta, Mapping):
        raise FlightLogError(f"meta is a {type(meta).__name__}; expected a JSON object (a dict with str keys)")
    for k in meta:
        if not isinstance(k, str):
            raise FlightLogError(f"meta has key {k!r} ({type(k).__name__}); expected a JSON object with str keys")
    try:
        return json.dumps(dict(meta), allow_nan=False, default=_json_default)
    except (TypeError, ValueError) as exc:
        raise FlightLogError(f"meta is not valid JSON ({exc}); expected a JSON object of numbers, strings, lists and objects (no NaN)") from None


def _meta_from_json(text: str) -> dict:
    def bad_constant(c):
        raise ValueError(f"{c} is not valid JSON")

    try:
        meta = json.loads(text, parse_constant=bad_constant)
    except ValueError as exc:
        raise FlightLogError(f"meta is not valid JSON ({exc}); expected a JSON object") from None
    if not isinstance(meta, dict):
        raise FlightLogError(f"meta is JSON {type(meta).__name__} {text[:60]!r}; expected a JSON object {{...}}")
    return meta


def _meta_number(meta: Mapping, key: str, *, positive: bool) -> float | None:
    if key not in meta:
        return None
    v = meta[key]
    name = f"meta['{key}']"
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise FlightLogError(f"{name} = {v!r}: expected a number (m or rad)")
    v = float(v)
    if not math.isfinite(v) or (v <= 0 if positive else v < 0):
        raise FlightLogError(f"{name} = {v!r}: expected a finite number {'> 0' if positive else '>= 0'}")
    return v


def _pose_hint(x, y, width, length, r) -> str:
    """Why poses might be outside the arena: units, a centred origin, swapped axes."""
    def fits(xs, ys, w, l):
        return bool(np.all((xs >= -r) & (xs <= w + r) & (ys >= -r) & (ys <= l + r)))

    big = np.max(np.abs(x)) > POSE_SCALE_FACTOR * width or np.max(np.abs(y)) > POSE_SCALE_FACTOR * length
    if big and fits(x / 100, y / 100, width, length):
        return "; pose x/y look like centimetres: divide by 100"
    if big and fits(x / 1000, y / 1000, width, length):
        return "; pose x/y look like millimetres: divide by 1000"
    if np.min(x) < -r or np.min(y) < -r:
        if fits(x + width / 2, y + length / 2, width, length):
            return "; the origin looks like the arena centre: expected a corner, add (width/2, length/2)"
    if fits(y, x, width, length):
        return "; x and y (or arena width and length) look swapped"
    return ""


def validate(log: FlightLog, *, check_units: bool = True) -> None:
    """Check a :class:`FlightLog` against format version 1; raise :class:`FlightLogError` if wrong.

    Checks, in order: types (numeric arrays must have a real number dtype, ``copter_ids`` str,
    ``meta`` a JSON object, extras plain arrays with names that do not clash with the standard
    ones); all-or-nothing blocks (``ultrasonic`` + ``ultrasonic_yaw`` + ``ultrasonic_offset``,
    ``imu_acc`` + ``imu_gyro``); shapes against T = ``len(t)``, N = ``len(copter_ids)``,
    S = ``len(ultrasonic_yaw)`` (T, N, S >= 1); ``t`` finite and strictly increasing; ``arena``
    finite and positive; ``meta`` fields (``copter_radius`` > 0, ``altitude``,
    ``tracking_sigma_*`` >= 0, ``source`` str); unique ``copter_ids``; finite poses inside the
    arena up to one copter radius (``meta['copter_radius']``, default 0.15 m); readings: no
    infinities (NaN is the only "no reading"), no negative distances (NaN ignored), ranging
    diagonal exactly 0 (NaN there is an error); ``ultrasonic_yaw`` finite and within +-2 pi
    (larger values look like degrees); ``ultrasonic_offset`` finite and >= 0.

    Unit heuristics (``check_units=False`` turns them off; nothing is ever rescaled):

    * ``arena``: a side > 100 looks like cm, > 1000 like mm (arenas larger than 100 m are
      not supported with the check on).
    * ``pose``: positions outside the arena, more than 10x its size, that fit it after
      dividing by 100 (1000) look like cm (mm). Positions that fit after shifting by half the
      arena or swapping x/y get the matching hint instead.
    * ``ultrasonic`` and off-diagonal ``ranging``: a median finite reading > 50 looks like cm,
      > 500 like mm.
    * ``imu_acc``: a median finite ``|component|`` > 50 looks like cm/s^2, > 500 like mm/s^2.
    * scalars: ``ultrasonic_offset`` > 1 m, ``meta['copter_radius']`` > 2 m,
      ``meta['altitude']`` > 20 m, ``meta['tracking_sigma_xy']`` > 1 m look like cm or mm.

    Yaw angles (``pose``, ``imu_gyro``) are not unit-checked: unwrapped radians can be large.
    """
    if not isinstance(log, FlightLog):
        raise FlightLogError(f"expected a FlightLog, got {type(log).__name__}")

    # -- presence, dtypes -----------------------------------------------------------------
    for name in _REQUIRED:
        if getattr(log, name) is None:
            raise FlightLogError(f"{name} is missing; a flight log needs {', '.join(_REQUIRED)}")
    arrays: dict[str, np.ndarray] = {}
    for name in _NUMERIC:
        v = getattr(log, name)
        if v is not None:
            arrays[name] = _check_numeric(name, v).astype(np.float64, copy=False)
    ids = _as_text("copter_ids", log.copter_ids, scalar=False)
    meta = log.meta
    _meta_to_json(meta)  # type check and JSON check
    if not isinstance(log.extras, Mapping):
        raise FlightLogError(f"extras is a {type(log.extras).__name__}; expected a dict of arrays")
    for k, v in log.extras.items():
        if not isinstance(k, str) or not k:
            raise FlightLogError(f"extras key {k!r}: expected a non-empty str array name")
        if k in _STANDARD:
            raise FlightLogError(f"extras['{k}'] clashes with the standard array {k!r}; set the FlightLog field instead")
        if k in _RESERVED_EXTRAS:
            raise FlightLogError(f"extras['{k}']: {k!r} is reserved by np.savez_compressed; rename the array")
        try:
            a = np.asarray(v)
        except (ValueError, TypeError) as exc:
            raise FlightLogError(f"extras['{k}'] cannot be converted to an array ({exc}); expected a rectangular array") from None
        if a.dtype.kind not in "biufcUSmM":
            raise FlightLogError(f"extras['{k}'] has dtype {a.dtype}; expected numbers or str (no pickled objects)")

    # -- all-or-nothing blocks ----------------------------------------------------------------
    for block, names in _BLOCKS.items():
        present = [n for n in names if getattr(log, n) is not None]
        if present and len(present) != len(names):
            missing = [n for n in names if n not in present]
            raise FlightLogError(
                f"{', '.join(present)} {'is' if len(present) == 1 else 'are'} present but {', '.join(missing)} "
                f"{'is' if len(missing) == 1 else 'are'} missing; the {block} block is all-or-nothing: {', '.join(names)}"
            )

    # -- shapes ---------------------------------------------------------------------------
    t = arrays["t"]
    if t.ndim != 1:
        raise FlightLogError(f"t has shape {_shape(t.shape)}; expected (T,)")
    if ids.ndim != 1:
        raise FlightLogError(f"copter_ids has shape {_shape(ids.shape)}; expected (N,)")
    T, N = t.shape[0], ids.shape[0]
    if T == 0:
        raise FlightLogError("t is empty, shape (0,); expected at least one sample")
    if N == 0:
        raise FlightLogError("copter_ids is empty, shape (0,); expected at least one copter")
    tn = "T = len(t), N = len(copter_ids)"
    expected = {
        "arena": ((2,), "(2,) = (width, length)"),
        "pose": ((T, N, 3), f"(T, N, 3) = {_shape((T, N, 3))} with {tn}"),
        "ranging": ((T, N, N), f"(T, N, N) = {_shape((T, N, N))} with {tn}"),
        "imu_acc": ((T, N, 2), f"(T, N, 2) = {_shape((T, N, 2))} with {tn}"),
        "imu_gyro": ((T, N), f"(T, N) = {_shape((T, N))} with {tn}"),
    }
    if "ultrasonic_yaw" in arrays:
        yaw_s = arrays["ultrasonic_yaw"]
        if yaw_s.ndim != 1:
            raise FlightLogError(f"ultrasonic_yaw has shape {_shape(yaw_s.shape)}; expected (S,)")
        S = yaw_s.shape[0]
        if S == 0:
            raise FlightLogError("ultrasonic_yaw is empty, shape (0,); expected at least one sonar (or no ultrasonic block)")
        expected["ultrasonic"] = ((T, N, S), f"(T, N, S) = {_shape((T, N, S))} with {tn}, S = len(ultrasonic_yaw)")
        expected["ultrasonic_offset"] = ((), "a scalar, shape ()")
    for name, (shape, text) in expected.items():
        if name in arrays and arrays[name].shape != shape:
            raise FlightLogError(f"{name} has shape {_shape(arrays[name].shape)}; expected {text}")

    # -- time -----------------------------------------------------------------------------
    if not np.all(np.isfinite(t)):
        i = int(np.argwhere(~np.isfinite(t))[0, 0])
        raise FlightLogError(f"t[{i}] = {t[i]}; expected finite sample times in s")
    if T > 1:
        dt = np.diff(t)
        if np.any(dt <= 0):
            i = int(np.argwhere(dt <= 0)[0, 0])
            raise FlightLogError(
                f"t is not strictly increasing: t[{i}] = {_fmt(t[i])} s, t[{i + 1}] = {_fmt(t[i + 1])} s "
                f"({_n(int(np.sum(dt <= 0)), 'non-increasing step')}); expected strictly increasing sample times"
            )

    # -- arena ----------------------------------------------------------------------------
    arena = arrays["arena"]
    if not np.all(np.isfinite(arena)) or np.any(arena <= 0):
        raise FlightLogError(f"arena = [{', '.join(_fmt(a) for a in arena)}]; expected finite width and length > 0 m")
    width, length = float(arena[0]), float(arena[1])
    if check_units:
        hint = _unit_hint(max(width, length), ARENA_CM_ABOVE, ARENA_MM_ABOVE)
        if hint:
            raise FlightLogError(
                f"arena = [{_fmt(width)}, {_fmt(length)}] is implausibly large for m (> {_fmt(ARENA_CM_ABOVE)}); "
                f"expected metres: arena {hint}"
            )

    # -- meta -----------------------------------------------------------------------------
    radius = _meta_number(meta, "copter_radius", positive=True)
    altitude = _meta_number(meta, "altitude", positive=False)
    sigma_xy = _meta_number(meta, "tracking_sigma_xy", positive=False)
    _meta_number(meta, "tracking_sigma_yaw", positive=False)
    if "source" in meta and not isinstance(meta["source"], str):
        raise FlightLogError(f"meta['source'] = {meta['source']!r}: expected a str")
    if check_units:
        for key, v in (("copter_radius", radius), ("altitude", altitude), ("tracking_sigma_xy", sigma_xy)):
            if v is not None:
                _check_scalar_length(f"meta['{key}']", v)
    if radius is None:
        radius = DEFAULT_COPTER_RADIUS

    # -- copter ids -----------------------------------------------------------------------
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        dups = [str(u) for u in uniq[counts > 1]]
        raise FlightLogError(f"copter_ids has duplicates {dups}; expected unique names")

    # -- pose -----------------------------------------------------------------------------
    pose = arrays["pose"]
    finite = np.isfinite(pose)
    if not finite.all():
        idx = tuple(np.argwhere(~finite)[0])
        raise FlightLogError(
            f"pose has {_n(int((~finite).sum()), 'non-finite value')} (first {pose[idx]} at "
            f"{_where(t, ids, idx[:2], 'tc')}, {'xyz'[idx[2]] if idx[2] < 2 else 'yaw'}); "
            "expected finite ground-truth poses (no NaN: the tracking system must see every copter)"
        )
    x, y = pose[..., 0], pose[..., 1]
    out = np.maximum.reduce([-x, x - width, -y, y - length])  # distance outside the arena box (per axis)
    bad = out > radius
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        hint = _pose_hint(x, y, width, length, radius) if check_units else ""
        raise FlightLogError(
            f"pose is outside the arena: copter {str(ids[idx[1]])!r} at t = {_fmt(t[idx[0]])} s (step {idx[0]}) is at "
            f"({_fmt(x[idx])}, {_fmt(y[idx])}) m, {_fmt(out[idx])} m outside [0, {_fmt(width)}] x [0, {_fmt(length)}] m "
            f"({_n(int(bad.sum()), 'sample')} outside); expected at most copter_radius = {_fmt(radius)} m outside{hint}"
        )

    # -- ultrasonic -----------------------------------------------------------------------
    if "ultrasonic" in arrays:
        us = arrays["ultrasonic"]
        _check_nonfinite_readings("ultrasonic", us, t, ids, "tcs")
        _check_negative("ultrasonic", us, None, t, ids, "tcs")
        if check_units:
            _check_median_units("ultrasonic", us, RANGE_CM_ABOVE, RANGE_MM_ABOVE)
        yaw_s = arrays["ultrasonic_yaw"]
        if not np.all(np.isfinite(yaw_s)):
            raise FlightLogError(f"ultrasonic_yaw = {yaw_s.tolist()}; expected finite mounting angles in rad")
        if check_units and np.any(np.abs(yaw_s) > 2 * math.pi + 1e-9):
            raise FlightLogError(
                f"ultrasonic_yaw = {yaw_s.tolist()} exceeds 2 pi; expected rad: looks like degrees, multiply by pi/180"
            )
        off = float(arrays["ultrasonic_offset"])
        if not math.isfinite(off) or off < 0:
            raise FlightLogError(f"ultrasonic_offset = {off!r}; expected a finite distance >= 0 m")
        if check_units:
            _check_scalar_length("ultrasonic_offset", off)

    # -- ranging --------------------------------------------------------------------------
    if "ranging" in arrays:
        rg = arrays["ranging"]
        diag = np.diagonal(rg, axis1=1, axis2=2)  # (T, N)
        bad = ~(diag == 0)  # NaN on the diagonal is wrong too
        if bad.any():
            i, c = np.argwhere(bad)[0]
            raise FlightLogError(
                f"ranging diagonal (a copter's range to itself) is {diag[i, c]} for {_where(t, ids, (i, c), 'tc')} "
                f"({_n(int(bad.sum()), 'bad diagonal value')}); expected exactly 0 on the diagonal"
            )
        _check_nonfinite_readings("ranging", rg, t, ids, "tco")
        off_diag = ~np.eye(N, dtype=bool)[None, :, :]
        _check_negative("ranging", rg, off_diag, t, ids, "tco")
        if check_units:
            _check_median_units("ranging", rg[np.broadcast_to(off_diag, rg.shape)], RANGE_CM_ABOVE, RANGE_MM_ABOVE)

    # -- imu ------------------------------------------------------------------------------
    if "imu_acc" in arrays:
        _check_nonfinite_readings("imu_acc", arrays["imu_acc"], t, ids, "tca")
        _check_nonfinite_readings("imu_gyro", arrays["imu_gyro"], t, ids, "tc")
        if check_units:
            _check_median_units("imu_acc", arrays["imu_acc"], ACC_CM_ABOVE, ACC_MM_ABOVE, "m/s^2")


_validate = validate  # load() has a parameter called validate


# ------------------------------------------------------------------------------------------
# files
# ------------------------------------------------------------------------------------------

def _with_file(path, exc: FlightLogError) -> FlightLogError:
    return FlightLogError(f"flight log {str(path)!r}: {exc}")


def save(log: FlightLog, path: str | os.PathLike, *, check_units: bool = True) -> None:
    """Validate ``log`` and write it to ``path`` as a compressed ``.npz`` (no pickles).

    The file is written exactly at ``path`` (no ``.npz`` suffix is appended) via a temporary
    file in the same directory, so a failed save leaves no partial file. Numeric arrays are
    stored as float64, ``format`` and ``meta`` as 0-d str arrays, ``copter_ids`` as a unicode
    str array, extras unchanged.
    """
    validate(log, check_units=check_units)
    arrays: dict[str, np.ndarray] = {"format": np.array(FORMAT)}
    for name in _REQUIRED + _OPTIONAL:
        v = getattr(log, name)
        if v is None:
            continue
        if name == "copter_ids":
            arrays[name] = np.asarray(_as_text(name, v, scalar=False)).astype(str)
        else:
            arrays[name] = np.asarray(v, dtype=np.float64)
    arrays["meta"] = np.array(_meta_to_json(log.meta))
    for k, v in log.extras.items():
        arrays[k] = np.asarray(v)

    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        with open(tmp, "xb") as f:  # plain open: the file gets the usual umask permissions
            np.savez_compressed(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def load(path: str | os.PathLike, validate: bool = True, *, check_units: bool = True) -> FlightLog:
    """Read a flight log ``.npz`` (``allow_pickle=False``) and, by default, :func:`validate` it.

    A missing or unreadable file, a file that is not an ``.npz`` archive, an object (pickled)
    array, a wrong or missing ``format``, missing required arrays or a ``meta`` that is not a
    JSON object always raise :class:`FlightLogError` naming the file; ``validate=False`` skips
    only the content checks of :func:`validate`. Numeric arrays are returned as float64;
    arrays the format does not name go to ``extras``.
    """
    do_validate = validate
    p = Path(path)
    if not p.exists():
        raise FlightLogError(f"flight log {str(p)!r}: file does not exist")
    try:
        npz = np.load(p, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise FlightLogError(f"flight log {str(p)!r}: cannot be read as a NumPy .npz archive ({exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise FlightLogError(f"flight log {str(p)!r}: is a single .npy array; expected an .npz archive of named arrays")
    raw: dict[str, np.ndarray] = {}
    with npz:
        for key in npz.files:
            try:
                raw[key] = npz[key]
            except ValueError as exc:
                if "allow_pickle" in str(exc) or "Object arrays" in str(exc):
                    raise FlightLogError(
                        f"flight log {str(p)!r}: array {key!r} is an object (pickled) array; expected numbers or str, no pickles"
                    ) from None
                raise FlightLogError(f"flight log {str(p)!r}: array {key!r} cannot be read ({exc})") from None
            except Exception as exc:  # corrupt member: zlib / zipfile / format errors
                raise FlightLogError(f"flight log {str(p)!r}: array {key!r} cannot be read ({type(exc).__name__}: {exc})") from None

    try:
        if "format" not in raw:
            raise FlightLogError(f"format is missing; expected a 0-d str array {FORMAT!r}")
        fmt = _as_text("format", raw["format"], scalar=True)
        if fmt != FORMAT:
            raise FlightLogError(f"format = {fmt!r}; expected exactly {FORMAT!r}")
        missing = [n for n in _REQUIRED if n not in raw]
        if missing:
            raise FlightLogError(
                f"required array{'s' if len(missing) > 1 else ''} {', '.join(missing)} missing; "
                f"a flight log needs {', '.join(_REQUIRED)}"
            )
        meta = _meta_from_json(_as_text("meta", raw["meta"], scalar=True)) if "meta" in raw else {}
        kwargs: dict[str, Any] = {}
        for name in _REQUIRED + _OPTIONAL:
            if name not in raw:
                continue
            a = raw[name]
            if name == "copter_ids":
                a = _as_text(name, a, scalar=False) if a.dtype.kind in "US" else a
            elif a.dtype.kind in "iuf":
                a = a.astype(np.float64, copy=False)
                if name == "ultrasonic_offset" and a.shape == ():
                    a = float(a)
            kwargs[name] = a
        extras = {k: v for k, v in raw.items() if k not in _STANDARD}
        log = FlightLog(**kwargs, meta=meta, extras=extras)
        if do_validate:
            _validate(log, check_units=check_units)
    except FlightLogError as exc:
        raise _with_file(p, exc) from None
    return log


# ------------------------------------------------------------------------------------------
# CSV import
# ------------------------------------------------------------------------------------------

_CSV_COLUMNS = ("t", "copter", "x", "y", "yaw")


def _natural_key(s: str):
    return [(0, int(tok), "") if tok.isdigit() else (1, 0, tok) for tok in re.split(r"(\d+)", s) if tok != ""]


def from_csv(path: str | os.PathLike, arena, *, copter_radius: float = DEFAULT_COPTER_RADIUS,
             meta: Mapping[str, Any] | None = None) -> FlightLog:
    """Import tracking data: a CSV with header ``t, copter, x, y, yaw`` (s, name, m, m, rad).

    Rows may come in any order. The result has one sample per distinct ``t`` value (sorted;
    times match exactly as parsed), copters in natural sort order of their names (``cf2``
    before ``cf10``), and ``meta`` = ``meta`` + ``copter_radius`` + ``source`` (``csv:<file
    name>`` unless given). Every copter must have exactly one row at every time: a missing or
    duplicated (copter, t) row is an error naming both, nothing is interpolated. Missing or
    unknown columns, empty or non-numeric cells are errors naming the column and line. The
    log is validated (units included) before it is returned.
    """
    import pandas as pd

    p = Path(path)
    where = f"flight log CSV {str(p)!r}"
    if not p.exists():
        raise FlightLogError(f"{where}: file does not exist")
    try:
        df = pd.read_csv(p, dtype=str, keep_default_na=False, skipinitialspace=True, skip_blank_lines=False)
    except pd.errors.EmptyDataError:
        raise FlightLogError(f"{where}: file is empty; expected a header row {', '.join(_CSV_COLUMNS)} and data rows") from None
    except (pd.errors.ParserError, UnicodeDecodeError, OSError) as exc:
        raise FlightLogError(f"{where}: cannot be parsed as CSV ({exc})") from None
    df.columns = [str(c).strip() for c in df.columns]
    cols = list(df.columns)
    missing = [c for c in _CSV_COLUMNS if c not in cols]
    unknown = [c for c in cols if c not in _CSV_COLUMNS]
    dup_cols = sorted({c for c in cols if cols.count(c) > 1})
    if missing or unknown or dup_cols:
        parts = []
        if missing:
            parts.append(f"missing column(s) {', '.join(map(repr, missing))}")
        if unknown:
            parts.append(f"unknown column(s) {', '.join(map(repr, unknown))}")
        if dup_cols:
            parts.append(f"repeated column(s) {', '.join(map(repr, dup_cols))}")
        raise FlightLogError(
            f"{where}: {'; '.join(parts)}; expected a header row with exactly the columns {', '.join(_CSV_COLUMNS)}"
        )
    lines = np.arange(len(df)) + 2  # 1-based file line numbers (line 1 is the header)
    blank = (df.fillna("").apply(lambda col: col.str.strip()) == "").all(axis=1).to_numpy()
    df, lines = df[~blank], lines[~blank]
    if len(df) == 0:
        raise FlightLogError(f"{where}: no data rows; expected rows t, copter, x, y, yaw")
    copter = [str(c) for c in df["copter"].str.strip()]
    if "" in copter:
        i = copter.index("")
        raise FlightLogError(f"{where}: column 'copter' is empty at line {lines[i]}; expected a copter name")
    values = {}
    for c in ("t", "x", "y", "yaw"):
        s = df[c].str.strip()
        num = pd.to_numeric(s, errors="coerce").to_numpy(dtype=np.float64)
        bad = ~np.isfinite(num)
        if bad.any():
            i = int(np.argmax(bad))
            raise FlightLogError(
                f"{where}: column {c!r} at line {lines[i]} (copter {copter[i]!r}) is {df[c].iloc[i]!r}; "
                f"expected a finite number ({_n(int(bad.sum()), 'bad cell')}; missing poses are not interpolated)"
            )
        values[c] = num

    times = np.unique(values["t"])
    ids = sorted(set(copter), key=lambda s: (_natural_key(s), s))
    ti = np.searchsorted(times, values["t"])
    index = {c: k for k, c in enumerate(ids)}
    ci = np.fromiter((index[c] for c in copter), dtype=np.int64, count=len(copter))
    T, N = len(times), len(ids)
    flat = ti * N + ci
    order = np.argsort(flat, kind="stable")
    sorted_flat = flat[order]
    dup = np.flatnonzero(sorted_flat[1:] == sorted_flat[:-1])
    if dup.size:
        a, b = order[dup[0]], order[dup[0] + 1]
        raise FlightLogError(
            f"{where}: copter {copter[a]!r} has more than one row at t = {_fmt(values['t'][a])} s "
            f"(lines {min(lines[a], lines[b])} and {max(lines[a], lines[b])}); expected one pose per copter and time"
        )
    seen = np.zeros(T * N, dtype=bool)
    seen[flat] = True
    if not seen.all():
        miss = np.flatnonzero(~seen)
        k = int(miss[0])
        more = f" (and {miss.size - 1} more missing (copter, t) pair(s))" if miss.size > 1 else ""
        raise FlightLogError(
            f"{where}: copter {ids[k % N]!r} has no row at t = {_fmt(times[k // N])} s{more}; "
            "expected every copter at every time (rows are not interpolated)"
        )
    pose = np.empty((T * N, 3), dtype=np.float64)
    pose[flat] = np.stack([values["x"], values["y"], values["yaw"]], axis=1)

    m = dict(meta or {})
    if "copter_radius" in m and m["copter_radius"] != copter_radius:
        raise FlightLogError(
            f"meta['copter_radius'] = {m['copter_radius']!r} disagrees with copter_radius = {copter_radius!r}; give it once"
        )
    m["copter_radius"] = copter_radius
    m.setdefault("source", f"csv:{p.name}")
    log = FlightLog(
        t=times,
        arena=np.asarray(arena),
        pose=pose.reshape(T, N, 3),
        copter_ids=np.array(ids, dtype=str),
        meta=m,
    )
    try:
        validate(log)
    except FlightLogError as exc:
        raise FlightLogError(f"{where}: {exc}") from None
    return log
