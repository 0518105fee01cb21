"""Align an asynchronous recording on one time base and build its flight log.

:func:`build_flight` turns a :class:`~.recording.Recording` (every copter tracked at its own times, every sensor
reading at its own time, possibly on another clock) into one ``docs/formats/flightlog.md`` flight:

1. **Check** the tables (:func:`~.recording.check_recording`) and the units against the arena.
2. **Clock offset**: reading time on the tracking clock = reading time + offset; ``"auto"`` estimates it from the
   data (:func:`~.clock.estimate_offset`), a number is used as given.
3. **Time base**: samples ``t_k = t_0 + k / rate`` over the span where every copter is tracked, from the latest
   tracking start ``t_0``; ``rate`` defaults to the tracking rate (the median over copters). Why not the sonar
   rate: each reading goes to the nearest sample, so it is off by up to half a period; at a 20 Hz base that is
   ±25 ms, and the gap diagnosis detects it (a simulated flight exported with 20 Hz sonars and imported at 20 Hz
   came out as `pose_noise`, at 100 Hz as no gap: ``tests/test_import.py``). A slower ``rate`` makes smaller
   files when the sensors are synchronous.
4. **Readings are never interpolated**: each goes, value unchanged, to the sample nearest its time. When two
   readings of one channel fall on one sample, the nearer one keeps it and the other moves to the free neighbouring
   sample on its side if that is within one period of its time, else it is dropped ("two readings in one sample":
   the channel is faster than the time base — pass a higher ``rate`` to keep them). Lost readings (NaN) and
   readings outside the tracked span are dropped. A lost reading (NaN) keeps a sample only where no value competes
   for it, and counts as lost. Every drop is counted in ``meta["import"]["dropped"]``. The time from each placed
   sonar / ranging reading to its sample is kept in the extras ``ultrasonic_time_offset`` (T, N, S) and
   ``ranging_time_offset`` (T, N, N) s (NaN where no reading), and ``ranging_expected`` (T, N, N) bool marks where
   a ranging reading was recorded (a value or a lost one): elsewhere NaN means "not sampled", not "dropped out",
   and the gap diagnosis scores dropouts only where a reading was expected.
5. **Poses** are interpolated to the samples (:class:`~.poses.TrackedPoses`: linear, yaw unwrapped).
6. ``meta["import"]`` records the rates and jitter found, the offset used (with its uncertainty and method), the
   time base, and what was dropped and why; the log is validated before it is returned.
"""
from __future__ import annotations

import math

import numpy as np

from ..flightlog import DEFAULT_COPTER_RADIUS, FlightLog, FlightLogError, validate
from ..flightlog.messages import fmt
from .clock import estimate_offset
from .poses import TrackedPoses
from .recording import KIND_IMU, KIND_NAMES, KIND_RANGING, KIND_ULTRASONIC, RecordingError, check_recording

__all__ = ["build_flight", "place_readings"]

#: a position or range this many times the arena's size looks like centimetres (or more: millimetres)
UNIT_FACTOR = 20.0


def _stream_stats(ch, kind):
    """(median rate Hz, median jitter s) over the streams of one kind; NaN when there are none."""
    rates, jitter = [], []
    bounds = np.searchsorted(ch.rd_stream, np.arange(len(ch.stream_names) + 1))  # rows are grouped by stream
    for s in np.unique(ch.rd_stream[ch.rd_kind == kind]):
        d = np.diff(ch.rd_t[bounds[s]:bounds[s + 1]])
        if d.size:
            rates.append(1.0 / float(np.median(d)))
            jitter.append(float(np.std(d)))
    if not rates:
        return math.nan, math.nan
    return float(np.median(rates)), float(np.median(jitter))


def place_readings(times, stream, t0: float, dt: float, n_samples: int, lost=None):
    """Sample index of each reading, or -1 where it is not placed, and the reason code per reading.

    times (m,) s on the time base's clock, stream (m,) int (one id per copter and channel); samples are
    ``t0 + k dt``, k < n_samples; lost (m,) bool marks lost readings (NaN), which take a sample only where no value
    competes for it (they mark the reading as expected there). Returns (sample (m,) int64, reason (m,) int8): 0 placed, 1 outside the time base,
    2 two readings in one sample. Rule in the module doc (nearest keeps the sample, the other moves to the free
    neighbour on its side within one period, else is dropped); one reading per (stream, sample), order kept.
    """
    m = times.size
    lost = np.zeros(m, dtype=bool) if lost is None else np.asarray(lost, dtype=bool)
    sample = np.full(m, -1, dtype=np.int64)
    reason = np.zeros(m, dtype=np.int8)
    pos = (times - t0) / dt
    k = np.rint(pos).astype(np.int64)
    inside = (k >= 0) & (k < n_samples)
    reason[~inside] = 1
    idx = np.flatnonzero(inside)

    def claim(cand, kk):
        """Nearest reading wins each (stream, sample) among ``cand`` (a value before a lost one); returns (winners,
        their samples, losers)."""
        key = stream[cand] * n_samples + kk
        dist = np.abs(pos[cand] - kk)
        order = np.lexsort((dist, lost[cand], key))
        first = np.ones(order.size, dtype=bool)
        first[1:] = key[order][1:] != key[order][:-1]
        return cand[order[first]], kk[order[first]], cand[order[~first]]

    win, wk, lose = claim(idx, k[idx])
    sample[win] = wk
    if lose.size:
        side = np.where(pos[lose] >= k[lose], 1, -1)
        nk = k[lose] + side
        ok = (nk >= 0) & (nk < n_samples) & (np.abs(pos[lose] - nk) < 1.0)
        ok &= ~np.isin(stream[lose] * n_samples + nk, stream[win] * n_samples + wk)
        w2, wk2, lose2 = claim(lose[ok], nk[ok])
        sample[w2] = wk2
        reason[lose[~ok]] = 2
        reason[lose2] = 2
    return sample, reason


def _num(x):
    """A float for JSON meta: None when not finite."""
    return float(x) if x is not None and math.isfinite(x) else None


def _units(ch, arena):
    """Positions, heights and each sonar / ranging stream's readings judged against the arena: a value far beyond
    it looks like centimetres or millimetres (a named error). Per stream, so one copter's ranging in millimetres
    among others in metres is caught."""
    W, L = arena
    size = max(W, L)
    coords = [("tracking x", ch.tr_x), ("tracking y", ch.tr_y)]
    if ch.tr_z is not None:
        coords.append(("tracking z", ch.tr_z))
    for name, v in coords:
        top = float(np.max(np.abs(v)))
        if top > UNIT_FACTOR * size:
            unit = "millimetres" if top > 10 * UNIT_FACTOR * size else "centimetres"
            raise RecordingError(f"{name} reaches {fmt(top)} in a {fmt(W)} m x {fmt(L)} m arena; that looks like "
                                 f"{unit}: convert positions to metres")
    diag = math.hypot(W, L)
    if ch.tr_z is not None:
        diag = math.hypot(diag, float(np.max(np.abs(ch.tr_z))))
    medians = {}
    for s in np.unique(ch.rd_stream[np.isin(ch.rd_kind, (KIND_ULTRASONIC, KIND_RANGING))]):
        v = ch.rd_value[(ch.rd_stream == s) & np.isfinite(ch.rd_value)]
        if v.size:
            medians[int(s)] = float(np.median(v))
    fine = [m for m in medians.values() if m <= UNIT_FACTOR * diag]
    for s, med in medians.items():
        if med > UNIT_FACTOR * diag:
            # beside streams in metres, the ratio to them tells mm from cm; alone, the ratio to the arena does
            ratio, limit = (med / float(np.median(fine)), 300.0) if fine else (med / diag, 10 * UNIT_FACTOR)
            unit = "millimetres" if ratio > limit else "centimetres"
            raise RecordingError(f"readings: stream {ch.stream_names[s]!r} has a median of {fmt(med)} in an arena "
                                 f"{fmt(diag)} m across" + (f" ({fmt(ratio)} times the other streams' median)" if fine
                                                             else "") + f"; that looks like {unit}: convert them to metres")


def build_flight(rec, arena, *, sonar_yaw=None, sonar_offset: float | None = None,
                 copter_radius: float = DEFAULT_COPTER_RADIUS, altitude: float | None = None,
                 clock_offset: float | str = "auto", rate: float | None = None, max_offset: float = 2.0,
                 config=None, seed: int = 0) -> FlightLog:
    """One validated :class:`~finkensim.flightlog.FlightLog` from a :class:`~.recording.Recording` (module doc).

    Args:
        rec: the recording (from :func:`~.csvtables.read_csv`, :func:`~.bags.read_bag`, or built by hand).
        arena: (width, length) m.
        sonar_yaw: (S,) mounting yaw of sonar i relative to the heading (rad); needed with sonar channels.
        sonar_offset: distance from the copter centre to each sonar (m); needed with sonar channels.
        copter_radius, altitude: m, written to ``meta``.
        clock_offset: s added to every reading time to put it on the tracking clock, or "auto" (estimated;
            :class:`~.clock.ClockOffsetError` when the data cannot decide).
        rate: samples per second of the time base (default: module doc).
        max_offset: half-width (s) of the "auto" search.
        config: the simulator's :class:`~finkensim.config.Config` (or None): its walls model (bending plates) is
            used by the "auto" estimate (:func:`~.clock.estimate_offset`); arena and sonar geometry come from the
            other arguments.
        seed: seed of the offset estimate's reading subsample and bootstrap.
    """
    try:
        a = np.asarray(arena, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.array([])
    if a.size != 2 or not np.all(np.isfinite(a)) or not np.all(a > 0):
        raise RecordingError(f"arena = {arena!r}: expected (width, length), two positive numbers of metres")
    W, L = float(a[0]), float(a[1])
    ch = check_recording(rec)
    _units(ch, (W, L))
    n_copters = len(ch.copters)
    has = {k: bool((ch.rd_kind == k).any()) for k in (KIND_ULTRASONIC, KIND_RANGING, KIND_IMU)}
    S = 0
    if has[KIND_ULTRASONIC]:
        if sonar_yaw is None or sonar_offset is None:
            missing = "sonar_yaw" if sonar_yaw is None else "sonar_offset"
            raise RecordingError(f"the readings have ultrasonic channels but {missing} is not given (--sonar-yaw-deg / "
                                 "--sonar-offset): the diagnosis needs where each sonar looks and sits")
        sonar_yaw = np.asarray(sonar_yaw, dtype=np.float64).reshape(-1)
        if sonar_yaw.size == 0 or not np.all(np.isfinite(sonar_yaw)):
            raise RecordingError(f"sonar_yaw = {sonar_yaw.tolist()!r}: expected one finite mounting yaw (rad) per sonar")
        S = sonar_yaw.size
        top = int(ch.rd_slot[ch.rd_kind == KIND_ULTRASONIC].max())
        if top >= S:
            raise RecordingError(f"readings: channel 'ultrasonic/{top}' but the sonar yaw list has {S} entries "
                                 f"(ultrasonic/0 ... ultrasonic/{S - 1}); give a yaw for every sonar")
        if not (math.isfinite(float(sonar_offset)) and float(sonar_offset) >= 0):
            raise RecordingError(f"sonar_offset = {sonar_offset!r}: expected a distance >= 0 m")
    poses = TrackedPoses(ch)
    t_lo, t_hi = poses.span
    if not t_hi > t_lo:
        raise RecordingError(f"tracking: the copters are never tracked at the same time (latest start {fmt(t_lo)} s, "
                             f"earliest end {fmt(t_hi)} s); expected overlapping tracking of every copter")
    geometry = dict(arena=(W, L), copter_radius=copter_radius, config=config,
                    sonar_yaw=sonar_yaw if S else None, sonar_offset=sonar_offset)
    clock = {}
    if isinstance(clock_offset, str):
        if clock_offset != "auto":
            raise RecordingError(f"clock_offset = {clock_offset!r}: expected 'auto' or a number of seconds")
        if ch.rd_t.size == 0:
            offset, clock = 0.0, dict(seconds=0.0, method="no readings")
        else:
            est = estimate_offset(ch, poses, geometry, max_offset=max_offset, seed=seed)
            offset = est.offset
            clock = dict(seconds=est.offset, uncertainty=est.uncertainty, method=f"auto ({est.method} readings "
                         "against the tracked poses)", n_readings=est.n_readings)
    else:
        offset = float(clock_offset)
        if not math.isfinite(offset):
            raise RecordingError(f"clock_offset = {clock_offset!r}: expected a finite number of seconds or 'auto'")
        clock = dict(seconds=offset, method="given")
    stats = {KIND_NAMES[k]: _stream_stats(ch, k) for k in (KIND_ULTRASONIC, KIND_RANGING, KIND_IMU) if has[k]}
    if rate is None:
        base_from, rate = "tracking", poses.rate
    else:
        base_from = "given"
        if not (math.isfinite(float(rate)) and float(rate) > 0):
            raise RecordingError(f"rate = {rate!r}: expected a positive number of samples per second")
    rate = float(rate)
    dt = 1.0 / rate
    tau = ch.rd_t + offset
    t0 = t_lo
    K = int(math.floor((t_hi - t0) / dt + 1e-9)) + 1
    if K < 1:
        raise RecordingError(f"the tracked span {fmt(t_lo)}-{fmt(t_hi)} s holds no sample at {fmt(rate)} Hz")
    t = t0 + dt * np.arange(K)
    finite = np.isfinite(ch.rd_value)
    sample, reason = place_readings(tau, ch.rd_stream, t0, dt, K, lost=~finite)
    expected = sample >= 0
    placed = expected & finite
    dropped = {}
    for code, why in ((1, "outside the tracked time span"), (2, "two readings in one sample (the channel is faster "
                                                              "than the time base; a higher --rate keeps them)")):
        for k in (KIND_ULTRASONIC, KIND_RANGING, KIND_IMU):
            c = int(((reason == code) & finite & (ch.rd_kind == k)).sum())
            if c:
                dropped[f"{KIND_NAMES[k]}: {why}"] = c
    for k in (KIND_ULTRASONIC, KIND_RANGING, KIND_IMU):
        c = int((~finite & (ch.rd_kind == k)).sum())
        if c:
            dropped[f"{KIND_NAMES[k]}: lost (NaN) readings"] = c

    pose = poses.all(t)
    log = FlightLog(t=t, arena=np.array([W, L]), pose=pose, copter_ids=np.array(ch.copters, dtype=str))
    extras = {}
    cn, sl, kk = ch.rd_copter, ch.rd_slot, sample
    if has[KIND_ULTRASONIC]:
        m = placed & (ch.rd_kind == KIND_ULTRASONIC)
        u = np.full((K, n_copters, S), np.nan)
        u[kk[m], cn[m], sl[m]] = ch.rd_value[m]
        off = np.full((K, n_copters, S), np.nan)
        off[kk[m], cn[m], sl[m]] = tau[m] - t[kk[m]]
        log.ultrasonic, log.ultrasonic_yaw, log.ultrasonic_offset = u, sonar_yaw, float(sonar_offset)
        extras["ultrasonic_time_offset"] = off
    if has[KIND_RANGING]:
        m = placed & (ch.rd_kind == KIND_RANGING)
        r = np.full((K, n_copters, n_copters), np.nan)
        r[kk[m], cn[m], sl[m]] = ch.rd_value[m]
        idx = np.arange(n_copters)
        r[:, idx, idx] = 0.0
        off = np.full((K, n_copters, n_copters), np.nan)
        off[kk[m], cn[m], sl[m]] = tau[m] - t[kk[m]]
        log.ranging = r
        extras["ranging_time_offset"] = off
        e = np.zeros((K, n_copters, n_copters), dtype=bool)
        m = expected & (ch.rd_kind == KIND_RANGING)
        e[kk[m], cn[m], sl[m]] = True
        extras["ranging_expected"] = e
    if has[KIND_IMU]:
        m = placed & (ch.rd_kind == KIND_IMU)
        imu = np.full((K, n_copters, 3), np.nan)
        imu[kk[m], cn[m], sl[m]] = ch.rd_value[m]
        log.imu_acc, log.imu_gyro = np.ascontiguousarray(imu[..., :2]), np.ascontiguousarray(imu[..., 2])
    z = poses.heights(t)
    if z is not None:
        extras["z"] = z
    log.extras = extras
    meta = {"source": rec.source or "recording", "copter_radius": float(copter_radius)}
    if altitude is not None:
        meta["altitude"] = float(altitude)
    meta["import"] = {
        "time_base": {"rate_hz": rate, "from": base_from, "t0": t0, "samples": K},
        "clock_offset": clock,
        "tracking": {"rate_hz": _num(poses.rate), "longest_gap_s": _num(poses.longest_gap), "poses": poses.counts},
        "rates_hz": {name: _num(v[0]) for name, v in stats.items()},
        "jitter_s": {name: _num(v[1]) for name, v in stats.items()},
        "readings_placed": {KIND_NAMES[k]: int((placed & (ch.rd_kind == k)).sum()) for k in
                            (KIND_ULTRASONIC, KIND_RANGING, KIND_IMU) if has[k]},
        "dropped": dropped,
        "reader": dict(rec.notes),
    }
    log.meta = meta
    try:
        validate(log)
    except FlightLogError as exc:
        raise RecordingError(f"the imported flight is not a valid flight log: {exc}") from None
    return log
