"""The tables of a withheld-effect validation run (:mod:`finkensim.gap.validation.cases`): the per-case summary with Wilson
intervals and the confusion matrix (:func:`confusion`), the share naming exactly the withheld effects
(:func:`exactly_withheld`), and the pair trials as an effect × effect grid
(:func:`pair_grid`; :func:`pair_tally` / :func:`pair_count` also feed the figure of :mod:`~finkensim.gap.validation.plot`)."""
from __future__ import annotations

import math

from .cases import CASES, essential, pair_right

__all__ = ["wilson", "withheld", "judged", "exactly_withheld", "confusion", "pair_tally", "pair_count", "pair_grid",
           "effect_pairs", "paired"]


def wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval (95 % by default) of a binomial proportion k/n."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, c - h), min(1.0, c + h)


def withheld(case: str) -> set[str]:
    """The catalogued effects a validation case withholds: both of a pair ``"a+b"``, the effect of a single case, none
    for a control (``null``, ``foreign``, ``foreign_multipath``).

    Parameters
    ----------
    case : str
        The case's name (a row's ``"case"``).

    Returns
    -------
    set of str
        Effect names.
    """
    if "+" in case:
        return set(case.split("+"))
    c = CASES.get(case)
    return {c.effect} if c is not None and c.effect is not None else set()


def judged(row: dict) -> bool:
    """Whether a trial was right, by the current rule, from its row: a pair trial is right when its verdict is a
    significant, explained gap whose effects explain both withheld ones (each named, or nested in a named one:
    :data:`~finkensim.gap.validation.cases.NESTED`); any other trial (and a row without the verdict's
    fields) keeps the row's ``correct``. Rows written
    before the nesting rule are judged alike.

    Parameters
    ----------
    row : dict
        One row of ``trials.jsonl``.

    Returns
    -------
    bool
    """
    if "+" not in row["case"] or "significant" not in row or "effects" not in row:  # no verdict to judge again
        return bool(row["correct"])
    return pair_right(row["significant"], row["unexplained"], row.get("effects") or (), withheld(row["case"]))


def exactly_withheld(row: dict) -> bool:
    """A trial named exactly the withheld effects: it is right (``row["correct"]``) and ``verdict.effects`` holds
    every withheld effect and nothing else (a control: no effect at all), an effect nested in another of the same
    set (:data:`~finkensim.gap.validation.cases.NESTED`) counting as that one. Computed from the row, so it also
    reads rows written before the column existed.

    Parameters
    ----------
    row : dict
        One row of ``trials.jsonl`` (:func:`~finkensim.gap.validation.cases.run_case`).

    Returns
    -------
    bool
        No effect missing and none extra.
    """
    return judged(row) and essential(row.get("effects") or ()) == essential(withheld(row["case"]))


def confusion(rows: list[dict]):
    """Per-case summary (with Wilson 95 % intervals; a last row pools every trial) and confusion matrix (true case ×
    verdict) as a DataFrame and Markdown."""
    import pandas as pd

    df = pd.DataFrame(rows)
    if "flagged_locations" not in df:
        df["flagged_locations"] = math.nan
    if "correction_shrink" not in df:
        df["correction_shrink"] = math.nan
    if "found_by" not in df:  # rows from before the targeted test
        df["found_by"] = None
    df["correct"] = [judged(r) for r in rows]
    df["exactly"] = [exactly_withheld(r) for r in rows]
    df["verdict"] = [("no gap" if not r["significant"] else ("unexplained" if r["unexplained"] else r["named"]))
                     for r in rows]
    summary = df.groupby("case", sort=False).agg(
        trials=("case", "size"), correct_n=("correct", "sum"), correct=("correct", "mean"),
        exactly_n=("exactly", "sum"),
        location_right=("location_ok", lambda s: s.dropna().astype(float).mean() if s.notna().any() else float("nan")),
        param_error_median=("param_error", "median"), shrink_mean=("shrink_heldout", "mean"),
        shrink_max=("shrink_heldout", "max"), correction_shrink=("correction_shrink", "mean"),
        flagged_none=("flagged_locations", lambda s: float((s.fillna(0) == 0).mean())),
        targeted=("found_by", lambda s: int((s == "targeted").sum())), seconds_mean=("seconds", "mean"))

    def pct(x):
        return "n/a" if x != x else f"{x:.0%}"

    lines = ["| case | trials | correct (Wilson 95 % CI) | exactly the withheld effects (Wilson 95 % CI) | no location flagged | location right | parameter error "
             "(median) | shrink mean / max | correction shrink | found by the targeted test | s per trial |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case, r in summary.iterrows():
        lo, hi = wilson(int(r["correct_n"]), int(r["trials"]))
        pe = "n/a" if r["param_error_median"] != r["param_error_median"] else f"{r['param_error_median']:.1%}"
        lines.append(f"| {case} | {int(r['trials'])} | {r['correct']:.0%} ({lo:.0%}–{hi:.0%}) | "
                     f"{_share(int(r['exactly_n']), int(r['trials']), '.0%')} | {pct(r['flagged_none'])} | "
                     f"{pct(r['location_right'])} | {pe} | {r['shrink_mean']:.2f} / {r['shrink_max']:.2f} | "
                     f"{pct(r['correction_shrink'])} | {int(r['targeted'])} | {r['seconds_mean']:.0f} |")
    n, k = len(df), int(df["correct"].sum())
    lo, hi = wilson(k, n)
    loc = df["location_ok"].dropna().astype(float)
    lines.append(f"| **all {summary.shape[0]} cases** | {n} | {k / n:.1%} ({lo:.1%}–{hi:.1%}) | "
                 f"{_share(int(df['exactly'].sum()), n, '.1%')} | "
                 f"{pct(float((df['flagged_locations'].fillna(0) == 0).mean()))} | "
                 f"{pct(loc.mean() if len(loc) else float('nan'))} | | {df['shrink_heldout'].mean():.2f} / "
                 f"{df['shrink_heldout'].max():.2f} | | {int((df['found_by'] == 'targeted').sum())} | {df['seconds'].mean():.0f} |")
    mat = pd.crosstab(df["case"], df["verdict"]).reindex(summary.index)
    lines += ["", "Confusion matrix (rows: withheld effect; columns: verdict, the first effect named):", ""]
    cols = list(mat.columns)
    lines.append("| case | " + " | ".join(cols) + " |")
    lines.append("| --- |" + " --- |" * len(cols))
    for case, r in mat.iterrows():
        lines.append(f"| {case} | " + " | ".join(str(int(x)) if x == x else "0" for x in r.values) + " |")
    return df, "\n".join(lines) + "\n"


def _share(k: int, n: int, fmt: str) -> str:
    """``k/n`` as a percentage with its Wilson 95 % interval."""
    lo, hi = wilson(k, n)
    return f"{k / n:{fmt}} ({lo:{fmt}}–{hi:{fmt}})"


def pair_tally(rows: list[dict]) -> tuple[list[str], dict[str, tuple[int, int]]]:
    """The pair trials of ``rows``: (the effects they combine, in catalogue order; {"a+b": (trials with both named,
    trials)})."""
    tally: dict[str, tuple[int, int]] = {}
    for r in rows:
        if "+" in r["case"]:
            k, n = tally.get(r["case"], (0, 0))
            tally[r["case"]] = (k + judged(r), n + 1)
    effects = [c.name for c in CASES.values() if c.effect is not None and any(c.name in p.split("+") for p in tally)]
    return effects, tally


def _exact_pairs(rows: list[dict]) -> tuple[int, int]:
    """(pair trials naming exactly their two effects, pair trials) of ``rows``."""
    pairs = [r for r in rows if "+" in r["case"]]
    return sum(exactly_withheld(r) for r in pairs), len(pairs)


def pair_count(tally: dict[str, tuple[int, int]], a: str, b: str) -> tuple[int, int]:
    """(both named, trials) of the pair of effects a and b in a :func:`pair_tally`, in either order; (0, 0) if none."""
    return tally.get(f"{a}+{b}") or tally.get(f"{b}+{a}") or (0, 0)


def pair_grid(rows: list[dict], target: float = 0.9) -> str:
    """The pair trials of ``rows`` as an effect × effect grid (Markdown): each cell k/n, the trials of pair a+b in
    which both effects were named; "—" where the two cannot be simulated together (or no trial ran). A last line
    counts the pairs whose share reaches ``target`` (the issue's "every pair both named in ≥ 90 %")."""
    effects, tally = pair_tally(rows)
    if not tally:
        return ""
    lines = ["| both named | " + " | ".join(effects[1:]) + " |", "| --- |" + " ---: |" * (len(effects) - 1)]
    for i, a in enumerate(effects[:-1]):
        cells = []
        for j, b in enumerate(effects[1:], start=1):
            k, n = pair_count(tally, a, b)
            cells.append("" if j <= i else (f"{k}/{n}" if n else "—"))
        lines.append(f"| {a} | " + " | ".join(cells) + " |")
    shares = {p: k / n for p, (k, n) in tally.items()}
    met = sum(x >= target for x in shares.values())
    worst = min(shares, key=shares.get)
    lo, hi = wilson(*tally[worst])
    lines += ["", f"Pairs with both effects named in ≥ {target:.0%} of their trials: {met} of {len(tally)}; lowest "
              f"{worst} {tally[worst][0]}/{tally[worst][1]} (Wilson 95 % {lo:.0%}–{hi:.0%}); trials per pair "
              f"{min(n for _, n in tally.values())}–{max(n for _, n in tally.values())}.",
              f"Pair trials naming exactly the two withheld effects (none missing, none extra): "
              f"{_share(*_exact_pairs(rows), '.1%')}, {_exact_pairs(rows)[0]} of {_exact_pairs(rows)[1]}."]
    return "\n".join(lines) + "\n"


def effect_pairs(rows: list[dict], effects: list[str] | None = None, target: float = 0.9) -> str:
    """Per effect, its pairs with every other effect (Markdown): how many pairs were tried, how many of them have both
    effects named (:func:`judged`) in ≥ ``target`` of their trials (18 of 20 at 0.9), the lowest pair and the trials
    per pair — the issues' "in the pairs matrix with every other effect ≥ 18/20". ``effects``: the effects to list
    (default: every effect of the pair trials); "" when ``rows`` hold no pair trial."""
    known, tally = pair_tally(rows)
    if not tally:
        return ""
    lines = [f"| effect | pairs | pairs with both named in ≥ {target:.0%} of trials | lowest pair (Wilson 95 % CI) | "
             "trials per pair |", "| --- | ---: | ---: | --- | --- |"]
    for e in effects or known:
        mine = {p: kn for p, kn in tally.items() if e in p.split("+")}
        if not mine:
            lines.append(f"| {e} | 0 | | | |")
            continue
        met = sum(k / n >= target for k, n in mine.values())
        worst = min(mine, key=lambda p: mine[p][0] / mine[p][1])
        k, n = mine[worst]
        lo, hi = wilson(k, n)
        ns = [n for _, n in mine.values()]
        lines.append(f"| {e} | {len(mine)} | {met} | {worst} {k}/{n} ({lo:.0%}–{hi:.0%}) | {min(ns)}–{max(ns)} |")
    return "\n".join(lines) + "\n"


def paired(rows: list[dict], base: list[dict]) -> str:
    """The trials that ``rows`` and ``base`` (two diagnoses' runs of the same matrix) both hold, compared trial by
    trial (Markdown): right and exactly right in each, and every trial whose named effects or judgement changed.
    Trials are matched by case, seed and the run's settings (``flights``, ``duration``, ``convention_mode``).

    Parameters
    ----------
    rows, base : list of dict
        Rows of ``trials.jsonl`` (:func:`~finkensim.gap.validation.sweep.merged_rows`): the new diagnosis's and the
        baseline's.

    Returns
    -------
    str
        A summary table and the changed trials; "no trial in common" when they share none.
    """
    def key(r):
        return r["case"], r["seed"], r.get("flights"), r.get("duration"), r.get("convention_mode")

    old = {key(r): r for r in base}
    both = sorted((k for k in {key(r): r for r in rows} if k in old), key=lambda k: (k[0], k[1]))
    if not both:
        return "no trial in common\n"
    new = {key(r): r for r in rows}
    n = len(both)

    def tally(rs, rule):
        k = sum(rule(rs[t]) for t in both)
        lo, hi = wilson(k, n)
        return f"{k} ({k / n:.1%}, {lo:.1%}–{hi:.1%})"

    out = ["| | baseline | this run |", "| --- | --- | --- |",
           f"| right | {tally(old, judged)} | {tally(new, judged)} |",
           f"| exactly the withheld effects | {tally(old, exactly_withheld)} | {tally(new, exactly_withheld)} |",
           f"| wall seconds per trial (mean, under each run's own load) | {sum(old[t]['seconds'] for t in both) / n:.1f} | "
           f"{sum(new[t]['seconds'] for t in both) / n:.1f} |", ""]
    changed = [t for t in both if (judged(old[t]), list(old[t].get("effects") or ()))
               != (judged(new[t]), list(new[t].get("effects") or ()))]
    out.append(f"{n} trials in common; {len(changed)} changed (✓ right, ✗ wrong):")
    out.append("")

    def says(r):
        v = ", ".join(r.get("effects") or ()) or ("unexplained" if r.get("unexplained") else
                                                   "no gap" if not r.get("significant") else "nothing")
        return f"{'✓' if judged(r) else '✗'} {v}"

    out += [f"- {t[0]} seed {t[1]}: {says(old[t])} → {says(new[t])}" for t in changed]
    return "\n".join(out) + "\n"
