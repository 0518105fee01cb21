"""Estimate the offset between the sensors' clock and the tracking clock from the data.

The sonar readings of a moving swarm change as the copters move: a reading matches the distance computed from the
tracked poses only at the right time. For a candidate offset δ, every reading taken at sensor time τ is compared
with the ideal reading at tracking time τ + δ — the distance from that sonar (pose interpolated, mounting yaw and
offset applied) to the nearest wall or copter, computed by the simulator's own ray cast
(:func:`finkensim.sensors.sonar.ideal_sonar`, rigid walls) — through a robust loss
``mean(min(|reading − ideal|, 0.25 m))`` (cross-talk and lost echoes cost at most 0.25 m each). Without sonars the
ranging readings are compared with the distance between the tracked copters instead.

The loss is evaluated on a coarse grid over ±``max_offset`` and refined around its minimum. The uncertainty is
the standard deviation of the minimum over bootstrap resamples of the readings. The estimate is refused with a
:class:`ClockOffsetError` (which tells the user to pass the offset) when the data cannot decide: fewer than
:data:`MIN_READINGS` usable readings; a loss curve with less than :data:`MIN_CONTRAST` relative depth (e.g. the
copters hardly moved); bootstrap minima that land away from the best one in more than 5 % of resamples
(two offsets explain the data about equally); a minimum on the edge of the search window; or an uncertainty larger
than one sample of the sensor.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .recording import KIND_RANGING, KIND_ULTRASONIC, RecordingError

__all__ = ["ClockEstimate", "ClockOffsetError", "estimate_offset", "MIN_READINGS", "MIN_CONTRAST"]

#: readings with an echo (sonar) or a value (ranging) needed at the least
MIN_READINGS = 100
#: the loss at the best offset must be at least this fraction below the median loss over the window
MIN_CONTRAST = 0.1
#: robust loss cap (m): a reading that matches no nearby offset costs this much
LOSS_CAP = 0.25
#: readings used at most (spread over the whole recording)
MAX_READINGS = 1500
N_BOOT = 200


class ClockOffsetError(RecordingError):
    """The data cannot decide the clock offset; the message says why and asks for the offset."""


@dataclass(frozen=True)
class ClockEstimate:
    """offset (s): add it to a reading's time to get tracking time; uncertainty (s): bootstrap standard deviation;
    method: "ultrasonic" or "ranging"; n_readings: readings compared; curve: (offsets (G,) s, loss (G,) m) of the
    coarse search, for plots."""

    offset: float
    uncertainty: float
    method: str
    n_readings: int
    curve: tuple


def _refuse(why: str) -> ClockOffsetError:
    return ClockOffsetError(f"clock offset 'auto': {why}; pass the offset between the clocks instead "
                            "(--clock-offset SECONDS, or clock_offset=SECONDS; 0 when both were recorded on one clock)")


def _pick_rows(ch, kind, max_offset, span, rng):
    """Row indices of usable readings of one kind, inside the tracking span for every candidate offset."""
    sel = (ch.rd_kind == kind) & np.isfinite(ch.rd_value) & (ch.rd_value > 0)
    if kind == KIND_ULTRASONIC and sel.any():
        # no echo: drivers write the range limit (exactly, or clipped noise around it); a pile-up of readings
        # within 2 % of the largest one is that, and those readings say nothing about the time
        top = np.max(ch.rd_value[sel])
        at_top = sel & (ch.rd_value >= 0.98 * top)
        if at_top.sum() >= 0.02 * sel.sum():
            sel &= ~at_top
    sel &= (ch.rd_t - max_offset > span[0]) & (ch.rd_t + max_offset < span[1])
    rows = np.flatnonzero(sel)
    if rows.size > MAX_READINGS:
        rows = np.sort(rng.choice(rows, MAX_READINGS, replace=False))
    return rows


def _wall_angles(poses, arena, radius):
    """(times (G,), theta (G, S)): the plate angles of ``arena``'s walls driven by the tracked copters on a grid at
    the tracking rate, as the gap diagnosis replays them (:func:`finkensim.world.walls_from_positions`)."""
    from ..world import walls_from_positions

    t_lo, t_hi = poses.span
    rate = poses.rate if np.isfinite(poses.rate) and poses.rate > 0 else 100.0
    times = np.arange(t_lo, t_hi, 1.0 / rate)
    pos = np.ascontiguousarray(poses.all(times)[..., :2])
    theta = np.empty((times.size, arena.n_plates))
    dist = np.empty((times.size, arena.n_plates))
    walls_from_positions(pos, times, arena.seg_a, arena.seg_b, radius, arena.hinge, arena.lever, theta, dist)
    return times, theta


def _sonar_ideal(ch, poses, rows, geometry):
    """ideal(δ) → (len(rows),) m: the ideal sonar reading of each row at tracking time t + δ. Walls: those of
    ``geometry["config"]`` (bending replayed from the tracked poses) when given, else rigid."""
    from ..arena import Arena
    from ..config import load_config
    from ..sensors.sonar_model import SonarModel
    from ..sensors.sonar import ideal_sonar

    W, L = geometry["arena"]
    cfg = geometry.get("config")
    if cfg is None:
        cfg = load_config({"walls": {"bending": False, "n_segments": 1}})
    cfg = cfg.replace({"arena.width": float(W), "arena.length": float(L),
                       "copters.radius": float(geometry["copter_radius"])})
    arena = Arena.from_config(cfg.arena, cfg.walls)
    model = SonarModel.from_config(cfg)._replace(
        mount_yaw=np.ascontiguousarray(geometry["sonar_yaw"], dtype=np.float64),
        offset=float(geometry["sonar_offset"]), max_range=1e3, ray_angles=np.zeros(1))
    copter, slot, t = ch.rd_copter[rows], ch.rd_slot[rows], ch.rd_t[rows]
    k = np.arange(rows.size)
    if cfg.walls.bending:
        grid, theta_grid = _wall_angles(poses, arena, float(geometry["copter_radius"]))

    def ideal(delta):
        p = poses.all(t + delta)  # (R, N, 3)
        if cfg.walls.bending:
            theta = theta_grid[np.clip(np.searchsorted(grid, t + delta), 0, grid.size - 1)]
        else:
            theta = np.zeros((rows.size, arena.n_plates))
        dist, _, _ = ideal_sonar(np.ascontiguousarray(p[..., :2]), np.ascontiguousarray(p[..., 2]),
                                      np.ascontiguousarray(theta), arena, model)
        return dist[k, copter, slot]

    return ideal


def _ranging_ideal(ch, poses, rows):
    copter, other, t = ch.rd_copter[rows], ch.rd_slot[rows], ch.rd_t[rows]

    def ideal(delta):
        out = np.empty(rows.size)
        for n in np.unique(copter):
            m = copter == n
            a = poses.copter(int(n), t[m] + delta)
            d = np.empty(int(m.sum()))
            for o in np.unique(other[m]):
                mo = other[m] == o
                b = poses.copter(int(o), t[m][mo] + delta)
                d[mo] = np.hypot(a[mo, 0] - b[:, 0], a[mo, 1] - b[:, 1])
            out[m] = d
        return out

    return ideal


def _loss_matrix(ideal, values, deltas):
    return np.stack([np.minimum(np.abs(values - ideal(d)), LOSS_CAP) for d in deltas])  # (G, R)


def _boot_argmins(loss, rng):
    R = loss.shape[1]
    w = rng.multinomial(R, np.full(R, 1.0 / R), size=N_BOOT).astype(float)  # (B, R)
    return np.argmin(w @ loss.T, axis=1)  # (B,)


def estimate_offset(ch, poses, geometry: dict, max_offset: float = 2.0, sample_period: float | None = None,
                    seed: int = 0) -> ClockEstimate:
    """The offset δ (s) with tracking time = reading time + δ, from the sonar readings (or, without sonars, the
    ranging readings) of a checked recording ``ch`` and its :class:`~.poses.TrackedPoses` ``poses``.

    geometry: arena (W, L) m, copter_radius m, and for sonars sonar_yaw (S,) rad, sonar_offset m and optionally
    config, the simulator's :class:`~finkensim.config.Config` whose walls (bending, hinge) the ideal readings use
    (default: rigid walls; bending walls shift the estimate by about one tracking sample when not modelled).
    max_offset: half-width of the search window (s). sample_period: the sensor's sampling period (s), the largest
    acceptable uncertainty (default: the median interval of its readings). Raises :class:`ClockOffsetError` when
    the data cannot decide (module doc).
    """
    if not (math.isfinite(max_offset) and max_offset > 0):
        raise RecordingError(f"max_offset = {max_offset!r}: expected a positive number of seconds")
    rng = np.random.default_rng(seed)
    span = poses.span
    sonar = _pick_rows(ch, KIND_ULTRASONIC, max_offset, span, rng) if geometry.get("sonar_yaw") is not None else []
    rows, method = sonar, "ultrasonic"
    if len(rows) < MIN_READINGS:
        rows, method = _pick_rows(ch, KIND_RANGING, max_offset, span, rng), "ranging"
    if len(rows) < MIN_READINGS:
        raise _refuse(f"only {len(sonar)} sonar readings with an echo and {len(rows)} ranging readings lie at least "
                      f"{max_offset:g} s inside the tracked time span (at least {MIN_READINGS} of one kind needed)")
    ideal = _sonar_ideal(ch, poses, rows, geometry) if method == "ultrasonic" else _ranging_ideal(ch, poses, rows)
    values = ch.rd_value[rows]
    if sample_period is None:
        same = ch.rd_stream[1:] == ch.rd_stream[:-1]
        kind = KIND_ULTRASONIC if method == "ultrasonic" else KIND_RANGING
        d = np.diff(ch.rd_t)[same & (ch.rd_kind[1:] == kind)]
        sample_period = float(np.median(d)) if d.size else 0.1
    step = min(0.02, sample_period / 2)
    coarse = np.linspace(-max_offset, max_offset, int(round(2 * max_offset / step)) + 1)
    loss_c = _loss_matrix(ideal, values, coarse)
    curve = loss_c.mean(axis=1)
    j = int(np.argmin(curve))
    med = float(np.median(curve))
    if not med > 0 or (med - curve[j]) / med < MIN_CONTRAST:
        raise _refuse(f"the {method} readings match the tracked poses about equally well at every offset in "
                      f"±{max_offset:g} s (loss {curve[j]:.3f} m at best, {med:.3f} m median): the copters moved too "
                      "little, or the readings do not follow the poses")
    if j <= 1 or j >= coarse.size - 2:
        raise _refuse(f"the best offset {coarse[j]:+.3f} s lies on the edge of the search window ±{max_offset:g} s "
                      "(try a wider window with --max-offset)")
    far = np.abs(coarse[_boot_argmins(loss_c, rng)] - coarse[j]) > 2 * step
    if far.mean() > 0.05:
        alt = coarse[_boot_argmins(loss_c, rng)][far]
        raise _refuse(f"two offsets explain the {method} readings about equally well ({coarse[j]:+.3f} s and near "
                      f"{float(np.median(alt)):+.3f} s in {100 * far.mean():.0f} % of bootstrap resamples)")
    fine = np.linspace(coarse[j] - 2 * step, coarse[j] + 2 * step, 41)
    loss_f = _loss_matrix(ideal, values, fine)
    best = float(fine[int(np.argmin(loss_f.mean(axis=1)))])
    unc = max(float(np.std(fine[_boot_argmins(loss_f, rng)])), (fine[1] - fine[0]) / 2)
    if unc > sample_period:
        raise _refuse(f"the estimate {best:+.3f} s is uncertain by ±{unc:.3f} s, more than one sample "
                      f"({sample_period:.3f} s) of the {method} readings")
    return ClockEstimate(offset=best, uncertainty=unc, method=method, n_readings=int(len(rows)),
                         curve=(coarse, curve))
