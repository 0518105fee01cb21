"""Memory a run will hold, estimated from the config before anything is allocated.

Every command that simulates or replays checks its estimate here first and refuses with a
:class:`MemoryBudgetError` (a :class:`~finkensim.config.ConfigError`) naming the largest arrays, the
estimate, the memory available and what to change, instead of dying later in a ``MemoryError`` (or
being killed by the kernel) after minutes of work::

    from finkensim.budget import check_memory, flight_arrays
    check_memory(flight_arrays(cfg), "a flight of simulation.duration = 60 s")

The estimates count the float64 arrays a run keeps at once (a recorded rollout and the flight log
built from it, the gap diagnosis's predictive ensembles); small per-step work arrays are not counted.
:func:`available_bytes` reads ``MemAvailable`` from ``/proc/meminfo`` (else ``psutil``, if
installed); the environment variable ``FINKENSIM_MEMORY_AVAILABLE`` (bytes, e.g. ``2e9``) overrides
it, for tests and for machines where the kernel's figure is misleading.
"""
from __future__ import annotations

import math
import os
from typing import Mapping

from .config import Config, ConfigError

__all__ = ["MEMORY_ENV", "MemoryBudgetError", "available_bytes", "format_bytes", "flight_arrays", "latency_arrays",
           "episode_arrays", "log_arrays", "sweep_objects", "gap_arrays", "check_memory", "flight_advice"]

MEMORY_ENV = "FINKENSIM_MEMORY_AVAILABLE"
"""Environment variable overriding the available memory (bytes)."""

F8 = 8  # bytes per float64
SONARS = 4  # horizontal sonars per copter


class MemoryBudgetError(ConfigError):
    """The arrays a run would hold exceed the memory available; the message names them and what to change."""


def available_bytes() -> int | None:
    """Memory available to this process in bytes (``FINKENSIM_MEMORY_AVAILABLE``, ``MemAvailable``, psutil), or None."""
    env = os.environ.get(MEMORY_ENV)
    if env:
        try:
            value = float(env)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value >= 0):
            raise ConfigError(f"{MEMORY_ENV} = {env!r}: expected a finite number of bytes >= 0, e.g. 2e9")
        return int(value)
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 - not installed or unsupported platform: no check
        return None


def format_bytes(n: float) -> str:
    """``1.5 TiB``, ``230 MiB``, ``12 B``: binary units, 3 significant digits."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} B"


def _steps(duration: float, dt: float) -> float:
    """Samples of a flight of ``duration`` s at ``dt`` s per step (a ConfigError when no number holds them)."""
    q = duration / dt + 0.5
    if not math.isfinite(q):
        raise ConfigError(f"simulation.duration / simulation.dt = {duration!r} s / {dt!r} s: more steps than a number "
                          "holds; expected a longer dt or a shorter duration")
    return math.floor(q) + 1.0


def flight_arrays(cfg: Config, duration: float | None = None, n_envs: int = 1, ideal: bool = True) -> dict[str, float]:
    """Bytes of the arrays one recorded flight holds: name -> bytes (T samples, N copters, B = ``n_envs``).

    Counts the rollout record (pose, velocity, acceleration, yaw rate, plate angles, every enabled
    sensor, with ``ideal`` the error-free sonar and ranging values) and the flight log's copies of it.
    ``duration`` (s) overrides ``simulation.duration`` (it may exceed what the config accepts).
    """
    T = _steps(cfg.simulation.duration if duration is None else duration, cfg.simulation.dt)
    N, B = float(cfg.copters.n), float(n_envs)
    copies = 2.0  # the record and the log built from it
    k = 1.0 + (1.0 if ideal else 0.0)
    out = {"state (T, N, 8)": T * B * N * 8 * F8 * copies,
           "walls (T, 4 n_segments)": T * B * 4 * cfg.walls.n_segments * F8 * copies}
    if cfg.sonar.enabled:
        out["ultrasonic (T, N, 4)"] = T * B * N * (SONARS + 1) * F8 * k * copies
    if cfg.ranging.enabled:
        out["ranging (T, N, N)"] = T * B * N * (N + len(cfg.ranging.beacons)) * F8 * k * copies
    if cfg.imu.enabled:
        out["imu (T, N, 3)"] = T * B * N * 3 * F8 * k * copies
    out.update(latency_arrays(cfg, n_envs))
    return out


def latency_arrays(cfg: Config, n_envs: int = 1) -> dict[str, float]:
    """Bytes of the sensor latency ring buffer (:mod:`finkensim.sensors.latency`): B x (largest lag + 1) x N x W,
    W = 4 sonar + (N + beacons) ranging + 3 IMU columns for each sensor with a lag, + 1 (empty without a lag)."""
    dt, N = cfg.simulation.dt, float(cfg.copters.n)
    widths = {"sonar": SONARS, "ranging": N + len(cfg.ranging.beacons), "imu": 3.0}
    lags = {s: math.floor(getattr(cfg, s).latency / dt + 0.5) for s in widths if getattr(cfg, s).enabled}
    lags = {s: lag for s, lag in lags.items() if lag > 0}
    if not lags:
        return {}
    W = sum(widths[s] for s in lags) + 1.0
    return {"latency ring buffer (B, lag + 1, N, W)": float(n_envs) * (max(lags.values()) + 1) * N * W * F8}


def episode_arrays(cfg: Config, duration: float | None = None, n_envs: int = 1) -> dict[str, float]:
    """Bytes one sweep episode (or a batched rollout of ``n_envs`` of them, as a tune trial flies) holds: it
    records poses only; the sensors run without being recorded (a latency's ring buffer is counted)."""
    T = _steps(cfg.simulation.duration if duration is None else duration, cfg.simulation.dt)
    N = float(cfg.copters.n)
    return {f"pose (T, {'B, ' if n_envs != 1 else ''}N, 3)": T * float(n_envs) * N * 3 * F8 * 2,
            **latency_arrays(cfg, n_envs)}


def log_arrays(T: float, N: int, sonars: int = 0, ranging: bool = False, imu: bool = False) -> dict[str, float]:
    """Bytes of a flight log of T samples of N copters being built (the log and one working copy of each array):
    ``sonars`` sonar channels per copter, the (T, N, N) ``ranging`` block, the ``imu`` block."""
    T, N = float(T), float(N)
    out = {"pose (T, N, 3)": T * N * 3 * F8 * 2, "t (T,)": T * F8 * 2}
    if sonars:
        out[f"ultrasonic (T, N, {sonars})"] = T * N * sonars * F8 * 2
    if ranging:
        out["ranging (T, N, N)"] = T * N * N * F8 * 2
    if imu:
        out["imu (T, N, 3)"] = T * N * 3 * F8 * 2
    return out


COMBINATION_BYTES = 5000
"""Bytes a sweep holds per combination: its Config (about 2.9 KB, measured with tracemalloc on a 2000-point grid)
and the design's dicts of values while they are built."""
RUN_BYTES = 1000
"""Bytes a sweep holds per run: its Run record (about 170 B measured) and its row in the results table and the
parquet table written from it."""


def sweep_objects(n_combinations: float, replicates: float = 1) -> dict[str, float]:
    """Bytes of the Python objects a sweep of ``n_combinations`` x ``replicates`` runs holds before and after it
    runs (its configs, runs and result rows), estimated from the counts alone, before anything is built."""
    n, runs = float(n_combinations), float(n_combinations) * float(replicates)
    return {f"configs ({n:.3g} combinations)": n * COMBINATION_BYTES, f"runs and results ({runs:.3g})": runs * RUN_BYTES}


def gap_arrays(cfg: Config, readings: float) -> dict[str, float]:
    """Bytes of the gap diagnosis's reading tables and predictive ensembles for ``readings`` real readings
    (M = ``gap.draws`` draws each, plus cached variants, features and indices)."""
    columns = cfg.gap.draws * 3 + 16
    return {"predictive ensembles (readings, M)": float(readings) * columns * F8}


def check_memory(arrays: Mapping[str, float], what: str, advice: str = "", available: int | None = None) -> float:
    """Raise :class:`MemoryBudgetError` if the ``arrays`` (name -> bytes) exceed the available memory.

    ``what`` names the run ("a flight of 1e+07 s of 6 copters"); ``advice`` says what to change.
    Returns the total estimate in bytes (also when the available memory is unknown: no check).
    """
    total = float(sum(arrays.values()))
    avail = available_bytes() if available is None else available
    if avail is not None and total > avail:
        largest = sorted(arrays.items(), key=lambda kv: -kv[1])[:3]
        parts = ", ".join(f"{name} {format_bytes(b)}" for name, b in largest if b > 0)
        raise MemoryBudgetError(
            f"{what} would hold about {format_bytes(total)} of arrays ({parts}), more than the "
            f"{format_bytes(avail)} of memory available; {advice or 'make the run smaller'} "
            f"(or set {MEMORY_ENV} to the bytes you can spare)"
        )
    return total


def flight_advice(cfg: Config) -> str:
    """What to change to make a flight smaller (the largest block first)."""
    tips = ["shorten simulation.duration (or --duration)"]
    if cfg.ranging.enabled and cfg.copters.n > 20:
        tips.insert(0, "set ranging.enabled = false (the (T, N, N) ranging array grows with N squared)")
    tips.append("lower copters.n")
    tips.append("raise simulation.dt")
    return "; ".join(tips)
