"""Hypothesis strategies for recorded data: :func:`flight_logs` (``spec/flightlog.md`` flights the loader accepts)
and :func:`recordings` (asynchronous recordings the importer turns into flights).

Ranges come from the format's own checks in :mod:`finkensim.flightlog.validation` (the unit heuristics'
limits: arena sides, scalar lengths, median sample step), so a generated log never trips a check meant for a
wrong unit. Shrinking goes toward one sample, one copter, no sensor block, no missing reading and the
simulator's own conventions.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from .models import sizes

__all__ = ["flight_logs", "recordings", "RecordingCase", "LOG_SENSORS", "NO_ECHO"]

LOG_SENSORS = ("ultrasonic", "ranging", "imu")
"""Optional sensor blocks of a flight log."""

NO_ECHO = ("nan", "max_range", "zero")
"""How imported logs write a sonar that heard no echo (``conventions=True``): NaN, the maximum range, 0."""

_MAX_READING = 10.0  # m, longest sonar / ranging reading drawn (far below the cm heuristic's limit)
_MAX_ACC = 20.0  # m/s^2
_MAX_GYRO = 10.0  # rad/s


def _floats(draw, shape, lo: float, hi: float) -> np.ndarray:
    return draw(hnp.arrays(np.float64, shape, elements=st.floats(lo, hi, allow_subnormal=False)))


def _mask(draw, shape, enabled: bool) -> np.ndarray:
    """A boolean mask (shrinks to all False); all False when not ``enabled``."""
    return draw(hnp.arrays(np.bool_, shape)) if enabled else np.zeros(shape, dtype=bool)


def _times(draw, T: int, conventions: bool) -> np.ndarray:
    """(T,) s strictly increasing: the simulator's t = k dt, or an imported clock (any origin, jittered steps)."""
    from ..flightlog.validation import T_MS_STEP_ABOVE

    dt = draw(st.floats(0.005, min(1.0, T_MS_STEP_ABOVE)))
    if not conventions:
        return dt * np.arange(T, dtype=np.float64)
    t0 = draw(st.one_of(st.floats(-100.0, 100.0), st.floats(1.5e9, 1.8e9)))  # seconds since boot or the epoch
    steps = dt * (1.0 + _floats(draw, (max(T - 1, 0),), -0.5, 0.5))
    t = t0 + np.concatenate([[0.0], np.cumsum(steps)])
    from hypothesis import assume

    assume(T < 2 or bool(np.all(np.diff(t) > 0)))  # float rounding of a large origin
    return t


@st.composite
def flight_logs(draw, *, n_steps=(1, 8), n_copters=(1, 4), sensors: Iterable[str] | None = None, n_sonars=None,
                missing: bool = True, conventions: bool = False, heights: bool = False, arena=None):
    """Valid :class:`~finkensim.flightlog.FlightLog` objects (``spec/flightlog.md``): :func:`~finkensim.flightlog.validate`,
    :func:`~finkensim.flightlog.save` and :func:`~finkensim.flightlog.load` accept them.

    Args:
        n_steps, n_copters: T and N: an int, a (low, high) pair or a strategy.
        sensors: the optional blocks present (subset of :data:`LOG_SENSORS`); default: any subset.
        n_sonars: S (as ``n_steps``); default 4 (front, left, back, right), or 1-6 with ``conventions``.
        missing: readings may be missing (NaN).
        conventions: as imported logs from other tools and arenas write them (see ``finkensim.gap.validation.conventions``):
            a clock with any origin and jittered steps, unwrapped yaw, any sonar layout and offset, a lost echo
            written as NaN, the maximum range or 0, tracking noise and a source in ``meta``, extra arrays, copter
            names of any text. Without: the simulator's own (t = k dt, yaw in [−π, π), four sonars at the centre).
        heights: per-copter heights. The hook for the height block another change adds to the format; the
            format has none yet, so True raises NotImplementedError.
        arena: (width, length) m, or None to draw both (0.5 m up to the validator's cm limit).
    """
    from ..flightlog import DEFAULT_COPTER_RADIUS, DEFAULT_SONAR_YAW, FlightLog
    from ..flightlog.validation import ARENA_CM_ABOVE, SCALAR_LIMITS

    if heights:
        raise NotImplementedError("flight_logs(heights=True): flight-log format 1 has no height block yet; this "
                                  "parameter is the hook for it")
    chosen = tuple(LOG_SENSORS) if sensors is None else tuple(sensors)
    bad = [s for s in chosen if s not in LOG_SENSORS]
    if bad:
        raise ValueError(f"sensors = {tuple(sensors)!r}: expected names from {LOG_SENSORS}")
    present = [s for s in chosen if draw(st.booleans())] if sensors is None else list(chosen)
    T = draw(sizes(n_steps, 1, 10**7))
    N = draw(sizes(n_copters, 1, 10**5))
    if arena is None:
        big = ARENA_CM_ABOVE if conventions else 10.0
        width, length = draw(st.floats(0.5, big)), draw(st.floats(0.5, big))
    else:
        width, length = float(arena[0]), float(arena[1])
    t = _times(draw, T, conventions)
    pose = np.empty((T, N, 3))
    pose[..., 0] = width * _floats(draw, (T, N), 0.0, 1.0)
    pose[..., 1] = length * _floats(draw, (T, N), 0.0, 1.0)
    if conventions:  # unwrapped heading: a start within 1.5 turns, then turns of up to 10 rad/s and one turn in all
        step = np.diff(t, prepend=t[0])[:, None]
        rate = min(10.0, 2 * math.pi / max(float(t[-1] - t[0]), 1e-9))  # (the loader reads > 3 turns as degrees)
        pose[..., 2] = np.cumsum(_floats(draw, (T, N), -rate, rate) * step, axis=0) \
            + _floats(draw, (1, N), -3 * math.pi, 3 * math.pi)
    else:
        pose[..., 2] = _floats(draw, (T, N), -math.pi, math.pi)
    radius = draw(st.floats(0.01, 0.5)) if conventions else DEFAULT_COPTER_RADIUS
    meta: dict[str, Any] = {"copter_radius": radius, "altitude": draw(st.floats(0.05, 3.0)) if conventions else 0.6,
                            "source": "finkensim.testing.flight_logs"}
    ids = [f"cf{k}" for k in range(N)]
    extras: dict[str, np.ndarray] = {}
    if conventions:
        meta["tracking_sigma_xy"] = draw(st.floats(0.0, min(0.05, SCALAR_LIMITS["meta['tracking_sigma_xy']"])))
        meta["tracking_sigma_yaw"] = draw(st.floats(0.0, 0.2))
        ids = draw(st.lists(st.text(st.characters(categories=("L", "N"), include_characters="_-"), min_size=1,
                                    max_size=6), min_size=N, max_size=N, unique=True))
        if draw(st.booleans()):
            extras["clock_offset"] = np.array(draw(st.floats(-1.0, 1.0)))
    kw: dict[str, Any] = {}
    if "ultrasonic" in present:
        S = draw(sizes(n_sonars, 1, 64)) if n_sonars is not None else (draw(st.integers(1, 6)) if conventions else 4)
        if conventions:
            yaw_s = _floats(draw, (S,), -math.pi, math.pi)
            offset = draw(st.floats(0.0, min(0.3, SCALAR_LIMITS["ultrasonic_offset"])))
        else:
            yaw_s = np.array((DEFAULT_SONAR_YAW * (S // 4 + 1))[:S])
            offset = 0.0
        max_range = draw(st.floats(0.5, _MAX_READING))
        us = max_range * _floats(draw, (T, N, S), 0.0, 1.0)
        no_echo = _mask(draw, (T, N, S), missing)
        us[no_echo] = {"nan": np.nan, "max_range": max_range, "zero": 0.0}[
            draw(st.sampled_from(NO_ECHO)) if conventions else "nan"]
        kw.update(ultrasonic=us, ultrasonic_yaw=yaw_s, ultrasonic_offset=offset)
        if conventions:
            meta["sonar_max_range"] = max_range
    if "ranging" in present:
        rg = _floats(draw, (T, N, N), 0.0, _MAX_READING)
        rg[_mask(draw, (T, N, N), missing)] = np.nan
        rg[:, np.arange(N), np.arange(N)] = 0.0
        kw["ranging"] = rg
    if "imu" in present:
        acc = _floats(draw, (T, N, 2), -_MAX_ACC, _MAX_ACC)
        gyro = _floats(draw, (T, N), -_MAX_GYRO, _MAX_GYRO)
        acc[_mask(draw, (T, N, 2), missing)] = np.nan
        gyro[_mask(draw, (T, N), missing)] = np.nan
        kw.update(imu_acc=acc, imu_gyro=gyro)
    return FlightLog(t=t, arena=np.array([width, length]), pose=pose, copter_ids=np.array(ids), meta=meta,
                     extras=extras, **kw)


@dataclass(frozen=True)
class RecordingCase:
    """An asynchronous recording and what the importer needs with it.

    ``recording`` (:class:`~finkensim.importing.Recording`); ``arena`` (width, length) m; ``sonar_yaw`` (S,) rad
    and ``sonar_offset`` m (None without sonar channels); ``clock_offset`` s, the offset to add to reading times
    (known, as the recording was made with it); ``flight``, the synchronous flight it was exported from.
    """

    recording: Any
    arena: tuple[float, float]
    sonar_yaw: Any
    sonar_offset: float | None
    clock_offset: float
    flight: Any

    def import_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`finkensim.importing.build_flight` besides the recording."""
        return dict(arena=self.arena, sonar_yaw=self.sonar_yaw, sonar_offset=self.sonar_offset,
                    clock_offset=self.clock_offset)

    def build(self):
        """The imported :class:`~finkensim.flightlog.FlightLog`: ``build_flight(recording, **import_kwargs())``."""
        from ..importing import build_flight

        return build_flight(self.recording, **self.import_kwargs())


@st.composite
def recordings(draw, *, n_copters=(1, 3), sensors: Iterable[str] | None = None, missing: bool = True,
               clock_offset=st.floats(-0.5, 0.5)):
    """:class:`RecordingCase` objects: a flight (:func:`flight_logs`, 10-40 samples at 20-100 Hz) exported as an
    arena records it (:func:`~finkensim.importing.to_recording`: tracking and each sensor stream at its own
    rate, timing jitter, sensor times on a clock ``clock_offset`` s behind the tracking clock).
    :func:`~finkensim.importing.check_recording` and :func:`~finkensim.importing.build_flight` accept them.

    ``sensors`` and ``missing`` as in :func:`flight_logs`; ``clock_offset`` a number or a strategy (s).
    """
    from ..importing import to_recording

    rate = draw(st.sampled_from([20.0, 50.0, 100.0]))
    T = draw(st.integers(10, 40))
    flight = draw(flight_logs(n_steps=T, n_copters=n_copters, sensors=sensors, missing=missing))
    flight.t[:] = np.arange(T) / rate
    offset = draw(clock_offset) if isinstance(clock_offset, st.SearchStrategy) else float(clock_offset)

    def stream_rate():
        return draw(st.floats(rate / 4, rate))

    rec = to_recording(flight, tracking_rate=rate, sonar_rate=stream_rate(), ranging_rate=stream_rate(),
                       imu_rate=stream_rate(), jitter=draw(st.floats(0.0, 0.3)), clock_offset=offset,
                       seed=draw(st.integers(0, 2**32 - 1)))
    sonar = flight.ultrasonic is not None
    return RecordingCase(recording=rec, arena=(float(flight.arena[0]), float(flight.arena[1])),
                         sonar_yaw=flight.ultrasonic_yaw if sonar else None,
                         sonar_offset=float(flight.ultrasonic_offset) if sonar else None,
                         clock_offset=offset, flight=flight)
