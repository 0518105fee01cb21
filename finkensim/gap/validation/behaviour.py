"""Behaviour-level check of the calibration loop: do a sweep's conclusions under the calibrated config agree with the
truth's, where the uncalibrated model's differ?

For one withheld-effect case (:mod:`finkensim.gap.validation.cases`) and seed, :func:`behaviour_configs` builds three
simulator configs:

- **truth**: the simulator config the case's "real" flights flew (:func:`~finkensim.gap.validation.cases.generate`'s
  logic: the base model plus the case's config keys). A case that acts by post-processing the simulated logs instead
  (``sonar_bias``, ``sound_speed``, ``latency``, ``ranging_nlos``, ``ranging_dropout``, ``pose_noise``,
  ``imu_bias``) has no config keys of its own: its simulator counterpart is the effect's own ``calibrate`` mapping
  (:class:`~finkensim.gap.attribute.effects.Effect`) applied to the case's true parameters. The controls outside the
  catalogue (``foreign``, ``foreign_multipath``) have none: the simulator cannot fly their truth (:data:`NOT_FLOWN`).
- **base**: the diagnosed config (the model that lacks the effect).
- **calibrated**: the config one ``--calibrate``-style diagnosis of the case's flights writes
  (:func:`~finkensim.gap.quantify.calibrate.write_calibrated`, learned correction included).

Each flies the same keys of the flight itself (swarm size, altitude, sonar offset, time step: :data:`FLIGHT_KEYS`,
the truth's values; the diagnosis reads them from the logs) and the attraction–repulsion behaviour
(:data:`BEHAVIOUR_UPDATES`). :func:`behaviour_sweeps` runs a sweep per config (the library's
:func:`~finkensim.sweep.run_sweep`, serial executor, the same sweep seed, so the three share their replicate seeds)
and :func:`judge` compares the 95 % intervals of the metrics' means: the calibration *agrees* on a metric when the
calibrated interval contains the truth's mean, and the effect *changes* the metric when the base interval excludes it.

What the behaviour reads: the attraction–repulsion controller reads the four horizontal sonars only
(:mod:`finkensim.behaviours.attraction`); with the default ``behaviour.wall_check = "none"`` it reads neither the
ranging nor the IMU (the wall check reads the ranging, and its ``sequence`` mode the IMU), and the logged poses'
tracking noise never enters the simulation. The ranging, IMU and pose effects should therefore leave it unchanged.

Run every single case (rows as JSON lines, the table as markdown)::

    python -m finkensim.gap.validation.behaviour --seed 100 --duration 30 --flights 2 --out docs/validation/behaviour-X
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ...config import Config, load_config
from ..attribute.effects import REGISTRY
from ..model.params import ModelParams
from ..quantify.calibrate import write_calibrated
from .cases import CASES, base_config, get_case, run_case
from .conventions import DEFAULT_CONVENTIONS, Conventions

__all__ = ["BEHAVIOUR_UPDATES", "FLIGHT_KEYS", "METRICS", "NOT_FLOWN", "MODELS", "true_params", "truth_config",
           "behaviour_configs", "behaviour_sweeps", "judge", "run_behaviour_case", "behaviour_table", "main"]

#: the behaviour every config flies: the default attraction–repulsion scenario (as
#: docs/validation/calibrate-behaviour/behaviour.toml)
BEHAVIOUR_UPDATES = {"behaviour.kind": "attraction_repulsion"}
#: keys of the flight rather than of the model: every config flies the truth's values
FLIGHT_KEYS = ("copters.n", "arena.altitude", "sonar.offset", "simulation.dt")
#: the headline metrics judged (:data:`finkensim.metrics.METRICS`: a fraction, m, a count)
METRICS = ("wall_sticking", "cohesion", "collisions")
#: cases whose truth the simulator cannot fly (effects outside the catalogue, acting on logs only)
NOT_FLOWN = ("foreign", "foreign_multipath")
#: the configs compared, in table order
MODELS = ("truth", "base", "calibrated")


def true_params(case_name: str, truth: dict, conventions: Conventions | None = None) -> dict:
    """The case's true effect parameters in the effect's own names: the truth dict of a trial without its private
    keys (``_…``), the effect's parameters it does not set at their neutral values (a latency of the other sensors:
    0 s; the pose noise's yaw: the conventions' tracking noise, which the case keeps).

    Parameters
    ----------
    case_name : str
        A single catalogued case (a key of :data:`~finkensim.gap.validation.cases.CASES` whose effect is set).
    truth : dict
        The trial's truth (:func:`~finkensim.gap.validation.cases.run_case`'s ``truth``, after generation: the
        latency actually applied, in s).
    conventions : Conventions, optional
        The recording conventions (default :data:`~finkensim.gap.validation.conventions.DEFAULT_CONVENTIONS`).

    Returns
    -------
    dict
        Parameter name → value, in the effect's units (:class:`~finkensim.gap.attribute.effects.Param`).
    """
    conv = conventions or DEFAULT_CONVENTIONS
    effect = REGISTRY[CASES[case_name].effect]
    values = {k: float(v) for k, v in truth.items() if not k.startswith("_")}
    if effect.name == "pose_noise":
        values.setdefault("sigma_yaw", conv.tracking_sigma_yaw)
    neutral = effect.start(ModelParams.from_config(base_config()))
    return {p.name: values.get(p.name, neutral.get(p.name, 0.0)) for p in effect.params}


def truth_config(case_name: str, seed: int, truth: dict, conventions: Conventions | None = None) -> Config:
    """The simulator config that flies the case's truth (without the behaviour updates).

    Config cases: :func:`~finkensim.gap.validation.cases.generate`'s simulator config (the case's keys drawn from
    ``seed`` as it draws them). Post-processing cases: the base simulator config plus the effect's ``calibrate``
    mapping of :func:`true_params`. ``null``: the base simulator config.

    Parameters
    ----------
    case_name : str
        A single case.
    seed : int
        The trial seed (draws the case's strength).
    truth : dict
        The trial's truth (:func:`true_params`).
    conventions : Conventions, optional
        The recording conventions.

    Returns
    -------
    Config

    Raises
    ------
    ValueError
        For a case in :data:`NOT_FLOWN` (or a pair).
    """
    if case_name in NOT_FLOWN or case_name not in CASES:
        raise ValueError(f"case {case_name!r}: the simulator cannot fly its truth")
    conv = conventions or DEFAULT_CONVENTIONS
    case = get_case(case_name)
    updates, post, _ = case.make(np.random.default_rng(seed))
    extra = {}
    if updates.get("walls.bending"):  # as generate: the hinge at least 0.4 m above the flight
        extra["walls.hinge_height"] = max(1.0, conv.altitude + 0.4)
    cfg = base_config({**conv.sim_updates(), **extra, **updates})
    if post is not None and case.effect is not None:
        effect = REGISTRY[case.effect]
        cfg = cfg.replace(effect.calibrate(true_params(case_name, truth, conv), cfg))
    return cfg


def _fly(cfg: Config, flight: Config, behaviour: dict | None = None) -> Config:
    """``cfg`` with the flight's keys of ``flight`` (:data:`FLIGHT_KEYS`) and the behaviour (:data:`BEHAVIOUR_UPDATES`
    plus ``behaviour``)."""
    keys = {}
    for k in FLIGHT_KEYS:
        section, name = k.split(".")
        keys[k] = getattr(getattr(flight, section), name)
    return cfg.replace({**keys, **BEHAVIOUR_UPDATES, **(behaviour or {})})


def behaviour_configs(case_name: str, seed: int, truth: dict, diagnosed: Config, calibrated: Config,
                      conventions: Conventions | None = None, behaviour: dict | None = None) -> dict[str, Config]:
    """The three configs of :data:`MODELS`, each flying the attraction–repulsion behaviour with the truth's flight keys.

    Parameters
    ----------
    case_name, seed, truth, conventions
        As :func:`truth_config`.
    diagnosed : Config
        The diagnosed (base) config.
    calibrated : Config
        The calibrated config of the trial's diagnosis.
    behaviour : dict, optional
        Further behaviour keys (dotted key → value) on top of :data:`BEHAVIOUR_UPDATES`, e.g.
        ``{"behaviour.wall_check": "sequence"}`` (a wall check that reads the ranging and the IMU).

    Returns
    -------
    dict
        ``{"truth": Config, "base": Config, "calibrated": Config}``.
    """
    truth_cfg = truth_config(case_name, seed, truth, conventions)
    return {"truth": _fly(truth_cfg, truth_cfg, behaviour), "base": _fly(diagnosed, truth_cfg, behaviour),
            "calibrated": _fly(calibrated, truth_cfg, behaviour)}


def behaviour_sweeps(configs: dict[str, Config], replicates: int = 100, duration: float = 20.0, seed: int = 7,
                     metrics=METRICS) -> dict[str, dict]:
    """A sweep per config (``replicates`` episodes of ``duration`` s, serial executor, the sweep seed ``seed`` for
    each, so the configs share their replicate seeds): per config the mean and 95 % Student-t interval of each metric
    (:func:`~finkensim.sweep.summarize`) and the runs' CPU time.

    Parameters
    ----------
    configs : dict
        Name → Config.
    replicates : int
        Episodes per config.
    duration : float
        Episode length, s.
    seed : int
        Sweep seed.
    metrics : sequence of str
        Metric names.

    Returns
    -------
    dict
        Name → ``{"<metric>_mean", "<metric>_ci_low", "<metric>_ci_high", "n_ok", "cpu_s", "values": {metric: list}}``.
    """
    from ...sweep import Sweep, run_sweep, summarize

    out = {}
    for name, cfg in configs.items():
        t0 = time.process_time()
        sweep = Sweep(cfg, replicates=replicates, duration=duration, seed=seed, metrics=list(metrics))
        df = run_sweep(sweep, executor="serial", progress=False)
        s = summarize(df, parameters=[], metrics=list(metrics)).iloc[0]
        row = {k: float(s[k]) for k in s.index if k.endswith(("_mean", "_ci_low", "_ci_high"))}
        row.update(n_ok=int(s["n_ok"]), cpu_s=time.process_time() - t0,
                   values={m: [float(v) for v in df[m]] for m in metrics})
        out[name] = row
    return out


def judge(stats: dict[str, dict], metrics=METRICS) -> dict:
    """The judgement of one effect from its sweeps' statistics.

    Per metric: ``changes`` (the base interval excludes the truth's mean), ``agrees`` (the calibrated interval
    contains it), ``identical`` (base and truth gave the same value in every replicate: the behaviour does not read
    what the effect changes), and ``verdict``: ``"unchanged"`` (the effect does not change the metric and the
    calibration keeps it), ``"met"`` (it changes it and the calibration agrees), ``"not met"`` (it changes it and
    the calibration does not agree), ``"calibration off"`` (unchanged by the effect, moved off by the calibration).
    Per effect: ``"does not change this behaviour"`` when every metric is unchanged, ``"met"`` when at least one is
    met and none is not, else ``"not met"``.

    Parameters
    ----------
    stats : dict
        ``{"truth", "base", "calibrated"}`` → ``{"<metric>_mean", "_ci_low", "_ci_high"[, "values"]}``.
    metrics : sequence of str
        Metric names.

    Returns
    -------
    dict
        ``{"metrics": {metric: {"changes", "agrees", "identical", "verdict"}}, "verdict": str}``.
    """
    per = {}
    for m in metrics:
        t = stats["truth"][f"{m}_mean"]
        b, c = stats["base"], stats["calibrated"]
        inside = lambda s: s[f"{m}_ci_low"] <= t <= s[f"{m}_ci_high"]  # noqa: E731
        vt, vb = stats["truth"].get("values", {}).get(m), b.get("values", {}).get(m)
        identical = vt is not None and vb is not None and len(vt) == len(vb) and bool(np.array_equal(vt, vb))
        changes, agrees = not inside(b), inside(c)
        verdict = ("met" if agrees else "not met") if changes else ("unchanged" if agrees else "calibration off")
        per[m] = {"changes": changes, "agrees": agrees, "identical": identical, "verdict": verdict}
    verdicts = [p["verdict"] for p in per.values()]
    if all(v == "unchanged" for v in verdicts):
        overall = "does not change this behaviour"
    elif "met" in verdicts and not {"not met", "calibration off"} & set(verdicts):
        overall = "met"
    else:
        overall = "not met"
    return {"metrics": per, "verdict": overall}


def run_behaviour_case(name: str, seed: int, n_flights: int = 2, duration: float = 30.0, replicates: int = 100,
                       sweep_duration: float = 20.0, sweep_seed: int = 7, behaviour: dict | None = None) -> dict:
    """One case: diagnose its flights (:func:`~finkensim.gap.validation.cases.run_case`), calibrate
    (:func:`~finkensim.gap.quantify.calibrate.write_calibrated`), sweep truth, base and calibrated, judge.

    Parameters
    ----------
    name : str
        A single case not in :data:`NOT_FLOWN`.
    seed : int
        Trial seed.
    n_flights : int
        Flights diagnosed.
    duration : float
        Seconds per diagnosed flight.
    replicates, sweep_duration, sweep_seed
        As :func:`behaviour_sweeps` (``sweep_duration`` in s).
    behaviour : dict, optional
        Further behaviour keys (:func:`behaviour_configs`).

    Returns
    -------
    dict
        The row: case, seed, truth, the diagnosis's verdict (``named``, ``effects``, ``unexplained``,
        ``significant``), ``calibration`` (the keys the calibration changed from the base, dotted key → value),
        ``stats`` (:func:`behaviour_sweeps` without the per-replicate values), ``judgement`` (:func:`judge`),
        ``diagnosis_cpu_s`` and ``sweep_cpu_s`` (s).
    """
    t0 = time.process_time()
    keep: dict = {}
    row = run_case(name, seed, n_flights=n_flights, duration=duration, keep=keep)
    report = keep["report"]
    diag_cpu = time.process_time() - t0
    with tempfile.TemporaryDirectory(prefix="finkensim-behaviour-") as tmp:
        cal = load_config(write_calibrated(report, Path(tmp) / "calibrated.toml"))
        configs = behaviour_configs(name, seed, row["truth"], report.details.config, cal, keep["conventions"],
                                    behaviour)
        stats = behaviour_sweeps(configs, replicates=replicates, duration=sweep_duration, seed=sweep_seed)
    verdict = judge(stats)
    base_d, cal_d = configs["base"].to_dict(), configs["calibrated"].to_dict()
    changed = {f"{s}.{k}": v for s, keys in cal_d.items() if isinstance(keys, dict) for k, v in keys.items()
               if base_d.get(s, {}).get(k) != v}
    return {"case": name, "seed": seed, "truth": row["truth"], "named": row["named"], "effects": row["effects"],
            "unexplained": row["unexplained"], "significant": row["significant"], "calibration": changed,
            "stats": {k: {kk: vv for kk, vv in v.items() if kk != "values"} for k, v in stats.items()},
            "judgement": verdict, "diagnosis_cpu_s": diag_cpu,
            "sweep_cpu_s": sum(v["cpu_s"] for v in stats.values()), "replicates": replicates,
            "sweep_duration": sweep_duration, "flights": n_flights, "flight_duration": duration,
            "behaviour": {**BEHAVIOUR_UPDATES, **(behaviour or {})}}


def _cell(s: dict, m: str) -> str:
    fmt = "{:.1f}" if m == "collisions" else "{:.3f}"
    return f"{fmt.format(s[f'{m}_mean'])} [{fmt.format(s[f'{m}_ci_low'])}, {fmt.format(s[f'{m}_ci_high'])}]"


def behaviour_table(rows: list[dict], metrics=METRICS) -> str:
    """Markdown: per case, the diagnosis's verdict, each metric's mean and 95 % interval under truth / base /
    calibrated, and the judgement (:func:`judge`; per metric ✓ met, ✗ not met, = unchanged, ! calibration off).

    Parameters
    ----------
    rows : list of dict
        Rows of :func:`run_behaviour_case`.
    metrics : sequence of str
        Metric names.

    Returns
    -------
    str
    """
    mark = {"met": "✓", "not met": "✗", "unchanged": "=", "calibration off": "!"}
    head = "| case | named | model | " + " | ".join(metrics) + " | judgement |"
    lines = [head, "|" + "---|" * (len(metrics) + 4)]
    for r in rows:
        j = r["judgement"]
        named = ", ".join(r["effects"]) or ("unexplained" if r["unexplained"] else "—")
        for i, model in enumerate(MODELS):
            cells = [_cell(r["stats"][model], m) for m in metrics]
            if i == 0:
                verdict = j["verdict"] + " (" + " ".join(mark[j["metrics"][m]["verdict"]] for m in metrics) + ")"
                lines.append(f"| {r['case']} | {named} | {model} | " + " | ".join(cells) + f" | {verdict} |")
            else:
                lines.append(f"| | | {model} | " + " | ".join(cells) + " | |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    """``python -m finkensim.gap.validation.behaviour``: run the cases, append rows to ``OUT/rows.jsonl`` (a case
    already there is skipped), write ``OUT/table.md``."""
    p = argparse.ArgumentParser(prog="python -m finkensim.gap.validation.behaviour", description=__doc__.split("\n")[0])
    p.add_argument("--cases", nargs="+", default=None, help="cases (default: every single case the simulator flies)")
    p.add_argument("--seed", type=int, default=100)
    p.add_argument("--flights", type=int, default=2)
    p.add_argument("--duration", type=float, default=30.0, help="seconds per diagnosed flight")
    p.add_argument("--replicates", type=int, default=100)
    p.add_argument("--sweep-duration", type=float, default=20.0, help="seconds per sweep episode")
    p.add_argument("--sweep-seed", type=int, default=7)
    p.add_argument("--wall-check", choices=("none", "per_reading", "sequence"), default="none",
                   help="behaviour.wall_check of every config (per_reading reads the ranging, sequence also the IMU)")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    behaviour = {"behaviour.wall_check": a.wall_check}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "rows.jsonl"
    rows = [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []
    done = {r["case"] for r in rows}
    for name in a.cases or [c for c in CASES if c not in NOT_FLOWN]:
        if name in done:
            continue
        row = run_behaviour_case(name, a.seed, a.flights, a.duration, a.replicates, a.sweep_duration, a.sweep_seed,
                                 behaviour)
        rows.append(row)
        with path.open("a") as f:
            f.write(json.dumps(row, default=lambda v: None if isinstance(v, float) and math.isnan(v) else str(v))
                    + "\n")
        print(f"{name}: {row['judgement']['verdict']} (diagnosis {row['diagnosis_cpu_s']:.0f} s, sweeps "
              f"{row['sweep_cpu_s']:.0f} s CPU)", file=sys.stderr, flush=True)
    (out / "table.md").write_text(behaviour_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
