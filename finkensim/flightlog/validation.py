"""Checking a :class:`~finkensim.flightlog.format.FlightLog` against format version 1.

:func:`validate` runs one small check per group of arrays (types, blocks, shapes, time, arena,
meta, copter ids, pose, ultrasonic, ranging, IMU) in that order and raises the first problem as
a :class:`~finkensim.flightlog.format.FlightLogError` naming the array, what is wrong and what
was expected. Unit heuristics flag values that look like centimetres, millimetres or degrees;
nothing is ever rescaled.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from .encoding import as_text, meta_to_json
from .format import (BLOCKS, DEFAULT_COPTER_RADIUS, HEIGHTS, NUMERIC, REQUIRED, RESERVED_EXTRAS, STANDARD, FlightLog,
                     FlightLogError)
from .messages import fmt, plural, shape_text, unit_hint, where

__all__ = [
    "validate",
    "ARENA_CM_ABOVE",
    "ARENA_MM_ABOVE",
    "RANGE_CM_ABOVE",
    "RANGE_MM_ABOVE",
    "ACC_CM_ABOVE",
    "ACC_MM_ABOVE",
    "POSE_SCALE_FACTOR",
    "SCALAR_LIMITS",
    "T_MS_STEP_ABOVE",
    "T_MS_STEP_FROM",
    "T_MS_SPAN_ABOVE",
    "YAW_DEG_RATE_ABOVE",
    "INTEGER_ALLOWED",
    "check_dtype",
]

# --- unit heuristics (documented in :func:`validate`) -------------------------------------
ARENA_CM_ABOVE = 100.0       # an arena side > 100 "m" is a side in cm ...
ARENA_MM_ABOVE = 1000.0      # ... and > 1000 "m" a side in mm
RANGE_CM_ABOVE = 50.0        # median sonar / ranging reading > 50 "m": cm ...
RANGE_MM_ABOVE = 500.0       # ... > 500 "m": mm
ACC_CM_ABOVE = 50.0          # median |imu_acc| > 50 "m/s^2": cm/s^2 ...
ACC_MM_ABOVE = 500.0         # ... > 500: mm/s^2
T_MS_STEP_ABOVE = 5.0        # median sample step > 5 "s" (that is plausible / 1000): t in ms ...
T_MS_STEP_FROM = 0.5         # ... and a step >= 0.5 "s" (the importer's threshold) over a flight longer than
T_MS_SPAN_ABOVE = 3600.0     # one hour (no battery flies that long; a 200 Hz tracker in ms spans 1000 "s" in 5 s)
YAW_DEG_RATE_ABOVE = 20.0    # pose yaw beyond 2 pi turning faster than 20 "rad"/s (90th percentile): degrees ...
YAW_DEG_MEDIAN_ABOVE = 6 * math.pi  # ... or a median |yaw| beyond three turns (radians a tracker accumulated over
                                    # a turn or two, or a constant offset of a few rad, pass)
POSE_SCALE_FACTOR = 10.0     # poses > 10x the arena that fit it after /100 (/1000): cm (mm)
SCALAR_LIMITS = {            # scalar lengths above these limits (m) look like cm or mm
    "ultrasonic_offset": 1.0,
    "meta['copter_radius']": 2.0,
    "meta['altitude']": 20.0,
    "meta['tracking_sigma_xy']": 1.0,
}


INTEGER_ALLOWED = ("arena", "ultrasonic_offset")
"""Numeric arrays that may be stored as integers (whole metres are exact there); every other
numeric array must be floating point: an integer ``pose``, ``t`` or reading array has been
truncated (or is in another unit, e.g. t in ms) and is an error, never silently converted."""


def check_dtype(name: str, arr: Any) -> np.ndarray:
    """Return ``arr`` as an array, or raise if its dtype is not a real number type (float64 in the spec).

    Integers are accepted only for :data:`INTEGER_ALLOWED`; an integer ``pose`` would be whole
    metres, an integer ``t`` whole seconds (or milliseconds): both are named errors.
    """
    a = np.asarray(arr)
    if a.dtype.kind not in "iuf":
        kind = {"b": "bool", "c": "complex", "O": "object (pickled)", "U": "str", "S": "bytes"}.get(a.dtype.kind, str(a.dtype))
        raise FlightLogError(f"{name} has dtype {a.dtype} ({kind}); expected float64 numbers")
    if a.dtype.kind in "iu" and name not in INTEGER_ALLOWED and a.size:
        unit = "s (or ms)" if name == "t" else "whole units"
        raise FlightLogError(
            f"{name} has integer dtype {a.dtype}; expected float64 (integers are truncated to {unit}); "
            f"write {name} as float64, nothing is converted"
        )
    return a


def _check_nonfinite_readings(name: str, a: np.ndarray, t, ids, axes: str) -> None:
    """Raise if readings ``a`` hold +-inf (NaN, a missing reading, is fine); ``axes`` as in :func:`where`."""
    bad = np.isinf(a)
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        raise FlightLogError(
            f"{name} has {plural(int(bad.sum()), 'infinite value')} (first {fmt(float(a[idx]))} at {where(t, ids, idx, axes)}); "
            "expected finite values, NaN for a missing reading"
        )


def _check_negative(name: str, a: np.ndarray, mask, t, ids, axes: str) -> None:
    """Raise if distances ``a`` (m) are negative where ``mask`` (broadcastable bool, None = all) is set."""
    with np.errstate(invalid="ignore"):
        bad = a < 0  # NaN compares False: missing readings are ignored
    if mask is not None:
        bad &= mask
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        raise FlightLogError(
            f"{name} has {plural(int(bad.sum()), 'negative reading')} (first {fmt(float(a[idx]))} m at {where(t, ids, idx, axes)}); "
            "expected distances >= 0 m, NaN for a missing reading"
        )


def _check_median_units(name: str, values: np.ndarray, cm_above: float, mm_above: float, unit: str = "m") -> None:
    """Raise if the median finite ``|values|`` (any shape, in ``unit``) looks like cm or mm (see :func:`unit_hint`)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return
    med = float(np.median(np.abs(finite)))
    hint = unit_hint(med, cm_above, mm_above, unit)
    if hint:
        raise FlightLogError(
            f"{name} has median |value| {fmt(med)}, implausibly large for {unit} (> {fmt(cm_above)}); "
            f"expected {unit}: {name} {hint}"
        )


def _check_scalar_length(name: str, value: float) -> None:
    """Raise if the length ``value`` (m) exceeds its :data:`SCALAR_LIMITS` entry (looks like cm or mm)."""
    limit = SCALAR_LIMITS[name]
    if value > limit:
        raise FlightLogError(
            f"{name} = {fmt(value)} is implausibly large for m (> {fmt(limit)}); expected metres: "
            "looks like centimetres (divide by 100) or millimetres (divide by 1000)"
        )


def _meta_number(meta: Mapping, key: str, *, positive: bool) -> float | None:
    """``meta[key]`` as a finite float (> 0 if ``positive``, else >= 0), or None if absent."""
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
    def fits(xs, ys, w, length):
        return bool(np.all((xs >= -r) & (xs <= w + r) & (ys >= -r) & (ys <= length + r)))

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
    infinities (NaN is the only "no reading"), the optional extra ``z`` (T, N) m heights finite, no negative distances (NaN ignored), ranging
    diagonal exactly 0 (NaN there is an error); integer dtypes only for ``arena`` and
    ``ultrasonic_offset`` (an integer ``pose`` or ``t`` is an error, never truncated); ``ultrasonic_yaw`` finite and within +-2 pi
    (larger values look like degrees); ``ultrasonic_offset`` finite and >= 0.

    Unit heuristics (``check_units=False`` turns them off; nothing is ever rescaled):

    * ``t``: a median sample step > 5 s looks like milliseconds.
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

    * ``t`` also: a median step >= 0.5 s over a span above one hour looks like milliseconds (a 200 Hz
      tracker in ms has steps of 5 "s"; no copter flies an hour).
    * ``pose`` yaw: beyond 2 pi in magnitude and either with a median magnitude beyond 6 pi (three turns) or
      turning faster than 20 per second at the 90th percentile looks like degrees (wrap jumps of 2 pi or 360 are
      not turns); unwrapped radians over a few slow turns, or offset by a few rad, pass. ``imu_gyro`` is not unit-checked.
    """
    if not isinstance(log, FlightLog):
        raise FlightLogError(f"expected a FlightLog, got {type(log).__name__}")
    arrays, ids = _check_arrays(log)
    meta_to_json(log.meta)  # type check and JSON check
    _check_extras(log.extras)
    _check_blocks(log)
    _check_shapes(arrays, ids)
    t = arrays["t"]
    _check_time(t, check_units)
    width, length = _check_arena(arrays["arena"], check_units)
    radius = _check_meta(log.meta, check_units)
    _check_copter_ids(ids)
    _check_pose(arrays["pose"], t, ids, (width, length), radius, check_units)
    if check_units:
        _check_yaw_degrees(arrays["pose"][..., 2], t, ids)
    if "ultrasonic" in arrays:
        _check_ultrasonic(arrays, t, ids, check_units)
    if "ranging" in arrays:
        _check_ranging(arrays["ranging"], t, ids, check_units)
    if "imu_acc" in arrays:
        _check_imu(arrays["imu_acc"], arrays["imu_gyro"], t, ids, check_units)
    if HEIGHTS in log.extras:
        _check_heights(np.asarray(log.extras[HEIGHTS]), t, ids, check_units)


def _check_heights(z: np.ndarray, t: np.ndarray, ids: np.ndarray, check_units: bool) -> None:
    """The optional extra ``z`` (T, N) m, each copter's height: real numbers of that shape, finite (a height is
    tracked with the pose), median |z| not like cm or mm."""
    shape = (t.shape[0], ids.shape[0])
    if z.dtype.kind not in "iuf" or z.shape != shape:
        raise FlightLogError(f"z (heights) has shape {z.shape} and dtype {z.dtype}; expected float64 of shape (T, N) = "
                             f"{shape}, each copter's height in m")
    bad = ~np.isfinite(z)
    if bad.any():
        i, c = np.argwhere(bad)[0]
        raise FlightLogError(f"z (heights) is {z[i, c]} for {where(t, ids, (i, c), 'tc')} ({plural(int(bad.sum()), 'bad value')}); "
                             "expected finite heights in m (heights come with the tracked pose)")
    if check_units:
        _check_median_units("z (heights)", z.astype(np.float64), RANGE_CM_ABOVE, RANGE_MM_ABOVE)


# ------------------------------------------------------------------------------------------
# the groups, in the order validate() runs them
# ------------------------------------------------------------------------------------------

def _check_arrays(log: FlightLog) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Required arrays present, numeric ones of a real dtype, ``copter_ids`` text.

    Returns ({name: float64 array} for every numeric array present, copter_ids as a str array).
    """
    for name in REQUIRED:
        if getattr(log, name) is None:
            raise FlightLogError(f"{name} is missing; a flight log needs {', '.join(REQUIRED)}")
    arrays: dict[str, np.ndarray] = {}
    for name in NUMERIC:
        v = getattr(log, name)
        if v is not None:
            arrays[name] = check_dtype(name, v).astype(np.float64, copy=False)
    ids = as_text("copter_ids", log.copter_ids, scalar=False)
    return arrays, ids


def _check_extras(extras: Any) -> None:
    """Extras: a dict of plain (numeric, str, time) arrays with names free for ``np.savez``."""
    if not isinstance(extras, Mapping):
        raise FlightLogError(f"extras is a {type(extras).__name__}; expected a dict of arrays")
    for k, v in extras.items():
        if not isinstance(k, str) or not k:
            raise FlightLogError(f"extras key {k!r}: expected a non-empty str array name")
        if k in STANDARD:
            raise FlightLogError(f"extras['{k}'] clashes with the standard array {k!r}; set the FlightLog field instead")
        if k in RESERVED_EXTRAS:
            raise FlightLogError(f"extras['{k}']: {k!r} is reserved by np.savez_compressed; rename the array")
        try:
            a = np.asarray(v)
        except (ValueError, TypeError) as exc:
            raise FlightLogError(f"extras['{k}'] cannot be converted to an array ({exc}); expected a rectangular array") from None
        if a.dtype.kind not in "biufcUSmM":
            raise FlightLogError(f"extras['{k}'] has dtype {a.dtype}; expected numbers or str (no pickled objects)")


def _check_blocks(log: FlightLog) -> None:
    """Every all-or-nothing block (:data:`BLOCKS`) entirely present or entirely absent."""
    for block, names in BLOCKS.items():
        present = [n for n in names if getattr(log, n) is not None]
        if present and len(present) != len(names):
            missing = [n for n in names if n not in present]
            raise FlightLogError(
                f"{', '.join(present)} {'is' if len(present) == 1 else 'are'} present but {', '.join(missing)} "
                f"{'is' if len(missing) == 1 else 'are'} missing; the {block} block is all-or-nothing: {', '.join(names)}"
            )


def _check_shapes(arrays: Mapping[str, np.ndarray], ids: np.ndarray) -> None:
    """Shapes against T = len(t) >= 1, N = len(copter_ids) >= 1, S = len(ultrasonic_yaw) >= 1."""
    t = arrays["t"]
    if t.ndim != 1:
        raise FlightLogError(f"t has shape {shape_text(t.shape)}; expected (T,)")
    if ids.ndim != 1:
        raise FlightLogError(f"copter_ids has shape {shape_text(ids.shape)}; expected (N,)")
    T, N = t.shape[0], ids.shape[0]
    if T == 0:
        raise FlightLogError("t is empty, shape (0,); expected at least one sample")
    if N == 0:
        raise FlightLogError("copter_ids is empty, shape (0,); expected at least one copter")
    tn = "T = len(t), N = len(copter_ids)"
    expected = {
        "arena": ((2,), "(2,) = (width, length)"),
        "pose": ((T, N, 3), f"(T, N, 3) = {shape_text((T, N, 3))} with {tn}"),
        "ranging": ((T, N, N), f"(T, N, N) = {shape_text((T, N, N))} with {tn}"),
        "imu_acc": ((T, N, 2), f"(T, N, 2) = {shape_text((T, N, 2))} with {tn}"),
        "imu_gyro": ((T, N), f"(T, N) = {shape_text((T, N))} with {tn}"),
    }
    if "ultrasonic_yaw" in arrays:
        yaw_s = arrays["ultrasonic_yaw"]
        if yaw_s.ndim != 1:
            raise FlightLogError(f"ultrasonic_yaw has shape {shape_text(yaw_s.shape)}; expected (S,)")
        S = yaw_s.shape[0]
        if S == 0:
            raise FlightLogError("ultrasonic_yaw is empty, shape (0,); expected at least one sonar (or no ultrasonic block)")
        expected["ultrasonic"] = ((T, N, S), f"(T, N, S) = {shape_text((T, N, S))} with {tn}, S = len(ultrasonic_yaw)")
        expected["ultrasonic_offset"] = ((), "a scalar, shape ()")
    for name, (shape, text) in expected.items():
        if name in arrays and arrays[name].shape != shape:
            raise FlightLogError(f"{name} has shape {shape_text(arrays[name].shape)}; expected {text}")


def _check_time(t: np.ndarray, check_units: bool) -> None:
    """``t`` (T,) in s: finite, strictly increasing, and (with ``check_units``) not in ms.

    A median sample step above :data:`T_MS_STEP_ABOVE` s looks like milliseconds.
    """
    if not np.all(np.isfinite(t)):
        i = int(np.argwhere(~np.isfinite(t))[0, 0])
        raise FlightLogError(f"t[{i}] = {t[i]}; expected finite sample times in s")
    if t.shape[0] > 1:
        dt = np.diff(t)
        if np.any(dt <= 0):
            i = int(np.argwhere(dt <= 0)[0, 0])
            raise FlightLogError(
                f"t is not strictly increasing: t[{i}] = {fmt(t[i])} s, t[{i + 1}] = {fmt(t[i + 1])} s "
                f"({plural(int(np.sum(dt <= 0)), 'non-increasing step')}); expected strictly increasing sample times"
            )
        step, span = float(np.median(dt)), float(t[-1] - t[0])
        if check_units and step > T_MS_STEP_ABOVE:
            raise FlightLogError(
                f"t has median sample step {fmt(step)}, implausibly long for s (> {fmt(T_MS_STEP_ABOVE)}); "
                "expected seconds: t looks like milliseconds: divide by 1000"
            )
        if check_units and step >= T_MS_STEP_FROM and span > T_MS_SPAN_ABOVE:
            raise FlightLogError(
                f"t has median sample step {fmt(step)} over a span of {fmt(span)}, implausible for s (a step >= "
                f"{fmt(T_MS_STEP_FROM)} s over more than {fmt(T_MS_SPAN_ABOVE)} s); expected seconds: t looks like "
                "milliseconds: divide by 1000"
            )


def _check_arena(arena: np.ndarray, check_units: bool) -> tuple[float, float]:
    """``arena`` (2,) finite and > 0 (and not in cm or mm); returns (width, length) in m."""
    if not np.all(np.isfinite(arena)) or np.any(arena <= 0):
        raise FlightLogError(f"arena = [{', '.join(fmt(a) for a in arena)}]; expected finite width and length > 0 m")
    width, length = float(arena[0]), float(arena[1])
    if check_units:
        hint = unit_hint(max(width, length), ARENA_CM_ABOVE, ARENA_MM_ABOVE)
        if hint:
            raise FlightLogError(
                f"arena = [{fmt(width)}, {fmt(length)}] is implausibly large for m (> {fmt(ARENA_CM_ABOVE)}); "
                f"expected metres: arena {hint}"
            )
    return width, length


def _check_meta(meta: Mapping, check_units: bool) -> float:
    """The ``meta`` fields the format names; returns the copter radius in m (default 0.15)."""
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
    return radius


def _check_copter_ids(ids: np.ndarray) -> None:
    """``copter_ids`` (N,) unique."""
    uniq, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):
        dups = [str(u) for u in uniq[counts > 1]]
        raise FlightLogError(f"copter_ids has duplicates {dups}; expected unique names")


def _check_pose(pose: np.ndarray, t: np.ndarray, ids: np.ndarray, size: tuple[float, float], radius: float,
                check_units: bool) -> None:
    """``pose`` (T, N, 3) finite and inside the arena ``size`` = (width, length) m up to ``radius`` m."""
    width, length = size
    finite = np.isfinite(pose)
    if not finite.all():
        idx = tuple(np.argwhere(~finite)[0])
        raise FlightLogError(
            f"pose has {plural(int((~finite).sum()), 'non-finite value')} (first {pose[idx]} at "
            f"{where(t, ids, idx[:2], 'tc')}, {'xyz'[idx[2]] if idx[2] < 2 else 'yaw'}); "
            "expected finite ground-truth poses (no NaN: the tracking system must see every copter)"
        )
    x, y = pose[..., 0], pose[..., 1]
    out = np.maximum.reduce([-x, x - width, -y, y - length])  # distance outside the arena box (per axis)
    bad = out > radius
    if bad.any():
        idx = tuple(np.argwhere(bad)[0])
        hint = _pose_hint(x, y, width, length, radius) if check_units else ""
        raise FlightLogError(
            f"pose is outside the arena: copter {str(ids[idx[1]])!r} at t = {fmt(t[idx[0]])} s (step {idx[0]}) is at "
            f"({fmt(x[idx])}, {fmt(y[idx])}) m, {fmt(out[idx])} m outside [0, {fmt(width)}] x [0, {fmt(length)}] m "
            f"({plural(int(bad.sum()), 'sample')} outside); expected at most copter_radius = {fmt(radius)} m outside{hint}"
        )


def _check_ultrasonic(arrays: Mapping[str, np.ndarray], t: np.ndarray, ids: np.ndarray, check_units: bool) -> None:
    """The ultrasonic block: readings (T, N, S) m, ``ultrasonic_yaw`` (S,) rad, ``ultrasonic_offset`` m."""
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


def _check_ranging(rg: np.ndarray, t: np.ndarray, ids: np.ndarray, check_units: bool) -> None:
    """``ranging`` (T, N, N) m: diagonal exactly 0, off-diagonal readings >= 0 or NaN."""
    N = ids.shape[0]
    diag = np.diagonal(rg, axis1=1, axis2=2)  # (T, N)
    bad = ~(diag == 0)  # NaN on the diagonal is wrong too
    if bad.any():
        i, c = np.argwhere(bad)[0]
        raise FlightLogError(
            f"ranging diagonal (a copter's range to itself) is {diag[i, c]} for {where(t, ids, (i, c), 'tc')} "
            f"({plural(int(bad.sum()), 'bad diagonal value')}); expected exactly 0 on the diagonal"
        )
    _check_nonfinite_readings("ranging", rg, t, ids, "tco")
    off_diag = ~np.eye(N, dtype=bool)[None, :, :]
    _check_negative("ranging", rg, off_diag, t, ids, "tco")
    if check_units:
        _check_median_units("ranging", rg[np.broadcast_to(off_diag, rg.shape)], RANGE_CM_ABOVE, RANGE_MM_ABOVE)


def _check_imu(acc: np.ndarray, gyro: np.ndarray, t: np.ndarray, ids: np.ndarray, check_units: bool) -> None:
    """The IMU block: ``imu_acc`` (T, N, 2) m/s^2 and ``imu_gyro`` (T, N) rad/s without infinities."""
    _check_nonfinite_readings("imu_acc", acc, t, ids, "tca")
    _check_nonfinite_readings("imu_gyro", gyro, t, ids, "tc")
    if check_units:
        _check_median_units("imu_acc", acc, ACC_CM_ABOVE, ACC_MM_ABOVE, "m/s^2")


def _check_yaw_degrees(yaw: np.ndarray, t: np.ndarray, ids: np.ndarray) -> None:
    """Raise if the pose yaw (T, N) looks like degrees (see :func:`validate`, :data:`YAW_DEG_RATE_ABOVE`)."""
    top = float(np.max(np.abs(yaw))) if yaw.size else 0.0
    if top <= 2 * math.pi + 1e-9:
        return
    d = np.abs(np.diff(yaw, axis=0))  # (T-1, N) per copter
    dt = np.diff(t)[:, None]
    turn = ~((np.abs(d - 2 * math.pi) < 0.5) | (np.abs(d - 360.0) < 5.0))
    rate = (d / dt)[turn]
    p90 = float(np.quantile(rate, 0.9)) if rate.size else 0.0
    med = float(np.median(np.abs(yaw)))
    if med > YAW_DEG_MEDIAN_ABOVE or p90 > YAW_DEG_RATE_ABOVE:
        c = int(np.argmax(np.max(np.abs(yaw), axis=0)))
        raise FlightLogError(
            f"pose yaw reaches {fmt(top)} (copter {str(ids[c])!r}; median |yaw| {fmt(med)}, 90th-percentile turn "
            f"rate {fmt(p90)} per s); expected rad: looks like degrees, multiply by pi/180 (if it is radians "
            "accumulated over many turns, wrap it to [-pi, pi))"
        )
