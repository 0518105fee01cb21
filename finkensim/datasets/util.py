"""UTIL pilot log ``twr-obs-log1``: one Crazyflie ranging to 8 surveyed anchors (UWB TWR), Vicon pose.

Conversions (the folder's README): both streams are stamped by the drone's onboard clock in milliseconds
(``timestamp_ms``), converted to seconds, so the clock offset is 0. Tracking: ``locSrv.{x,y,z}`` (m) and yaw from
the quaternion ``locSrv.{qx,qy,qz,qw}`` of the drone ``cf``. The anchors are motionless nodes ``anchor0`` ...
``anchor7`` at their surveyed antenna centres ``anchorAntK`` (``anchor_0607.txt``, Vicon frame), tracked as
constant poses at the drone's tracking times. Reading ``ranging/anchorK`` of ``cf`` = ``distance`` (m) to anchor K.
Truth per reading: the 3-D distance from the tracked drone centre (interpolated to the reading time) to the anchor
antenna (no tag offset: the UWB tag's place on the drone is not documented).
"""
from __future__ import annotations

import numpy as np

from .files import DatasetError, read_csv_verified, verified_bytes
from .record import RealDataset, fixed_node_tracking, to_arena_frame, yaw_from_quaternion

__all__ = ["load_util", "UTIL", "anchor_positions"]

UTIL = "util_twr_obs_log1"
N_ANCHORS = 8


def anchor_positions() -> np.ndarray:
    """(8, 3) m: the surveyed antenna centre ``anchorAntK`` of anchors 0...7 (Vicon frame)."""
    pos = {}
    for line in verified_bytes(UTIL, "anchor_0607.txt").decode().splitlines():
        name, *vals = [s.strip() for s in line.split(",")]
        if name.startswith("anchorAnt"):
            pos[int(name[len("anchorAnt"):])] = [float(v) for v in vals]
    missing = [k for k in range(N_ANCHORS) if k not in pos]
    if missing:
        raise DatasetError(f"{UTIL}/anchor_0607.txt: no anchorAnt{missing[0]} line; expected anchors 0-7")
    return np.array([pos[k] for k in range(N_ANCHORS)])


def load_util() -> RealDataset:
    """The UTIL TWR log as a :class:`~.record.RealDataset` (module doc)."""
    import pandas as pd

    m = read_csv_verified(UTIL, "estPose_mocap.csv")
    t = m["timestamp_ms"].to_numpy() / 1000.0
    drone = pd.DataFrame({"t": t, "copter": "cf", "x": m["locSrv.x"], "y": m["locSrv.y"],
                          "yaw": yaw_from_quaternion(m["locSrv.qx"], m["locSrv.qy"], m["locSrv.qz"], m["locSrv.qw"]),
                          "z": m["locSrv.z"]})
    anchors = anchor_positions()
    names = [f"anchor{k}" for k in range(N_ANCHORS)]
    tracking, origin, arena = to_arena_frame(pd.concat([drone, fixed_node_tracking(names, anchors, t)],
                                                       ignore_index=True))
    d = read_csv_verified(UTIL, "estDistance.csv")
    d = d.sort_values(["id", "timestamp_ms"], kind="stable")
    rt = d["timestamp_ms"].to_numpy() / 1000.0
    ids = d["id"].to_numpy()
    readings = pd.DataFrame({"t": rt, "copter": "cf", "channel": [f"ranging/anchor{k}" for k in ids],
                             "value": d["distance"].to_numpy()})
    centre = np.stack([np.interp(rt, t, m[c].to_numpy()) for c in ("locSrv.x", "locSrv.y", "locSrv.z")], axis=1)
    truth = readings.copy()
    truth["truth"] = np.linalg.norm(centre - anchors[ids], axis=1)
    from ..importing import Recording

    notes = {"dataset": UTIL, "clock": "onboard ms clock, converted to s", "origin_m": [float(v) for v in origin],
             "anchors": "surveyed antenna centres anchorAnt0-7 (anchor_0607.txt)"}
    rec = Recording(tracking=tracking, readings=readings, source=f"dataset:{UTIL}", notes=notes)
    return RealDataset(name=UTIL, recording=rec, arena=arena, origin=origin, clock_offset=0.0, truth=truth,
                       fixed_nodes=tuple(names), description=__doc__, notes=notes)
