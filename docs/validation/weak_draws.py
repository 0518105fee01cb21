"""How strong the drawn radio effects were in the trials a validation run got wrong (docs/validation.md).

    python docs/validation/weak_draws.py docs/validation/radio20-e6b9078 [--tail-below 0.035] [--delay-sd-below 0.05]

For ``ranging_nlos_tail``: a trial's tail strength is probability × mean (m), the mean extra range per reading; it
counts the trials whose verdict misses the tail, below and above ``--tail-below``. For ``ranging_node_delay``: the
standard deviation (m) of the delays of the copters flown (the row's ``conventions.n_copters``; equal delays are one
common offset, a ``ranging_bias``); it counts the wrong trials below and above ``--delay-sd-below``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def rows(directory: Path) -> list[dict]:
    with open(directory / "trials.jsonl") as f:
        return [json.loads(line) for line in f if line.strip()]


def tail_strength(row: dict) -> float:
    t = row["truth"]
    return t["ranging_nlos_tail.probability"] * t["ranging_nlos_tail.mean"]


def delay_sd(row: dict) -> float:
    n = int(row["conventions"]["n_copters"])
    return float(np.std([row["truth"][f"ranging_node_delay.delay_{i}"] for i in range(n)]))


def split(trials, measure, bar, missed):
    low = [r for r in trials if measure(r) < bar]
    high = [r for r in trials if measure(r) >= bar]
    return len(low), sum(map(missed, low)), len(high), sum(map(missed, high))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("directory", type=Path, nargs="+")
    ap.add_argument("--tail-below", type=float, default=0.035, help="tail strength bar, m (default 0.035)")
    ap.add_argument("--delay-sd-below", type=float, default=0.05, help="node-delay spread bar, m (default 0.05)")
    a = ap.parse_args(argv)
    all_rows = [r for d in a.directory for r in rows(d)]
    with_ = lambda name: [r for r in all_rows if name in r["case"].split("+")]  # noqa: E731
    tail = with_("ranging_nlos_tail")
    if tail:
        lo, lo_miss, hi, hi_miss = split(tail, tail_strength, a.tail_below,
                                         lambda r: "ranging_nlos_tail" not in r["effects"])
        print(f"ranging_nlos_tail: {len(tail)} trials, the tail missed in {lo_miss + hi_miss}: {lo_miss} of the {lo} "
              f"with probability x mean < {a.tail_below} m, {hi_miss} of the other {hi}")
        for r in sorted((r for r in tail if "ranging_nlos_tail" not in r["effects"]), key=tail_strength):
            t = r["truth"]
            print(f"  {r['case']} seed {r['seed']}: p {t['ranging_nlos_tail.probability']:.3f}, mean "
                  f"{t['ranging_nlos_tail.mean']:.3f} m, p x mean {tail_strength(r):.3f} m -> {r['effects']}")
    delay = with_("ranging_node_delay")
    if delay:
        lo, lo_wrong, hi, hi_wrong = split(delay, delay_sd, a.delay_sd_below, lambda r: not r["correct"])
        print(f"ranging_node_delay: {len(delay)} trials, {lo_wrong + hi_wrong} wrong: {lo_wrong} of the {lo} whose "
              f"flown delays have a standard deviation < {a.delay_sd_below} m, {hi_wrong} of the other {hi}")
        for r in sorted((r for r in delay if not r["correct"]), key=delay_sd):
            print(f"  {r['case']} seed {r['seed']}: {r['conventions']['n_copters']} copters, delays' sd "
                  f"{delay_sd(r):.3f} m -> {r['effects']}")


if __name__ == "__main__":
    main()
