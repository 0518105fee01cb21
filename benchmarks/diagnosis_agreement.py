"""``python -m benchmarks.diagnosis_agreement run|compare``: do two versions of the diagnosis give the same answers?

A change that cuts the diagnosis's work may change its reports; before it is kept, a fixed sample of validation
trials (2 flights × 30 s, random conventions, as in ``gap-validate``) is run with the code before and after the
change, one process, one numba thread, and the answers are compared trial by trial.

* ``run --out FILE [--cases …] [--seeds 100 101 …] [--pairs …]``: runs every (case, seed) of the sample and writes
  one JSON line per trial: the verdict (significant gap, effects named, unexplained), right / wrong, the fitted
  values of the effects named, and the trial's CPU seconds (``time.process_time``, after a warm-up trial).
  Each line also holds ``report_sha256``: a digest of the report's JSON document and of every fitted value and
  bootstrap interval, bit for bit.
* ``run --sample verdict``: the verdict sample instead (every single case and control at one seed and the hard
  pair trials of :data:`VERDICT_PAIRS`), each line also with "exactly" (right and nothing more named) and the
  held-out gap.
* ``compare BEFORE AFTER [--table]``: per trial, whether the verdict is the same; right → wrong and wrong → right trials
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
#: the verdict sample (``run --sample verdict``): every single case and control at seed 100 and these pair trials,
#: chosen to be hard — the bulge beside other effects, the NLOS tail beside other radio effects, the bias beside the
#: node delay, tracking noise beside NLOS and dropout (the pairs matrix of ``d429ec6`` missed seed 0 of several of
#: them and got seed 1 right), and the greedy-swap test's trials (``tests/test_gap_validate.py``, seeds 0 and 2)
VERDICT_SEED = 100
VERDICT_PAIRS = ("wall_bulge+sonar_bias:0", "wall_bulge+sonar_bias:2", "wall_bulge+crosstalk_geometric:1",
                 "wall_bulge+latency:1", "wall_bulge+pose_noise:1", "wall_bulge+ranging_nlos_tail:1",
                 "latency+ranging_nlos_tail:0", "latency+ranging_nlos_tail:1", "ranging_nlos+ranging_nlos_tail:1",
                 "ranging_bias+ranging_nlos_tail:1", "ranging_antenna_offset+ranging_nlos_tail:0",
                 "ranging_bias+ranging_node_delay:0", "ranging_nlos+pose_noise:1", "ranging_dropout+pose_noise:1",
                 "sound_speed+crosstalk_geometric:51", "latency+pose_noise:1")


def verdict_sample() -> list[tuple[str, int]]:
    """The (case, seed) trials of the verdict sample: every single case and control at :data:`VERDICT_SEED`, then
    :data:`VERDICT_PAIRS`."""
    from finkensim.gap.validation.cases import CASES

    return [(c, VERDICT_SEED) for c in CASES] + [_trial(t) for t in VERDICT_PAIRS]


def _trial(text: str) -> tuple[str, int]:
    case, seed = text.rsplit(":", 1)
    return case, int(seed)


def run_sample(trials, out_path: str, log=print) -> None:
    """Run every (case, seed) of ``trials`` and append one JSON line per trial to ``out_path`` (see the module
    docstring)."""
    import numba

    from finkensim.gap.validation.cases import run_case

    numba.set_num_threads(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run_case(trials[0][0], trials[0][1], FLIGHTS, DURATION, conventions="random")  # warm-up: kernels compiled
        with open(out_path, "a") as fh:
            for case, seed in trials:
                keep: dict = {}
                t0 = time.process_time()
                row = run_case(case, seed, FLIGHTS, DURATION, conventions="random", keep=keep)
                cpu = time.process_time() - t0
                added = keep["report"].details.added_params
                rec = dict(case=case, seed=seed, cpu_s=round(cpu, 3), correct=bool(row["correct"]),
                           exactly=_exactly(case, row), significant=bool(row["significant"]),
                           effects=list(row["effects"]), unexplained=bool(row["unexplained"]),
                           ambiguous=list(row["ambiguous"]), gap_before=float(row["gap_before"]),
                           shrink_heldout=float(row["shrink_heldout"]),
                           values={k: {n: float(x) for n, x in v.items()} for k, v in added.items()},
                           report_sha256=_report_digest(keep["report"]))
                fh.write(json.dumps(rec) + "\n")
                fh.flush()
                log(f"{case} seed {seed}: {cpu:.1f} s CPU, {_label(rec)}, "
                    f"effects {rec['effects']}{' unexplained' if rec['unexplained'] else ''}")


def _exactly(case: str, row: dict) -> bool:
    """Right with nothing more: an effect case names exactly its effects, a control is right (nothing to add)."""
    from finkensim.gap.validation.cases import get_case

    effects = get_case(case).effects or ((get_case(case).effect,) if get_case(case).effect else ())
    if not effects:
        return bool(row["correct"])
    return bool(row["correct"]) and set(row["effects"]) == set(effects)


def _label(rec: dict) -> str:
    """"exactly", "right" (the truth named, and more) or "missed"."""
    if not rec["correct"]:
        return "missed"
    return "exactly" if rec.get("exactly", rec["correct"]) else "right"


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


def compare(before_path: str, after_path: str, table: bool = False) -> str:
    """Markdown summary of the trials in both files (see the module docstring); ``table``: one row per trial."""
    before, after = _load(before_path), _load(after_path)
    keys = [k for k in before if k in after]
    same = [k for k in keys if _verdict(before[k]) == _verdict(after[k])]
    lost = [k for k in keys if before[k]["correct"] and not after[k]["correct"]]
    lost_exact = [k for k in keys if _label(before[k]) == "exactly" and _label(after[k]) != "exactly"]
    won = [k for k in keys if after[k]["correct"] and not before[k]["correct"]]
    changes = [c for c in (_value_change(before[k], after[k]) for k in same) if not math.isnan(c)]
    exact = [k for k in keys if before[k]["values"] == after[k]["values"]]
    digests = [k for k in keys if "report_sha256" in before[k] and "report_sha256" in after[k]]
    identical = [k for k in digests if before[k]["report_sha256"] == after[k]["report_sha256"]]
    cb, ca = [before[k]["cpu_s"] for k in keys], [after[k]["cpu_s"] for k in keys]
    L = [f"trials compared: {len(keys)}; same verdict: {len(same)}; right before: "
         f"{sum(before[k]['correct'] for k in keys)}, right after: {sum(after[k]['correct'] for k in keys)}",
         f"exactly before: {sum(_label(before[k]) == 'exactly' for k in keys)}, exactly after: "
         f"{sum(_label(after[k]) == 'exactly' for k in keys)}",
         f"right -> wrong: {[f'{c}:{s}' for c, s in lost] or 'none'}",
         f"exactly -> not exactly: {[f'{c}:{s}' for c, s in lost_exact] or 'none'}",
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
                 f"mean {statistics.mean(cb):.2f} -> {statistics.mean(ca):.2f}, sum {sum(cb):.1f} -> {sum(ca):.1f}")
    if table:
        L += ["", "| trial | verdict | named | held-out gap left | CPU s |", "|---|---|---|---|---:|"]
        L += [f"| {c}:{s} | {_pair(_label(before[(c, s)]), _label(after[(c, s)]))} | "
              f"{_pair(' '.join(before[(c, s)]['effects']) or '-', ' '.join(after[(c, s)]['effects']) or '-')}"
              f"{' (unexplained)' if after[(c, s)]['unexplained'] else ''} | "
              f"{_pair(_gap_left(before[(c, s)]), _gap_left(after[(c, s)]))} | "
              f"{before[(c, s)]['cpu_s']:.1f} → {after[(c, s)]['cpu_s']:.1f} |" for c, s in keys]
    return "\n".join(L)


def _pair(a: str, b: str) -> str:
    return a if a == b else f"{a} → {b}"


def _gap_left(r: dict) -> str:
    """The held-out gap the verdict's effects leave, ``gap_before × (1 − shrink_heldout)`` ("-" if not recorded)."""
    if "gap_before" not in r or math.isnan(r["shrink_heldout"]):
        return "-"
    return f"{r['gap_before'] * (1.0 - r['shrink_heldout']):.3f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run the sample of trials into a JSON-lines file")
    r.add_argument("--out", required=True)
    r.add_argument("--cases", nargs="*", default=None, help="single cases (default: every case and control)")
    r.add_argument("--seeds", nargs="+", type=int, default=list(DEFAULT_SEEDS))
    r.add_argument("--pairs", nargs="*", default=list(DEFAULT_PAIRS))
    r.add_argument("--sample", choices=("seeds", "verdict"), default="seeds",
                   help="seeds: --cases and --pairs at every --seeds; verdict: the verdict sample (VERDICT_PAIRS)")
    r.add_argument("--trials", nargs="*", default=None, metavar="CASE:SEED",
                   help="only these trials (of any sample)")
    r.add_argument("--skip", default=None, metavar="FILE", help="leave out the trials already in this file")
    c = sub.add_parser("compare", help="compare two files written by run")
    c.add_argument("before")
    c.add_argument("after")
    c.add_argument("--table", action="store_true", help="one row per trial")
    a = ap.parse_args(argv)
    if a.cmd == "compare":
        print(compare(a.before, a.after, table=a.table))
        return 0
    from finkensim.gap.validation.cases import CASES

    if a.trials is not None:
        trials = [_trial(t) for t in a.trials]
    elif a.sample == "verdict":
        trials = verdict_sample()
    else:
        trials = [(c, s) for c in list(a.cases if a.cases is not None else CASES) + list(a.pairs) for s in a.seeds]
    if a.skip:
        done = _load(a.skip)
        trials = [t for t in trials if t not in done]
    run_sample(trials, a.out, log=lambda m: print(m, file=sys.stderr, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
