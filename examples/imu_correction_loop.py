"""Does the IMU's learned correction close the loop? A small check outside ``gap-validate``'s cases.

"Real" flights get an IMU error nobody catalogued: bursts of a constant extra acceleration and yaw rate (each burst
starts at a random time, lasts U(0.3, 2) s and draws its offsets from N(0, 0.4²) m/s² per axis and N(0, 0.05²)
rad/s; about 15 % of the time is in a burst), which no catalogued effect (a constant bias, a latency) explains. The
diagnosis fits a learned correction of the IMU; the calibrated config flies it (``imu.correction_file``); fresh
flights of the same truth are diagnosed under the calibrated config with and without the correction file, and the
script prints the held-out gap of each diagnosis (the first tries the IMU's catalogued effects imu_bias and
latency; the re-diagnoses only measure the gap).

    nice -n 10 python examples/imu_correction_loop.py [seed]

(docs/calibration.md quotes its output.)
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

import finkensim as fs
from finkensim.config import load_config
from finkensim.gap.quantify.calibrate import write_calibrated
from finkensim.gap.validation.cases import Case, generate

SMALL = {"gap.draws": 16, "gap.max_samples_per_flight": 400, "gap.fit_max_readings": 6000, "gap.n_boot": 100}


def _bursts(log, cfg, rng):
    """Add the bursts to the logged IMU readings, per copter (the module docstring)."""
    t = np.asarray(log.t)
    T, N = log.imu_gyro.shape
    acc, gyro = log.imu_acc.copy(), log.imu_gyro.copy()
    start = 0.153 * (t[1] - t[0])  # bursts start at 0.153/s: with a mean length of 1.15 s, 15 % of the time in one
    for n in range(N):
        k = 0
        while k < T:
            if rng.random() < start:
                end = np.searchsorted(t, t[k] + rng.uniform(0.3, 2.0))
                acc[k:end, n] += rng.normal(0.0, 0.4, 2)
                gyro[k:end, n] += rng.normal(0.0, 0.05)
                k = end
            else:
                k += 1
    log.imu_acc, log.imu_gyro = acc, gyro


CASE = Case("imu_bursts", None, lambda r: ({}, _bursts, {}), "imu")


def main(seed: int = 100) -> None:
    logs, cfg, _ = generate(CASE, seed, n_flights=2, duration=30.0)
    cfg = cfg.replace(SMALL)
    first = fs.diagnose(logs, ["a.npz", "b.npz"], cfg, effect_names=["imu_bias", "latency"])
    print(f"first diagnosis: verdict {first.verdict.get('effects')}, unexplained {first.verdict.get('unexplained')}, "
          f"gap {first.gap_before:.4f}, correction {first.correction}")
    new, _, _ = generate(CASE, seed, n_flights=2, duration=30.0, flights_from=2)
    with tempfile.TemporaryDirectory() as tmp:
        cal = load_config(write_calibrated(first, Path(tmp) / "calibrated.toml"))
        print(f"calibrated: imu.correction_file set: {bool(cal.imu.correction_file)}")
        for label, c in (("with the IMU correction", cal), ("without it", cal.replace({"imu.correction_file": ""}))):
            again = fs.diagnose(new, ["c.npz", "d.npz"], c, effect_names=[])
            print(f"fresh flights, {label}: gap {again.gap_before:.4f} = {again.gap_before / first.gap_before:.1%} of "
                  f"the first; significant {again.verdict.get('significant_gap')}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
