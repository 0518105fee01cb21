"""Wall plausibility check: which sonar readings see a wall rather than a swarm-mate.

Walls look like swarm-mates to the attraction–repulsion controller, so copters stick to walls. The
report's remedy compares each sonar reading with the virtual-ranging readings (which only tagged
objects — copters, beacons — produce). Wall readings are then dropped from attraction and kept for
repulsion (:mod:`finkensim.behaviours.attraction`). Everything here uses the copter's own sensors.

**Per reading** (``behaviour.wall_check = "per_reading"``). Sonar k of copter n reads r (m). A reading
at ``sonar.max_range`` is no echo and never a wall. Otherwise the reading is turned into an estimate of
the centre distance of the object it sees, e = r + rim with rim = ``copters.radius`` + ``sonar.offset``
(the sonar measures from the sonar to the body's rim, the ranging from centre to centre), and it is a
**wall** unless some ranging reading ρ of copter n (every column except its own, i.e. other copters and
beacons) matches it:

- ρ < ``ranging.max_range``: match when |e − ρ| ≤ ε (``wall_check_epsilon``, 0.286 m);
- ρ ≥ ``ranging.max_range`` (out of range: the tag is at least that far): match when e ≥ max_range − ε.

Ranging has no direction, so a wall at the same distance as some copter in another direction passes
the check (a known limit of the method).

**Sequence** (``"sequence"``). A sonar that fails the per-reading check ``sequence_fail_count`` times
in a row is flagged: it is treated as seeing a wall — whatever it reads — until the copter's inertial
dead reckoning shows it has moved ``sequence_release_distance`` or turned ``sequence_release_angle_deg``
since the flag was set; then the flag and the counter are cleared (and counting starts again, from the
same step's reading). A passing reading resets the counter. Before a sonar is flagged its readings are
treated as swarm-mates.

**Dead reckoning** (:func:`dead_reckon_env`), per copter, in its own start frame (its heading at
switch-on is 0, its position 0; copters start at rest, so the velocity estimate starts at exactly 0)::

    ψ̂ ← ψ̂ + g·dt                 (integrated gyro g, rad; not wrapped)
    v̂ ← v̂ + R(ψ̂)·a_body·dt       (accelerometer reading a_body rotated into the start frame)
    p̂ ← p̂ + v̂·dt

the same semi-implicit Euler the kinematic copter model uses, with the IMU reading of a state (the
acceleration of the step that ended there, the yaw rate of that step) — so with an ideal IMU it tracks
the true motion relative to the start pose up to rounding. The velocity is integrated continuously
from the start (not reset when a flag is set), so "moved since the flag" = |p̂ − p̂_flag| is a double
integral of the accelerometer that does not assume the copter was at rest when the flag was set; the
turn is |ψ̂ − ψ̂_flag|. A biased accelerometer makes p̂ drift quadratically in time, which releases
flags early — the price of using only onboard sensors.

**Memory** (:class:`BehaviourState`, arrays (B, N, ...), carried across steps): fail counters,
wall flags (the last judgement, for every mode), the dead-reckoned pose at each flag, the dead-reckoned
pose and velocity, and per-episode counters (flag onsets, wall-judged echoes).

Per-environment ``inline="always"`` kernels (``*_env``) serve compiled rollouts; the batched wrappers
(:func:`per_reading_check`, :func:`dead_reckon`, :func:`wall_check`) the per-step Python path. NumPy
reference: ``tests/naive/behaviours.py``.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from ..config import Config, ConfigError
from ..kernels.cellgrid import NO_GRID, grid_layout, no_grid_buffers, query_env
from ..sensors.ranging_kernels import ranging_reach

__all__ = ["WALL_CHECK_NONE", "WALL_CHECK_PER_READING", "WALL_CHECK_SEQUENCE", "WALL_CHECK_CODES",
           "WallCheckParams", "BehaviourState", "reading_fails", "per_reading_env", "dead_reckon_env",
           "sequence_env", "wall_check_env", "per_reading_check", "dead_reckon", "wall_check"]

WALL_CHECK_NONE = 0
WALL_CHECK_PER_READING = 1
WALL_CHECK_SEQUENCE = 2
WALL_CHECK_CODES = {"none": WALL_CHECK_NONE, "per_reading": WALL_CHECK_PER_READING, "sequence": WALL_CHECK_SEQUENCE}


class WallCheckParams(NamedTuple):
    """Wall-check parameters in SI units, as passed to the kernels.

    mode: ``WALL_CHECK_*``; epsilon m: match tolerance; rim m: radius + sonar offset, added to a sonar
    reading to estimate a centre distance; sonar_max_range, ranging_max_range m; fail_count: consecutive
    failures before a flag; release_distance m, release_angle rad: dead-reckoned motion that clears a
    flag; dt s: IMU sample period (the world step).
    """

    mode: int
    epsilon: float
    rim: float
    sonar_max_range: float
    ranging_max_range: float
    fail_count: int
    release_distance: float
    release_angle: float
    dt: float

    @classmethod
    def from_config(cls, cfg: Config) -> "WallCheckParams":
        be = cfg.behaviour
        return cls(int(WALL_CHECK_CODES[be.wall_check]), float(be.wall_check_epsilon),
                   float(cfg.copters.radius + cfg.sonar.offset), float(cfg.sonar.max_range),
                   float(cfg.ranging.max_range), int(be.sequence_fail_count), float(be.sequence_release_distance),
                   math.radians(be.sequence_release_angle_deg), float(cfg.simulation.dt))


class BehaviourState(NamedTuple):
    """Per-copter memory of the behaviours, carried across steps (arrays owned by the state); one record for
    Python and the kernels.

    fail_count (B, N, 4) int64: consecutive per-reading failures of each sonar (sequence check);
    wall (B, N, 4) bool: the sonar's reading is judged a wall (last step's judgement, any mode);
    anchor (B, N, 4, 3): dead-reckoned (x m, y m, heading rad) when the flag was set;
    dr_pos (B, N, 2) m, dr_vel (B, N, 2) m/s, dr_yaw (B, N) rad: IMU dead reckoning in each copter's
    start frame; wall_onsets (B, N) int64: flags set since init; wall_readings (B, N) int64: echoes
    judged to be walls since init; sonar_held (B, N, K) m: the sonars' last measurements, shown between
    measurements when ``sonar.update_hz`` > 0 (:mod:`finkensim.sensors.sonar_hold`); commands (B, N, W) float64:
    the flown behaviour's own memory (W = ``Behaviour.memory``, :mod:`finkensim.behaviours.registry`);
    sensor_delay (B, slots, N, W): the ring buffer of delayed readings when a sensor has a latency
    (:mod:`finkensim.sensors.latency`; (B, 0, N, 0) without).
    """

    fail_count: np.ndarray
    wall: np.ndarray
    anchor: np.ndarray
    dr_pos: np.ndarray
    dr_vel: np.ndarray
    dr_yaw: np.ndarray
    wall_onsets: np.ndarray
    wall_readings: np.ndarray
    sonar_held: np.ndarray
    commands: np.ndarray
    sensor_delay: np.ndarray

    @classmethod
    def zeros(cls, n_envs: int, n_copters: int, n_sonars: int = 4, memory: int = 0) -> "BehaviourState":
        """Empty memory of ``n_envs`` environments of ``n_copters`` copters with ``n_sonars`` sonars, and
        ``memory`` floats per copter for the behaviour."""
        B, N, K = int(n_envs), int(n_copters), int(n_sonars)
        return cls(np.zeros((B, N, K), dtype=np.int64), np.zeros((B, N, K), dtype=np.bool_),
                   np.zeros((B, N, K, 3)), np.zeros((B, N, 2)), np.zeros((B, N, 2)), np.zeros((B, N)),
                   np.zeros((B, N), dtype=np.int64), np.zeros((B, N), dtype=np.int64), np.zeros((B, N, K)),
                   np.zeros((B, N, int(memory))),
                   np.zeros((B, 0, N, 0)))

    def copy(self) -> "BehaviourState":
        """Copies of every array."""
        return BehaviourState(*(a.copy() for a in self))

    def select(self, envs) -> "BehaviourState":
        """The sub-batch of environments ``envs`` as an independent memory."""
        return BehaviourState(*(np.ascontiguousarray(a[envs]) for a in self))


# ---------------------------------------------------------------------------------------------
# per-environment kernels


@njit(cache=True, inline="always")
def _matches(e, rho, wall_check):
    """Whether a ranging reading rho (m) matches the centre-distance estimate e (m) of a sonar reading."""
    if rho >= wall_check.ranging_max_range:
        return e >= wall_check.ranging_max_range - wall_check.epsilon
    return abs(e - rho) <= wall_check.epsilon


@njit(cache=True, inline="always")
def reading_fails(r, ranging_row, self_n, wall_check, cand, n_cand, n_copters):
    """True if sonar reading r (m) is an echo that matches no ranging reading in ranging_row (N + M,) m.

    n_cand < 0: every column is tested. Else the copter columns outside cand[:n_cand] are known to read exactly
    ``ranging.max_range`` (the ranging drew only the copters the grid found in range,
    :func:`~finkensim.sensors.ranging_kernels.ranging_grid_env`): they match alike, so one test stands for all of
    them; the candidates and the n_copters… beacon columns are tested one by one. The same answer either way.
    """
    if r >= wall_check.sonar_max_range:
        return False
    e = r + wall_check.rim
    if n_cand < 0:
        for j in range(ranging_row.shape[0]):
            if j != self_n and _matches(e, ranging_row[j], wall_check):
                return False
        return True
    if n_copters - 1 - n_cand > 0 and _matches(e, wall_check.ranging_max_range, wall_check):
        return False
    for c in range(n_cand):
        if _matches(e, ranging_row[cand[c]], wall_check):
            return False
    for j in range(n_copters, ranging_row.shape[0]):
        if _matches(e, ranging_row[j], wall_check):
            return False
    return True


@njit(cache=True, inline="always")
def per_reading_env(sonar_b, ranging_b, wall_check, fail_out, near):
    """Per-reading check of one environment: sonar_b (N, 4) m, ranging_b (N, N + M) m → fail_out (N, 4) bool.

    near = (pos_b (N, 2) m, grid, cells, on): with ``on`` (the ranging ran on the engine's cell grid ``grid`` this step,
    :func:`~finkensim.sensors.ranging_kernels.ranging_grid_env`), each copter's columns in range are found again
    on the grid (``cells``: this environment's buffers, built for the same positions) instead of scanning all N + M.
    """
    pos_b, grid, cells, on = near
    N = sonar_b.shape[0]
    reach = ranging_reach(wall_check.ranging_max_range)
    for n in range(N):
        n_cand = -1
        if on:
            n_cand = query_env(pos_b[n, 0], pos_b[n, 1], reach, n, grid_layout(grid), cells[0], cells[1], cells[2],
                               cells[4], cells[5])
        for k in range(sonar_b.shape[1]):
            fail_out[n, k] = reading_fails(sonar_b[n, k], ranging_b[n], n, wall_check, cells[4], n_cand, N)


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def dead_reckon_env(acc_b, gyro_b, dt, dr_pos, dr_vel, dr_yaw):
    """Advance the dead reckoning of one environment by one IMU sample, in place.

    acc_b (N, 2) m/s² body frame, gyro_b (N,) rad/s; dr_pos, dr_vel (N, 2), dr_yaw (N,).
    """
    for n in range(acc_b.shape[0]):
        psi = dr_yaw[n] + gyro_b[n] * dt
        dr_yaw[n] = psi
        c = np.cos(psi)
        s = np.sin(psi)
        ax = c * acc_b[n, 0] - s * acc_b[n, 1]
        ay = s * acc_b[n, 0] + c * acc_b[n, 1]
        dr_vel[n, 0] += ax * dt
        dr_vel[n, 1] += ay * dt
        dr_pos[n, 0] += dr_vel[n, 0] * dt
        dr_pos[n, 1] += dr_vel[n, 1] * dt


@njit(cache=True, inline="always")
def sequence_env(fail_b, dr_pos, dr_yaw, wall_check, count, wall, anchor, onsets):
    """Sequence check of one environment, in place: release flags the dead reckoning clears, then count
    failures fail_b (N, 4) and flag sonars reaching ``fail_count``; onsets (N,) counts new flags."""
    for n in range(fail_b.shape[0]):
        for k in range(fail_b.shape[1]):
            if wall[n, k]:
                mx = dr_pos[n, 0] - anchor[n, k, 0]
                my = dr_pos[n, 1] - anchor[n, k, 1]
                if np.sqrt(mx * mx + my * my) >= wall_check.release_distance or \
                        abs(dr_yaw[n] - anchor[n, k, 2]) >= wall_check.release_angle:
                    wall[n, k] = False
                    count[n, k] = 0
            if not wall[n, k]:
                if fail_b[n, k]:
                    count[n, k] += 1
                else:
                    count[n, k] = 0
                if count[n, k] >= wall_check.fail_count:
                    wall[n, k] = True
                    count[n, k] = 0
                    anchor[n, k, 0] = dr_pos[n, 0]
                    anchor[n, k, 1] = dr_pos[n, 1]
                    anchor[n, k, 2] = dr_yaw[n]
                    onsets[n] += 1


@njit(cache=True, inline="always", error_model="numpy")  # why: finkensim.kernels.outline
def wall_check_env(sonar_b, ranging_b, wall_check, fail_buf, memory, b, near):
    """The configured check (``wall_check.mode``) for environment b; updates its part of ``memory`` (a
    :class:`BehaviourState`: fail counters, flags, anchors, counters; reads the dead reckoning) and its wall flags
    memory.wall[b] (N, 4) in place. fail_buf (N, 4) bool is a work buffer (left holding the per-reading result);
    near: as :func:`per_reading_env`."""
    wall = memory.wall[b]
    onsets = memory.wall_onsets[b]
    N, K = sonar_b.shape
    if wall_check.mode == WALL_CHECK_NONE:
        for n in range(N):
            for k in range(K):
                wall[n, k] = False
        return
    per_reading_env(sonar_b, ranging_b, wall_check, fail_buf, near)
    if wall_check.mode == WALL_CHECK_PER_READING:
        for n in range(N):
            for k in range(K):
                if fail_buf[n, k] and not wall[n, k]:
                    onsets[n] += 1
                wall[n, k] = fail_buf[n, k]
    else:
        sequence_env(fail_buf, memory.dr_pos[b], memory.dr_yaw[b], wall_check, memory.fail_count[b], wall, memory.anchor[b],
                     onsets)
    wall_readings = memory.wall_readings[b]
    for n in range(N):
        for k in range(K):
            if wall[n, k] and sonar_b[n, k] < wall_check.sonar_max_range:
                wall_readings[n] += 1


# ---------------------------------------------------------------------------------------------
# batched kernels and wrappers


@njit(cache=True, inline="always")
def _no_grid(n):
    """``near`` of :func:`per_reading_env` without a cells (every column is scanned)."""
    return (np.empty((n, 2)), NO_GRID, no_grid_buffers(), False)


@njit(cache=True, parallel=True)
def _per_reading_batch(sonar, ranging, wall_check, out):
    for b in prange(sonar.shape[0]):
        per_reading_env(sonar[b], ranging[b], wall_check, out[b], _no_grid(sonar.shape[1]))


@njit(cache=True, parallel=True)
def _dead_reckon_batch(acc, gyro, dt, dr_pos, dr_vel, dr_yaw):
    for b in prange(acc.shape[0]):
        dead_reckon_env(acc[b], gyro[b], dt, dr_pos[b], dr_vel[b], dr_yaw[b])


@njit(cache=True, parallel=True)
def _wall_check_batch(sonar, ranging, wall_check, memory):
    for b in prange(sonar.shape[0]):
        fail_buf = np.empty(sonar.shape[1:], dtype=np.bool_)
        wall_check_env(sonar[b], ranging[b], wall_check, fail_buf, memory, b, _no_grid(sonar.shape[1]))


def _check_params(wall_check):
    if not isinstance(wall_check, WallCheckParams):
        raise ConfigError(f"params: expected WallCheckParams (WallCheckParams.from_config(cfg)), got "
                          f"{type(wall_check).__name__}")
    return wall_check


def _sonar_ranging(sonar, ranging):
    sonar = np.ascontiguousarray(sonar, dtype=np.float64)
    if sonar.ndim != 3:
        raise ConfigError(f"sonar has shape {sonar.shape}: expected (B, N, 4) m")
    B, N, _ = sonar.shape
    ranging = np.ascontiguousarray(ranging, dtype=np.float64)
    if ranging.ndim != 3 or ranging.shape[:2] != (B, N) or ranging.shape[2] < N:
        raise ConfigError(f"ranging has shape {ranging.shape}: expected (B, N, N + M) = ({B}, {N}, >= {N}) m")
    return sonar, ranging


def _check_state(state, shape):
    if not isinstance(state, BehaviourState):
        raise ConfigError(f"state: expected a BehaviourState, got {type(state).__name__}")
    if state.wall.shape != shape:
        raise ConfigError(f"state.wall has shape {state.wall.shape}: expected {shape} like the sonar readings")
    return state


def per_reading_check(sonar, ranging, params: WallCheckParams):
    """(B, N, 4) bool: sonar readings (B, N, 4) m that match no ranging reading (B, N, N + M) m."""
    params = _check_params(params)
    sonar, ranging = _sonar_ranging(sonar, ranging)
    out = np.empty(sonar.shape, dtype=np.bool_)
    _per_reading_batch(sonar, ranging, params, out)
    return out


def dead_reckon(imu_acc, imu_gyro, state: BehaviourState, params: WallCheckParams) -> None:
    """Advance ``state``'s dead reckoning in place by one IMU sample: imu_acc (B, N, 2) m/s² body frame,
    imu_gyro (B, N) rad/s."""
    params = _check_params(params)
    acc = np.ascontiguousarray(imu_acc, dtype=np.float64)
    gyro = np.ascontiguousarray(imu_gyro, dtype=np.float64)
    if acc.shape != state.dr_pos.shape or gyro.shape != state.dr_yaw.shape:
        raise ConfigError(f"imu_acc {acc.shape} / imu_gyro {gyro.shape}: expected {state.dr_pos.shape} and "
                          f"{state.dr_yaw.shape}")
    _dead_reckon_batch(acc, gyro, params.dt, state.dr_pos, state.dr_vel, state.dr_yaw)


def wall_check(sonar, ranging, params: WallCheckParams, state: BehaviourState):
    """The configured check of one step for B environments; updates ``state`` in place (call
    :func:`dead_reckon` first for the sequence check) and returns a copy of the wall flags (B, N, 4) bool."""
    params = _check_params(params)
    sonar, ranging = _sonar_ranging(sonar, ranging)
    s = _check_state(state, sonar.shape)
    _wall_check_batch(sonar, ranging, params, s)
    return s.wall.copy()
