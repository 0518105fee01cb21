"""``python -m benchmarks.ideal_ranging [--samples T] [--repeats R]``: a flight log's error-free ranging values, one
call of the ranging kernel per sample (as ``scenario.sensor_blocks`` did before ``5527c4e``) against one call for all
T samples (as it does now), on T random poses of the default scenario's N copters.

Prints, per repeat, the CPU (user + system of every thread, :func:`time.process_time`) and wall clock of each way and
whether the values are identical. The per-sample way launches numba's parallel region T times: with
``OMP_WAIT_POLICY`` unset OpenMP threads spin between the calls, which on a busy machine costs far more than the work.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=600, help="T (default: %(default)s, a 30 s flight at dt 0.05 s)")
    ap.add_argument("--repeats", type=int, default=3, help="measurements (default: %(default)s)")
    a = ap.parse_args(argv)

    import finkensim as fs
    from finkensim.sensors.ranging import RangingModel, ranging_readings

    cfg = fs.load_scenario()
    model = RangingModel.from_config(cfg.ranging)
    T, N = a.samples, cfg.copters.n
    pose = np.random.default_rng(0).uniform(0.0, 2.0, (T, N, 3))
    beacons = np.zeros((0, 2))

    def per_sample():
        return np.stack([ranging_readings(pose[k:k + 1, :, :2], beacons, 0, np.zeros(1, np.int64), k, model,
                                          ideal=True, yaw=pose[k:k + 1, :, 2])[0] for k in range(T)])

    def batched():
        return ranging_readings(np.ascontiguousarray(pose[:, :, :2]), beacons, 0, np.zeros(T, np.int64), 0, model,
                                ideal=True, yaw=np.ascontiguousarray(pose[:, :, 2]))

    batched()  # compiled (or loaded from the cache) before the clock starts
    print(f"T = {T} samples of N = {N} copters, OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', '(unset)')}, "
          f"load average {os.getloadavg()[0]:.1f}")
    for _ in range(a.repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        old = per_sample()
        c1, w1 = time.process_time(), time.perf_counter()
        new = batched()
        c2, w2 = time.process_time(), time.perf_counter()
        print(f"per sample: CPU {c1 - c0:.4f} s, wall {w1 - w0:.4f} s; one call: CPU {c2 - c1:.4f} s, "
              f"wall {w2 - w1:.4f} s; identical: {np.array_equal(old, new)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
