"""``python -m benchmarks.diagnosis_agreement run|compare``: do two versions of the diagnosis give the same answers?

A change that cuts the diagnosis's work may change its reports; before it is kept, a fixed sample of validation
trials (2 flights × 30 s, random conventions, as in ``gap-validate``) is run with the code before and after the
change, one process, one numba thread, and the answers are compared trial by trial.

* ``run --out FILE [--cases …] [--seeds 100 101 …] [--pairs …]``: runs every (case, seed) of the sample and writes
  one JSON line per trial: the verdict (significant gap, effects named, unexplained), right / wrong, the fitted
  values of the effects named, and the trial's CPU seconds (``time.process_time``, after a warm-up trial).
  Each line also holds ``report_sha256``: a digest of the report's JSON document and of every fitted value and
  bootstrap interval, bit for bit.
* ``compare BEFORE AFTER``: per trial, whether the verdict is the same; right → wrong and wrong → right trials
  named; how many trials' fitted values are exactly equal and whose whole reports are bit-identical (digests); the
  largest relative change of a named effect's fitted values; the CPU seconds' medians and sums.

Run it with the code to be compared on ``PYTHONPATH`` (e.g. an exported copy of the commit before the change) and
``OMP_WAIT_POLICY=passive``; timings follow the machine's load, the answers do not.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import statistics
import sys
import time
import warnings

#: the default sample: every single case and control, and pairs among the dearest and most traded-off effects
DEFAULT_SEEDS = (100, 101, 102)
DEFAULT_PAIRS = ("wall_bulge+sonar_bias", "sound_speed+crosstalk_geometric", "ranging_nlos+sonar_bias",
                 "latency+pose_noise", "beam_width+sonar_rayleigh_scale", "sound_speed+sonar_bias")
FLIGHTS, DURATION = 2, 30.0


def run_sample(cases, seeds, out_path: str, log=print) -> None:
    """Run every (case, seed) and append one JSON line per trial to ``out_path`` (see the module docstring)."""
    import numba

    from finkensim.gap.validation.cases import run_case

    numba.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_case(cases[0], seeds[0], FLIGHTS, DURATION, conventions="random")  # warm-up: kernels loaded or compiled
        with open(out_path, "a") as fh:
            for case in cases:
                for seed in seeds:
                    keep: dict = {}
                    t0 = time.process_time()
                    row = run_case(case, seed, FLIGHTS, DURATION, conventions="random", keep=keep)
                    cpu = time.process_time() - t0
                    added = keep["report"].details.added_params
                    rec = dict(case=case, seed=seed, cpu_s=round(cpu, 3), correct=bool(row["correct"]),
                               significant=bool(row["significant"]), effects=list(row["effects"]),
                               unexplained=bool(row["unexplained"]), ambiguous=list(row["ambiguous"]),
                               values={k: {n: float(x) for n, x in v.items()} for k, v in added.items()},
                               report_sha256=_report_digest(keep["report"]))
                    fh.write(json.dumps(rec) + "\n")
                    fh.flush()
                    log(f"{case} seed {seed}: {cpu:.1f} s CPU, {'right' if rec['correct'] else 'wrong'}, "
                        f"effects {rec['effects']}{' unexplained' if rec['unexplained'] else ''}")


def _feed(h, x) -> None:
    """Feed ``x`` (dicts, sequences, arrays, numbers, strings) into the hash ``h``, every bit of every number."""
    import numpy as np

    if isinstance(x, dict):
        for k in sorted(x, key=repr):
            h.update(repr(k).encode())
            _feed(h, x[k])
    elif isinstance(x, (list, tuple)):
        h.update(b"[%d" % len(x))
        for v in x:
            _feed(h, v)
    elif isinstance(x, np.ndarray):
        h.update(repr((x.dtype.str, x.shape)).encode() + np.ascontiguousarray(x).tobytes())
    elif isinstance(x, (float, np.floating)):
        h.update(float(x).hex().encode())
    else:
        h.update(repr(x).encode())


def _report_digest(report) -> str:
    """SHA-256 of the report's JSON document and of every fitted value and bootstrap interval, bit for bit."""
    h = hashlib.sha256(report.to_json().encode())
    _feed(h, report.details.added_params)
    _feed(h, report.details.param_intervals)
    return h.hexdigest()


def _load(path: str) -> dict:
    with open(path) as fh:
        rows = [json.loads(line) for line in fh if line.strip()]
    return {(r["case"], r["seed"]): r for r in rows}


def _verdict(r: dict) -> tuple:
    return (r["significant"], tuple(r["effects"]), r["unexplained"])


def _value_change(a: dict, b: dict) -> float:
    """Largest relative change of a fitted value of an effect named in both (NaN: none in common)."""
    out = math.nan
    for eff, va in a["values"].items():
        vb = b["values"].get(eff)
        if vb is None:
            continue
        for k, x in va.items():
            if k in vb:
                d = abs(vb[k] - x) / max(abs(x), abs(vb[k]), 1e-9)
                out = d if math.isnan(out) else max(out, d)
    return out


def compare(before_path: str, after_path: str) -> str:
    """Markdown summary of the trials in both files (see the module docstring)."""
    before, after = _load(before_path), _load(after_path)
    keys = [k for k in before if k in after]
    same = [k for k in keys if _verdict(before[k]) == _verdict(after[k])]
    lost = [k for k in keys if before[k]["correct"] and not after[k]["correct"]]
    won = [k for k in keys if after[k]["correct"] and not before[k]["correct"]]
    changes = [c for c in (_value_change(before[k], after[k]) for k in same) if not math.isnan(c)]
    exact = [k for k in keys if before[k]["values"] == after[k]["values"]]
    digests = [k for k in keys if "report_sha256" in before[k] and "report_sha256" in after[k]]
    identical = [k for k in digests if before[k]["report_sha256"] == after[k]["report_sha256"]]
    cb, ca = [before[k]["cpu_s"] for k in keys], [after[k]["cpu_s"] for k in keys]
    L = [f"trials compared: {len(keys)}; same verdict: {len(same)}; right before: "
         f"{sum(before[k]['correct'] for k in keys)}, right after: {sum(after[k]['correct'] for k in keys)}",
         f"right -> wrong: {[f'{c}:{s}' for c, s in lost] or 'none'}",
         f"wrong -> right: {[f'{c}:{s}' for c, s in won] or 'none'}",
         "verdict changed: " + (", ".join(f"{c}:{s} {_verdict(before[(c, s)])} -> {_verdict(after[(c, s)])}"
                                          for c, s in keys if (c, s) not in same) or "none")]
    L.append(f"fitted values of the named effects exactly equal: {len(exact)} of {len(keys)}"
             + (f"; differ: {', '.join(f'{c}:{s}' for c, s in keys if (c, s) not in exact)}" if len(exact) < len(keys)
                else ""))
    if digests:
        L.append(f"whole report (JSON document, fitted values, intervals) bit-identical: {len(identical)} of "
                 f"{len(digests)}" + (f"; differ: {', '.join(f'{c}:{s}' for c, s in digests if (c, s) not in identical)}"
                                      if len(identical) < len(digests) else ""))
    if changes:
        L.append(f"fitted values of the named effects (same verdict): median relative change "
                 f"{statistics.median(changes):.2g}, largest {max(changes):.2g}")
    if keys:
        L.append(f"CPU s per trial: median {statistics.median(cb):.2f} -> {statistics.median(ca):.2f}, "
                 f"sum {sum(cb):.1f} -> {sum(ca):.1f}")
    return "\n".join(L)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the sample of trials into a JSON-lines file")
    r.add_argument("--out", required=True)
    r.add_argument("--cases", nargs="*", default=None, help="single cases (default: every case and control)")
    r.add_argument("--seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS))
    r.add_argument("--pairs", nargs="*", default=list(DEFAULT_PAIRS))
    c = sub.add_parser("compare", help="compare two files written by run")
    c.add_argument("before")
    c.add_argument("after")
    a = ap.parse_args(argv)
    if a.cmd == "compare":
        print(compare(a.before, a.after))
        return 0
    from finkensim.gap.validation.cases import CASES

    cases = list(a.cases if a.cases is not None else CASES) + list(a.pairs)
    run_sample(cases, a.seeds, a.out, log=lambda m: print(m, file=sys.stderr, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
