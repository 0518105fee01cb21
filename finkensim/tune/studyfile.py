"""The study file: a TOML description of an Optuna study over scenario parameters, checked up front.

Format (top-level keys before the tables; ``[base]`` and the parameter specs as in sweep files)::

    description = "cut wall sticking without losing cohesion"
    n_trials = 40            # finished trials the study should have (a resumed study runs the rest)
    seed = 0                 # sampler seed
    duration = 20.0          # s per episode (default: simulation.duration of the base scenario)
    sampler = "tpe"          # "tpe" (default; one or several objectives), "nsga2" or "random"
    study_name = "tune"      # name in the storage (default "finkensim-tune")
    storage = "study.db"     # SQLite file relative to --out (default), or an RDB URL ("postgresql://...")

    [base]                   # the scenario every trial starts from (see finkensim.sweep)
    config = "scenario.toml"
    [base.behaviour]
    kind = "attraction_repulsion"

    [params]                 # dotted config keys -> ranges
    "behaviour.ar_b" = { low = 1.0, high = 8.0 }
    "behaviour.ar_c" = { low = 0.3, high = 4.0, log = true }
    "behaviour.wall_check" = { choices = ["none", "per_reading", "sequence"] }

    [objectives]             # metric (finkensim.metrics.METRICS) -> "minimize" or "maximize"
    wall_sticking = "minimize"
    cohesion = "minimize"

    [evaluation]
    n_envs = 32              # Monte-Carlo environments per trial: ONE compiled batched rollout
    seed = 0                 # the same environments for every trial (common random numbers)
    heldout_envs = 128       # environments of the held-out comparison of best vs. defaults
    heldout_seed = 1         # must differ from seed

    [compare.ideal]          # optional: extra held-out comparisons under changed settings
    "sonar.error" = "none"

Every problem raises :class:`~finkensim.sweep.SweepError` naming the key, the value and what was expected.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..config import Config, ConfigError
from ..metrics import METRICS
from ..usertext import suggest
from ..sweep.parsing import Parser, is_duration
from ..sweep.sweepfile import SPEC_KEYS, base_from_table, param_spec, read_sweep_toml

__all__ = ["Param", "StudySpec", "parse_study", "TOP_KEYS", "SAMPLERS"]

TOP_KEYS = ("description", "n_trials", "seed", "duration", "sampler", "study_name", "storage", "base", "params",
            "objectives", "evaluation", "compare")
EVAL_KEYS = {"n_envs": 32, "seed": 0, "heldout_envs": 128, "heldout_seed": 1}
SAMPLERS = ("tpe", "nsga2", "random")
DIRECTIONS = ("minimize", "maximize")


@dataclass(frozen=True)
class Param:
    """One tuned dotted config key: a float/int range (``low``, ``high``, ``log``) or ``choices``."""

    key: str
    kind: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    choices: tuple | None = None


@dataclass(frozen=True)
class StudySpec:
    """A checked study file (see the module doc)."""

    base: Config
    params: tuple[Param, ...]
    objectives: tuple[tuple[str, str], ...]
    n_trials: int
    duration: float
    seed: int = 0
    sampler: str = "tpe"
    study_name: str = "finkensim-tune"
    storage: str = "study.db"
    n_envs: int = 32
    eval_seed: int = 0
    heldout_envs: int = 128
    heldout_seed: int = 1
    compare: dict = field(default_factory=dict)
    description: str = ""
    source: str = "study"
    text: str | None = None

    def config(self, values: Mapping[str, Any], extra: Mapping[str, Any] | None = None) -> Config:
        """The base config with the tuned ``values`` (dotted key -> value) and ``extra`` settings applied."""
        return self.base.replace({**dict(values), **dict(extra or {})})

    def defaults(self) -> dict[str, Any]:
        """The base config's values of the tuned keys."""
        out = {}
        for p in self.params:
            section, _, name = p.key.partition(".")
            out[p.key] = getattr(getattr(self.base, section), name)
        return out


def _param(p: Parser, key: str, spec) -> Param:
    kind, choices, (lo, hi, log) = param_spec(p, "params", key, spec)
    if choices is not None:
        return Param(key, kind, choices=choices)
    return Param(key, kind, low=lo, high=hi, log=log)


MAX_CORNERS = 512
"""Combinations of range ends and choices checked together (more: a fixed sample of them, plus every value alone)."""


def _corners(params: tuple[Param, ...]) -> list[dict]:
    """Combinations of every range's ends and every choice (all of them up to :data:`MAX_CORNERS`, else a fixed
    random sample of that many)."""
    import itertools

    import numpy as np

    axes = [[(prm.key, v) for v in (prm.choices if prm.choices is not None else (prm.low, prm.high))]
            for prm in params]
    total = int(np.prod([len(a) for a in axes], dtype=float))
    if total <= MAX_CORNERS:
        return [dict(c) for c in itertools.product(*axes)]
    rng = np.random.default_rng(0)
    return [{k: v for k, v in (a[int(rng.integers(len(a)))] for a in axes)} for _ in range(MAX_CORNERS)]


def _check_params_on_base(p: Parser, base: Config, params: tuple[Param, ...], n_envs: int, duration: float) -> None:
    """Every end of every range and every choice must make a valid config alone, and every combination of them
    (:func:`_corners`) one that a trial can fly (a behaviour's sensors switched on) in the memory available."""
    from ..budget import check_memory, episode_arrays
    from ..swarm import check_behaviour_sensors, needs_sensors

    for prm in params:
        values = prm.choices if prm.choices is not None else (prm.low, prm.high)
        for v in values:
            try:
                base.replace({prm.key: v})
            except ConfigError as exc:
                raise p.error(f"[params] {prm.key}: {exc}") from None
    for corner in _corners(params):
        where = ", ".join(f"{k} = {v!r}" for k, v in corner.items())
        try:
            cfg = base.replace(corner)
            check_behaviour_sensors(cfg, sensors=needs_sensors(cfg.behaviour.kind))
        except ConfigError as exc:
            raise p.error(f"[params] the combination {where} cannot be flown: {exc}; narrow the ranges or choices, "
                          "or change [base]") from None
        check_memory(episode_arrays(cfg, duration, n_envs), f"a trial of {n_envs} environments x {duration:g} s "
                     f"({where})", "lower [evaluation] n_envs / heldout_envs or duration")


def parse_study(source: str | Path | Mapping[str, Any], base_dir: str | Path | None = None) -> StudySpec:
    """A :class:`StudySpec` from a study TOML path, TOML text or parsed tables (module doc for the format)."""
    if isinstance(source, Mapping):
        data, name, text = source, "study", None
        base_dir = Path.cwd() if base_dir is None else Path(base_dir)
    else:
        data, file_dir, name, text = read_sweep_toml(source)
        name = name if name != "sweep" else "study"
        base_dir = file_dir if base_dir is None else Path(base_dir)
    p = Parser(name)
    for key in data:
        if key not in TOP_KEYS:
            raise p.error(f"unknown key {key!r}{suggest(key, TOP_KEYS)}; allowed: {', '.join(TOP_KEYS)}")
    for req in ("params", "objectives", "n_trials"):
        if req not in data:
            raise p.error(f"missing {req!r}: a study needs n_trials, [params] and [objectives]")
    n_trials = p.integer("n_trials", data["n_trials"], 1)
    seed = p.integer("seed", data.get("seed", 0), 0, 2**32 - 1)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise p.error(f"description = {description!r}: expected a string")
    base = base_from_table(p, data.get("base", {}), base_dir)
    duration = data.get("duration", base.simulation.duration)
    if not is_duration(duration):
        raise p.error(f"duration = {duration!r}: expected a number of seconds > 0")
    if int(round(duration / base.simulation.dt)) < 1:
        raise p.error(f"duration = {duration!r}: shorter than one step of simulation.dt = {base.simulation.dt} s")

    table = data["params"]
    if not isinstance(table, Mapping) or not table:
        raise p.error(f"params = {table!r}: expected a table [params] of dotted keys -> {{low, high}} or {{choices}}")
    specs = p.flatten("params", table, lambda v: any(k in v for k in SPEC_KEYS))
    params = tuple(_param(p, k, v) for k, v in specs.items())

    objs = data["objectives"]
    if not isinstance(objs, Mapping) or not objs:
        raise p.error(f"objectives = {objs!r}: expected a table [objectives] of metric -> 'minimize' or 'maximize'")
    for metric, direction in objs.items():
        if metric not in METRICS:
            raise p.error(f"[objectives] unknown metric {metric!r}{suggest(metric, METRICS)}; expected one of "
                          f"{', '.join(METRICS)}")
        if direction not in DIRECTIONS:
            raise p.error(f"[objectives] {metric} = {direction!r}: expected 'minimize' or 'maximize'")
    objectives = tuple((m, d) for m, d in objs.items())

    sampler = data.get("sampler", "tpe")
    if sampler not in SAMPLERS:
        raise p.error(f"sampler = {sampler!r}{suggest(str(sampler), SAMPLERS)}: expected one of {', '.join(SAMPLERS)}")
    for key in ("study_name", "storage"):
        if key in data and (not isinstance(data[key], str) or not data[key]):
            raise p.error(f"{key} = {data[key]!r}: expected a non-empty string")

    ev = data.get("evaluation", {})
    if not isinstance(ev, Mapping):
        raise p.error(f"evaluation = {ev!r}: expected a table [evaluation] ({', '.join(EVAL_KEYS)})")
    for key in ev:
        if key not in EVAL_KEYS:
            raise p.error(f"[evaluation] unknown key {key!r}{suggest(key, EVAL_KEYS)}; allowed: {', '.join(EVAL_KEYS)}")
    e = {k: ev.get(k, v) for k, v in EVAL_KEYS.items()}
    n_envs = p.integer("[evaluation] n_envs", e["n_envs"], 1, 10**6)
    heldout_envs = p.integer("[evaluation] heldout_envs", e["heldout_envs"], 2, 10**6)
    eval_seed = p.integer("[evaluation] seed", e["seed"], 0, 2**62)
    heldout_seed = p.integer("[evaluation] heldout_seed", e["heldout_seed"], 0, 2**62)
    if heldout_seed == eval_seed:
        raise p.error(f"[evaluation] heldout_seed = {heldout_seed}: expected a seed different from seed = {eval_seed} "
                      "(held-out environments must not be the tuning environments)")

    _check_params_on_base(p, base, params, max(n_envs, heldout_envs), float(duration))

    compare = {}
    table = data.get("compare", {})
    if not isinstance(table, Mapping):
        raise p.error(f"compare = {table!r}: expected tables [compare.<name>] of dotted keys -> values")
    for cname, settings in table.items():
        if not isinstance(settings, Mapping):
            raise p.error(f"[compare.{cname}] = {settings!r}: expected a table of dotted config keys -> values")
        flat = p.flatten(f"compare.{cname}", settings, lambda v: False)
        for k in flat:
            p.check_key(f"compare.{cname}", k)
        try:
            base.replace(flat)
        except ConfigError as exc:
            raise p.error(f"[compare.{cname}] {exc}") from None
        compare[str(cname)] = flat
    return StudySpec(base=base, params=params, objectives=objectives, n_trials=n_trials, duration=float(duration),
                     seed=seed, sampler=sampler, study_name=data.get("study_name", "finkensim-tune"),
                     storage=data.get("storage", "study.db"), n_envs=n_envs, eval_seed=eval_seed,
                     heldout_envs=heldout_envs, heldout_seed=heldout_seed, compare=compare, description=description,
                     source=name, text=text)
