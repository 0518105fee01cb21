"""MURP trial 16: three ground/aerial robots at fixed heights ranging to each other (UWB, 1-s window means).

Conversions (the folder's README): robot ``i`` is tracked by the base pose ``A_x, A_y, A_z, A_yaw`` of the files
with base ``i`` (1 Hz window means; yaw in degrees, converted to radians); ``robot1`` is acl-beta at 1.75 m, the
other two run at ≈ 0.5 m. Reading ``ranging/robot<j>`` of ``robot<i>`` at time t is the window mean ``r`` (the mean
over the 6 × 6 antenna pairs) of file ``base-i_targ-j``, or one antenna pair's mean (``pair="1_1"`` ...). Tracking
and ranges share one clock (offset 0). Truth per reading: ``r_t`` (or the pair's ``k_l_t``), the motion-capture
distance (3-D, antenna to antenna).
"""
from __future__ import annotations

import numpy as np

from .files import DatasetError, read_csv_verified
from .record import RealDataset, to_arena_frame

__all__ = ["load_murp", "MURP"]

MURP = "murp_trial16"
ROBOTS = (1, 2, 3)


def _file(i: int, j: int) -> str:
    return f"16_base-{i}_targ-{j}_win-1_step-1.csv"


def load_murp(pair: str = "mean") -> RealDataset:
    """MURP trial 16 as a :class:`~.record.RealDataset` (module doc).

    Args:
        pair: ``"mean"`` (column ``r``, the mean over the 36 antenna pairs) or one antenna pair ``"k_l"``
            (k, l = 1...6: base antenna k to target antenna l).
    """
    import pandas as pd

    valid = ["mean"] + [f"{k}_{m}" for k in range(1, 7) for m in range(1, 7)]
    if pair not in valid:
        raise DatasetError(f"pair = {pair!r}: expected 'mean' or an antenna pair 'k_l' with k, l in 1...6")
    value_col, truth_col = ("r", "r_t") if pair == "mean" else (pair, f"{pair}_t")
    tracks, reads, truths = [], [], []
    for i in ROBOTS:
        for j in ROBOTS:
            if i == j:
                continue
            f = read_csv_verified(MURP, _file(i, j))
            if not tracks or tracks[-1]["copter"].iloc[0] != f"robot{i}":
                tracks.append(pd.DataFrame({"t": f["t"], "copter": f"robot{i}", "x": f["A_x"], "y": f["A_y"],
                                            "yaw": np.radians(f["A_yaw"]), "z": f["A_z"]}))
            else:
                same = np.allclose(tracks[-1]["x"].to_numpy(), f["A_x"].to_numpy(), atol=1e-6)
                if not same:
                    raise DatasetError(f"{MURP}: {_file(i, j)} gives robot{i} another pose than the other file with "
                                       f"base {i}; expected one base pose per robot")
            reads.append(pd.DataFrame({"t": f["t"], "copter": f"robot{i}", "channel": f"ranging/robot{j}",
                                       "value": f[value_col]}))
            truths.append(f[truth_col].to_numpy())
    tracking, origin, arena = to_arena_frame(pd.concat(tracks, ignore_index=True))
    readings = pd.concat(reads, ignore_index=True)
    truth = readings.copy()
    truth["truth"] = np.concatenate(truths)
    from ..importing import Recording

    notes = {"dataset": MURP, "pair": pair, "robot1": "acl-beta (1.75 m)", "origin_m": [float(v) for v in origin],
             "window": "1-s means of 25 Hz ranges per antenna pair"}
    rec = Recording(tracking=tracking, readings=readings, source=f"dataset:{MURP}", notes=notes)
    return RealDataset(name=MURP, recording=rec, arena=arena, origin=origin, clock_offset=0.0, truth=truth,
                       description=__doc__, notes=notes)
