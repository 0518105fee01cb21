"""MILUV ``cirObstacles_3_random_0``: three quadcopters ranging to each other (UWB), tracked by motion capture.

Conversions (the folder's README): tracking from each drone's ``mocap.csv`` (x, y, z m; yaw from the quaternion);
the files are already on the experiment clock after MILUV's ``timeshift.yaml`` (kept in ``notes``), and the range
files are stamped on the same clock, so the clock offset is 0. Tags 10/11 sit on ``ifo001``, 20/21 on ``ifo002``,
30/31 on ``ifo003``; a drone-to-drone reading appears in both drones' files and is kept once; the measuring copter
is the one whose tag started the exchange (``from_id``). Readings to the fixed anchors 0–5 are left out: the
anchors' positions are not part of this copy. Truth per reading: ``gt_range``, the motion-capture distance between
the two *tags* (which sit off the drones' centres).
"""
from __future__ import annotations

import numpy as np

from .files import DatasetError, read_csv_verified, verified_bytes
from .record import RealDataset, to_arena_frame, yaw_from_quaternion

__all__ = ["load_miluv", "MILUV"]

MILUV = "miluv_cirObstacles_3_random_0"
DRONES = ("ifo001", "ifo002", "ifo003")


def _timeshift() -> dict:
    out = {}
    for line in verified_bytes(MILUV, "timeshift.yaml").decode().splitlines():
        key, _, value = line.partition(":")
        if value.strip():
            out[key.strip()] = int(value)
    return out


def load_miluv(tags: str = "all") -> RealDataset:
    """The MILUV flight as a :class:`~.record.RealDataset` (module doc for the conversions).

    Args:
        tags: ``"all"`` keeps every tag pair (each drone carries two tags); ``"first"`` keeps only readings between
            the drones' first tags (10, 20, 30).
    """
    import pandas as pd

    if tags not in ("all", "first"):
        raise DatasetError(f"tags = {tags!r}: expected 'all' or 'first'")
    parts = []
    for name in DRONES:
        m = read_csv_verified(MILUV, f"{name}/mocap.csv")
        parts.append(pd.DataFrame({
            "t": m["timestamp"], "copter": name, "x": m["pose.position.x"], "y": m["pose.position.y"],
            "yaw": yaw_from_quaternion(m["pose.orientation.x"], m["pose.orientation.y"], m["pose.orientation.z"],
                                       m["pose.orientation.w"]),
            "z": m["pose.position.z"]}))
    tracking, origin, arena = to_arena_frame(pd.concat(parts, ignore_index=True))
    uwb = pd.concat([read_csv_verified(MILUV, f"{name}/uwb_range.csv") for name in DRONES], ignore_index=True)
    drone_of = {10 * (k + 1) + j: name for k, name in enumerate(DRONES) for j in (0, 1)}
    inter = uwb["from_id"].isin(drone_of) & uwb["to_id"].isin(drone_of)
    if tags == "first":
        inter &= (uwb["from_id"] % 10 == 0) & (uwb["to_id"] % 10 == 0)
    n_anchor = int((~uwb["from_id"].isin(drone_of) | ~uwb["to_id"].isin(drone_of)).sum())
    rd = uwb[inter].drop_duplicates(["timestamp", "from_id", "to_id"])
    copter = rd["from_id"].map(drone_of).to_numpy()
    channel = ("ranging/" + rd["to_id"].map(drone_of)).to_numpy()
    readings = pd.DataFrame({"t": rd["timestamp"].to_numpy(), "copter": copter, "channel": channel,
                             "value": rd["range"].to_numpy()})
    order = np.lexsort((readings["t"].to_numpy(), readings["channel"].to_numpy(), readings["copter"].to_numpy()))
    readings = readings.iloc[order].reset_index(drop=True)
    truth = readings.copy()
    truth["truth"] = rd["gt_range"].to_numpy()[order]
    truth["from_tag"] = rd["from_id"].to_numpy()[order]
    truth["to_tag"] = rd["to_id"].to_numpy()[order]
    truth["range_raw"] = rd["range_raw"].to_numpy()[order]
    from ..importing import Recording

    notes = {"dataset": MILUV, "timeshift": _timeshift(), "tags": tags,
             "left_out": {"readings to fixed anchors 0-5 (positions not in this copy)": n_anchor,
                          "copies of drone-to-drone readings in the other drone's file": int(inter.sum() - len(rd))},
             "origin_m": [float(v) for v in origin]}
    rec = Recording(tracking=tracking, readings=readings, source=f"dataset:{MILUV}", notes=notes)
    return RealDataset(name=MILUV, recording=rec, arena=arena, origin=origin, clock_offset=0.0, truth=truth,
                       description=__doc__, notes=notes)
