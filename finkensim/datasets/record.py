"""What a dataset loader returns: the recording, its arena, the truth the dataset itself gives, and how to import it.

A :class:`RealDataset` holds a :class:`~finkensim.importing.Recording` in the arena frame (origin shifted so every
node sits inside ``[0, width] x [0, length]``), the per-reading truth the dataset publishes, and the documented
time base. :meth:`RealDataset.flight` builds the flight log through the importer; :meth:`RealDataset.write_csv`
writes the importer's tracking and readings CSV files and returns the ``finkensim import`` arguments that read
them unchanged.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["RealDataset", "yaw_from_quaternion", "to_arena_frame", "ARENA_MARGIN"]

#: m between the outermost node (copter or anchor) and the arena edge after the origin shift
ARENA_MARGIN = 0.25


def yaw_from_quaternion(qx, qy, qz, qw) -> np.ndarray:
    """Heading (rad, counter-clockwise from +x, in [-π, π]) of unit quaternions (x, y, z, w), arrays of one shape:
    the z-y-x Euler yaw ``atan2(2(wz + xy), 1 − 2(y² + z²))``."""
    qx, qy, qz, qw = (np.asarray(a, dtype=np.float64) for a in (qx, qy, qz, qw))
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def to_arena_frame(tracking, margin: float = ARENA_MARGIN):
    """(tracking shifted, origin (2,) m, arena (2,) m): x, y shifted so the smallest tracked x, y sit ``margin``
    from the corner; the arena is the tracked extent plus ``margin`` on each side. ``tracking`` is a DataFrame
    with x, y columns (a copy is returned)."""
    lo = np.array([tracking["x"].min(), tracking["y"].min()], dtype=np.float64)
    hi = np.array([tracking["x"].max(), tracking["y"].max()], dtype=np.float64)
    origin = lo - margin
    out = tracking.copy()
    out["x"] = out["x"] - origin[0]
    out["y"] = out["y"] - origin[1]
    arena = np.round(hi - lo + 2 * margin, 3) + 0.001  # rounded up to mm, so every node stays inside
    return out, origin, arena


def fixed_node_tracking(names, xyz, times):
    """Tracking rows (DataFrame t, copter, x, y, yaw, z) of motionless nodes (anchors): each of ``names`` at its
    ``xyz`` (n, 3) m at every time of ``times`` (K,) s, yaw 0, so the importer tracks them over the whole flight."""
    import pandas as pd

    xyz = np.asarray(xyz, dtype=np.float64)
    K = len(times)
    return pd.DataFrame({"t": np.tile(np.asarray(times, dtype=np.float64), len(names)),
                         "copter": np.repeat(list(names), K), "x": np.repeat(xyz[:, 0], K),
                         "y": np.repeat(xyz[:, 1], K), "yaw": 0.0, "z": np.repeat(xyz[:, 2], K)})


@dataclass(frozen=True)
class RealDataset:
    """One public recording, ready for the importer.

    Attributes:
        name: the dataset's folder name (``miluv_cirObstacles_3_random_0`` ...).
        recording: tracking (t s, copter, x m, y m, yaw rad, z m) in the arena frame and readings
            (t s, copter, channel ``ranging/<node>``, value m), each at its own times.
        arena: (width, length) m, the tracked extent plus :data:`ARENA_MARGIN` on each side.
        origin: (2,) m, the dataset-frame point that became the arena corner (x_arena = x_dataset − origin).
        clock_offset: s to add to reading times to put them on the tracking clock (the dataset's documented time
            base; 0 when both are stamped on one clock).
        truth: per reading, what the dataset gives as the true value: DataFrame t, copter, channel, value, truth
            (m), same rows as ``recording.readings``.
        fixed_nodes: names of motionless nodes (anchors) tracked as constant poses.
        description: provenance and conversions, in words.
    """

    name: str
    recording: object
    arena: np.ndarray
    origin: np.ndarray
    clock_offset: float
    truth: object
    fixed_nodes: tuple = ()
    description: str = ""
    notes: dict = field(default_factory=dict)

    @property
    def copters(self) -> list:
        """Names of every node (moving copters first, then fixed nodes), in tracking order."""
        return list(dict.fromkeys(self.recording.tracking["copter"]))

    def flight(self, *, rate: float | None = None, copter_radius: float = 0.15):
        """The :class:`~finkensim.flightlog.FlightLog` of the recording, built by
        :func:`finkensim.importing.build_flight` with the documented clock offset; ``rate`` Hz of the time base
        (default: the tracking rate)."""
        from ..importing import build_flight

        return build_flight(self.recording, arena=tuple(self.arena), clock_offset=self.clock_offset, rate=rate,
                            copter_radius=copter_radius)

    def write_csv(self, folder: str | os.PathLike) -> list:
        """Write ``track.csv`` (with the ``z`` column) and ``read.csv`` into ``folder`` (created) and return the
        ``finkensim import`` arguments (list of str, without ``--out``) that read them unchanged."""
        from ..importing import write_csv

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        track, read = folder / "track.csv", folder / "read.csv"
        write_csv(self.recording, track, read)
        return ["--tracking", str(track), "--readings", str(read), "--arena", f"{self.arena[0]:g},{self.arena[1]:g}",
                "--clock-offset", f"{self.clock_offset:g}"]

    def summary(self) -> str:
        """One line: nodes, span, readings."""
        rd = self.recording.readings
        tr = self.recording.tracking
        span = float(tr["t"].max() - tr["t"].min())
        return (f"{self.name}: {len(self.copters)} nodes ({len(self.fixed_nodes)} fixed), {span:.1f} s tracked, "
                f"{len(rd)} ranging readings, arena {self.arena[0]:g} x {self.arena[1]:g} m")
