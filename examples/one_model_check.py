"""One model: does the diagnosis find a gap between the simulator and its own predictive model at the same config?

"Real" flights are simulated the way ``finkensim gap-validate`` simulates its cases (two 30 s flights, the default
conventions, tracking noise on the logged poses) with the config updates TRUTH (JSON), and diagnosed under the
diagnosed base config plus MODEL (default: TRUTH itself). With MODEL = TRUTH the simulator's kernels and the
diagnosis's predictive model should agree: no significant gap beyond the test's false-alarm rate. With a MODEL
that differs from TRUTH in a setting no effect fits (e.g. the cross-talk cone), it shows what such a difference
leaves.

    nice -n 10 python examples/one_model_check.py '{"imu.latency": 0.3}' [MODEL_JSON] [seed]

(docs/calibration.md quotes its output.)
"""
from __future__ import annotations

import json
import sys
import time

from finkensim.gap.diagnosis import Diagnosis
from finkensim.gap.pipeline import run_diagnosis
from finkensim.gap.validation.cases import Case, generate


def main(truth: dict, model: dict | None = None, seed: int = 100) -> None:
    model = truth if model is None else model
    case = Case("one_model", None, lambda r: (dict(truth), None, {}), None)
    t = time.process_time()
    logs, cfg, _ = generate(case, seed, n_flights=2, duration=30.0)
    report = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace(model)))
    d = report.details
    print(f"truth {truth}; model {model}; seed {seed}")
    print(f"held-out gap {report.gap_before:.4f} (p = {d.gap_before_p:.2g}), significant: "
          f"{report.verdict['significant_gap']}; effects selected: {report.verdict['effects']}")
    print("per sensor (gap, significant):", {s: (round(v["gap"], 4), bool(v["significant"]))
                                             for s, v in d.per_sensor.items()})
    print("significant locations:", [(loc["sensor"], loc["feature"]) for loc in report["locations"]
                                     if loc.get("significant")][:6])
    print(f"CPU {time.process_time() - t:.0f} s")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(json.loads(args[0]), json.loads(args[1]) if len(args) > 1 and args[1] != "-" else None,
         int(args[2]) if len(args) > 2 else 100)
