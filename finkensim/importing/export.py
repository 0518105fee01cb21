"""Turn a synchronous (simulated) flight into an asynchronous recording, as an arena would record it.

:func:`to_recording` is the inverse of the import for tests and demonstrations: tracking at its own rate, each
sonar, ranging pair and IMU at its own rate with timing jitter, every sensor stamped on a clock that is
``clock_offset`` seconds behind the tracking clock. Values are never interpolated: every sample is the flight's own
value at one of its sample times (a jittered time is snapped to the nearest sample of the flight), so the flight
should be recorded faster than every exported rate (e.g. simulated at 100 Hz). :func:`write_csv` writes the two
CSV files that :func:`~.csvtables.read_csv` reads (times and values at full precision).
"""
from __future__ import annotations

import os

import numpy as np

from .recording import OPTIONAL_TRACKING_COLUMNS, READING_COLUMNS, TRACKING_COLUMNS, Recording, RecordingError

__all__ = ["to_recording", "write_csv"]


def _channel_samples(T: int, dt: float, rate: float, jitter: float, rng) -> np.ndarray:
    """Sample indices (increasing, unique) of one channel at ``rate`` Hz with a random phase and Gaussian timing
    jitter of ``jitter`` periods (std), snapped to the flight's samples (period dt)."""
    period = 1.0 / rate
    nominal = rng.uniform(0, period) + period * np.arange(int(T * dt / period) + 1)
    times = nominal + rng.normal(0.0, jitter * period, nominal.size)
    k = np.rint(times / dt).astype(np.int64)
    k = k[(k >= 0) & (k < T)]
    return np.unique(k)


def to_recording(flight, *, tracking_rate: float = 100.0, sonar_rate: float = 20.0, ranging_rate: float = 10.0,
                 imu_rate: float | None = None, jitter: float = 0.1, clock_offset: float = 0.0,
                 seed: int = 0) -> Recording:
    """An asynchronous :class:`~.recording.Recording` of a :class:`~finkensim.flightlog.FlightLog` (module doc).

    Args:
        flight: a flight log with a uniform time step (e.g. from :func:`finkensim.simulate_flight`).
        tracking_rate, sonar_rate, ranging_rate, imu_rate: samples per second of each stream (imu_rate default:
            the flight's own rate); at most the flight's rate.
        jitter: timing jitter of the sensor streams, as a standard deviation in periods of their own rate.
        clock_offset: s; sensor times are stamped ``t − clock_offset``, so ``clock_offset`` is what the import must
            add back (its ``clock_offset`` argument).
        seed: seed of the phases and jitter.
    """
    import pandas as pd

    t = np.asarray(flight.t, dtype=np.float64)
    T, N = flight.n_steps, flight.n_copters
    if T < 2:
        raise RecordingError(f"flight has {T} sample(s): expected at least 2 to export")
    dt = float(np.median(np.diff(t)))
    rate = 1.0 / dt
    imu_rate = rate if imu_rate is None else imu_rate
    for name, r in (("tracking_rate", tracking_rate), ("sonar_rate", sonar_rate), ("ranging_rate", ranging_rate),
                    ("imu_rate", imu_rate)):
        if not (np.isfinite(r) and 0 < r <= rate * (1 + 1e-9)):
            raise RecordingError(f"{name} = {r!r}: expected a rate in (0, {rate:g}] Hz (the flight's own rate)")
    rng = np.random.default_rng(seed)
    ids = [str(c) for c in flight.copter_ids]
    step = max(1, int(round(rate / tracking_rate)))
    tk = np.arange(0, T, step)
    tracking = pd.DataFrame({
        "t": np.tile(t[tk], N), "copter": np.repeat(ids, tk.size),
        "x": flight.pose[tk, :, 0].T.reshape(-1), "y": flight.pose[tk, :, 1].T.reshape(-1),
        "yaw": flight.pose[tk, :, 2].T.reshape(-1)})
    parts = []

    def add(n, channel, ks, values):
        parts.append(pd.DataFrame({"t": t[ks] - clock_offset, "copter": ids[n], "channel": channel, "value": values}))

    for n in range(N):
        if flight.ultrasonic is not None:
            for s in range(flight.n_sonars):
                ks = _channel_samples(T, dt, sonar_rate, jitter, rng)
                add(n, f"ultrasonic/{s}", ks, flight.ultrasonic[ks, n, s])
        if flight.ranging is not None:
            for o in range(N):
                if o != n:
                    ks = _channel_samples(T, dt, ranging_rate, jitter, rng)
                    add(n, f"ranging/{ids[o]}", ks, flight.ranging[ks, n, o])
        if flight.imu_acc is not None:
            ks = _channel_samples(T, dt, imu_rate, jitter, rng)
            add(n, "imu/acc_x", ks, flight.imu_acc[ks, n, 0])
            add(n, "imu/acc_y", ks, flight.imu_acc[ks, n, 1])
            add(n, "imu/gyro", ks, flight.imu_gyro[ks, n])
    readings = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame({c: [] for c in READING_COLUMNS})
    return Recording(tracking=tracking[list(TRACKING_COLUMNS)], readings=readings[list(READING_COLUMNS)],
                     source=f"export of {flight.meta.get('source', 'a flight')}",
                     notes={"exported": dict(tracking_rate=tracking_rate, sonar_rate=sonar_rate,
                                             ranging_rate=ranging_rate, imu_rate=imu_rate, jitter=jitter,
                                             clock_offset=clock_offset, seed=seed)})


def write_csv(rec: Recording, tracking_path: str | os.PathLike, readings_path: str | os.PathLike) -> None:
    """Write a recording as the tracking and readings CSV files of :func:`~.csvtables.read_csv` (atomically); the
    tracking's optional ``z`` column (m) is written when the recording has it."""
    from ..atomic import write_atomic

    cols = list(TRACKING_COLUMNS) + [c for c in OPTIONAL_TRACKING_COLUMNS if c in rec.tracking.columns]
    write_atomic(tracking_path, lambda tmp: rec.tracking.to_csv(tmp, index=False, columns=cols))
    write_atomic(readings_path, lambda tmp: rec.readings.to_csv(tmp, index=False, columns=list(READING_COLUMNS)))
