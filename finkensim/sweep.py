"""Monte-Carlo parameter sweeps: a design of configs × replicate seeds, run on a local process pool,
serially, or on a Dask cluster, with results written run by run so a crash loses only unfinished runs.

    from finkensim.sweep import Sweep, run_sweep
    sweep = Sweep.from_toml("sweep.toml")          # validates everything; builds every config
    df = run_sweep(sweep, out="out/sweep")         # pandas.DataFrame, one row per run
    df = run_sweep(sweep, out="out/sweep", resume=True)   # finish an interrupted sweep

The sweep file (TOML; top-level keys before the tables)::

    description = "wall sticking vs. swarm size and speed"
    replicates = 20          # seeds per parameter combination (default 20)
    duration = 20.0          # s per episode (default: simulation.duration of the base scenario)
    seed = 1                 # sweep seed; replicate seeds derive from (seed, combination, replicate)
    metrics = ["cohesion", "wall_sticking", "collisions"]   # optional subset of finkensim.metrics.METRICS

    [base]                   # the scenario every run starts from (default: the built-in scenario)
    config = "scenario.toml" # optional, relative to this file; inline sections override it
    [base.copters]
    radius = 0.15

    [grid]                   # full factorial over dotted config keys (or "profile")
    "copters.n" = [4, 8]
    "behaviour.speed" = [0.2, 0.4]

or, instead of ``[grid]``, a random design::

    [random]
    n_samples = 16
    "behaviour.speed" = { low = 0.1, high = 0.5 }        # uniform; integers inclusive for int keys
    "walls.threshold" = { low = 0.25, high = 2.0, log = true }
    "behaviour.kind" = { choices = ["random_walk", "hover"] }

**Linked settings: named variants.** A factor whose levels each set several keys at once (e.g. a
sensor model = an error model *and* a cross-talk model) is a ``[variants.<factor>]`` table: each
entry is one level, a name and the dotted keys it sets. Levels are crossed with the grid (or the
random design) like any other factor; the factor comes first (outermost), in file order, and its
results column ``<factor>`` holds the level name::

    [variants.sonar]
    ideal = { "sonar.error" = "none", "sonar.crosstalk" = "off" }
    seed = { "sonar.error" = "seed", "sonar.crosstalk" = "constant", "sonar.crosstalk_probability" = 0.68 }
    geometric = { "sonar.error" = "rayleigh", "sonar.crosstalk" = "geometric" }   # {} = the base values

    [grid]
    "walls.bending" = [false, true]            # 3 sonar levels x 2 = 6 combinations

A key a level leaves out takes its base value. Each level is checked as a whole on the base config
(so linked keys may depend on each other); a key set by a variant may not also be swept by the grid
or by another variant factor, two levels of one factor may not give the same configuration, and a
factor name may not contain a dot or clash with a results column.

Dotted keys may also be written as TOML tables (``[grid.copters] n = [4, 8]``). Everything is
checked before any run starts: unknown keys (with a suggestion), empty lists, values of the wrong
type or range (every config of the design is built through :meth:`Config.replace`), behaviours
that cannot run, unknown executors. Problems raise :class:`SweepError` (a ``ConfigError``).

Runs are numbered ``run_id = combination * replicates + replicate``. Replicate r of combination k
flies with a seed derived from (sweep seed, k, r) alone (``numpy.random.SeedSequence``), so results
do not depend on the executor, the number of workers or the order of completion.

Output directory ``out``:

- ``parts/run-XXXXX.parquet`` — one row per finished run, written atomically (temp file + rename)
  as soon as the run ends; ``resume=True`` runs only the runs whose part is missing.
- ``results.parquet`` — all rows sorted by run id: ``run_id, combination, <parameters>, replicate,
  seed, <metrics>, status ("ok" / "error"), error (exception text), elapsed (s)``.
- ``summary.csv`` — per combination: n_runs, n_ok, n_error and ``<metric>_mean``, ``_ci_low``,
  ``_ci_high`` (95 % Student-t interval of the mean over the successful replicates).
- ``summary.png`` — one panel per metric, mean ± CI per combination.
- ``sweep.json`` — the design and its fingerprint (``resume`` refuses a directory of another sweep).

A run that raises is recorded with status "error" and its exception; every other run proceeds. A
worker that dies (the run never finished) gives an error row without a part, so ``resume`` retries it.
"""
from __future__ import annotations

import dataclasses
import difflib
import hashlib
import itertools
import json
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from . import __version__
from .config import SECTIONS, Config, ConfigError, check_key
from .episode import check_runnable, run_episode
from .metrics import METRICS, check_metric_names
from .scenario import load_scenario

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["SweepError", "Sweep", "Run", "EXECUTORS", "run_sweep", "load_results", "summarize", "plot_summary"]

EXECUTORS = ("serial", "process", "dask")
TOP_KEYS = ("description", "replicates", "duration", "seed", "metrics", "base", "variants", "grid", "random")
_RESULT_COLUMNS = ("run_id", "combination", "replicate", "seed", "status", "error", "elapsed")
DEFAULT_REPLICATES = 20
RESERVED_KEYS = {
    "simulation.seed": "the seed of each run derives from the top-level 'seed' of the sweep",
    "simulation.n_envs": "each run is one environment",
}
_SPEC_KEYS = ("low", "high", "log", "choices")
_SEED_TAG_RUN = 1     # SeedSequence([seed, 1, k, r]) -> run seeds
_SEED_TAG_DESIGN = 2  # SeedSequence([seed, 2]) -> random design samples


class SweepError(ConfigError):
    """A sweep file, design, executor or output directory is wrong; raised before any run starts."""


@dataclass(frozen=True)
class Run:
    """One episode of a sweep: combination ``combination``, replicate ``replicate``, seed ``seed``."""

    run_id: int
    combination: int
    replicate: int
    seed: int
    params: Mapping[str, Any]


# ------------------------------------------------------------------------------------------ parsing

def _suggest(word: str, options: Iterable[str]) -> str:
    hint = difflib.get_close_matches(str(word), list(options), n=1)
    return f" (did you mean {hint[0]!r}?)" if hint else ""


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _field(key: str):
    """The dataclass field of a dotted config key (the key has been checked)."""
    section, _, name = key.partition(".")
    return {f.name: f for f in dataclasses.fields(SECTIONS[section])}[name]


def _field_kind(key: str) -> str:
    if key == "profile":
        return "str"
    t = _field(key).type
    t = t if isinstance(t, str) else getattr(t, "__name__", str(t))
    return "tuple" if t.startswith("tuple") else t


def _get(cfg: Config, key: str):
    if key == "profile":
        return cfg.profile
    section, _, name = key.partition(".")
    return getattr(getattr(cfg, section), name)


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)


def format_params(params: Mapping[str, Any]) -> str:
    """``copters.n=4, behaviour.speed=0.2`` (or ``base`` when nothing is swept)."""
    return ", ".join(f"{k}={_fmt(v)}" for k, v in params.items()) or "base"


class _Parser:
    """Checks a sweep table with error messages prefixed by the sweep's source name."""

    def __init__(self, source: str):
        self.source = source

    def error(self, message: str) -> SweepError:
        return SweepError(f"{self.source}: {message}")

    def check_key(self, table: str, key: str) -> str:
        if key == "profile":
            return key
        section, _, name = key.partition(".")
        if not name or "." in name:
            raise self.error(f"[{table}] {key!r}: expected a dotted config key 'section.key' (e.g. 'copters.n') or 'profile'")
        try:
            check_key(section, name)
        except ConfigError as exc:
            raise self.error(f"[{table}] {exc}") from None
        if key in RESERVED_KEYS:
            raise self.error(f"[{table}] {key} cannot be swept: {RESERVED_KEYS[key]}")
        return key

    def flatten(self, table: str, data: Mapping[str, Any], is_leaf: Callable[[Any], bool],
                prefix: str = "") -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in data.items():
            key = f"{prefix}.{k}" if prefix else str(k)
            if isinstance(v, Mapping) and not is_leaf(v):
                out.update(self.flatten(table, v, is_leaf, key))
            else:
                out[key] = v
        return out

    def integer(self, key, value, lo, hi=None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(f"{key} = {value!r}: expected an integer, got {type(value).__name__}")
        if value < lo or (hi is not None and value > hi):
            allowed = f">= {lo}" + (f" and <= {hi}" if hi is not None else "")
            raise self.error(f"{key} = {value!r}: expected an integer {allowed}")
        return int(value)


def _seed_for(sweep_seed: int, combination: int, replicate: int) -> int:
    """The seed of replicate ``replicate`` of ``combination``: 63 bits of SeedSequence([seed, 1, k, r])."""
    state = np.random.SeedSequence([sweep_seed, _SEED_TAG_RUN, combination, replicate]).generate_state(1, np.uint64)
    return int(state[0] >> np.uint64(1))


class Sweep:
    """A validated sweep design: a base scenario, swept parameters, their combinations and replicates.

    Build with :meth:`from_toml` / :meth:`from_dict`, or directly::

        Sweep(base_cfg, {"copters.n": [4, 8], "behaviour.speed": [0.2, 0.4]}, replicates=5, duration=20.0,
              variants={"sonar": {"ideal": {"sonar.error": "none", "sonar.crosstalk": "off"}, "default": {}}})

    (a mapping of lists is a full-factorial grid; ``variants`` maps factor → level name → dotted keys,
    crossed with it). Every config of the design is built on construction, so a wrong value is a
    :class:`SweepError` before anything runs.

    Attributes:
        base: the base :class:`Config` (with ``duration`` applied).
        parameters: the variant factors (file order), then the swept keys (file order).
        combinations: one dict per combination: variant factor → level name, swept key → canonical
            value (as the built config holds it).
        variants: factor → level name → {dotted key: canonical value} (empty when there are none).
        configs: the :class:`Config` of each combination.
        replicates, seed, duration, metrics, design ("grid", "random" or "single"), source, text.
    """

    def __init__(self, base: Config | str | Path | Mapping | None = None,
                 grid: Mapping[str, Sequence[Any]] | None = None, *, replicates: int = DEFAULT_REPLICATES,
                 seed: int = 0, duration: float | None = None, metrics: Iterable[str] | None = None,
                 combinations: Sequence[Mapping[str, Any]] | None = None, design: str | None = None,
                 source: str = "sweep", text: str | None = None, description: str = "",
                 variants: Mapping[str, Mapping[str, Mapping[str, Any]]] | None = None):
        p = _Parser(source)
        self.source, self.text, self.description = source, text, description
        self.replicates = p.integer("replicates", replicates, 1)
        self.seed = p.integer("seed", seed, 0, 2**63 - 1)
        if isinstance(metrics, str):
            metrics = [metrics]
        try:
            self.metrics = check_metric_names(metrics)
        except ValueError as exc:
            raise p.error(f"metrics: {exc}") from None
        if metrics is not None and not self.metrics:
            raise p.error("metrics = []: expected at least one metric name")
        try:
            base_cfg = load_scenario(base)
            if duration is not None:
                if not _is_number(duration) or not math.isfinite(duration) or duration <= 0:
                    raise SweepError(f"duration = {duration!r}: expected a number of seconds > 0")
                base_cfg = base_cfg.replace({"simulation.duration": float(duration)})
        except SweepError as exc:
            raise p.error(str(exc)) from None
        except ConfigError as exc:
            raise p.error(f"[base] {exc}") from None
        self.base = base_cfg
        self.duration = self.base.simulation.duration

        if grid is not None and combinations is not None:
            raise p.error("give either a grid or explicit combinations, not both")
        if grid is not None:
            grid = {p.check_key("grid", k): v for k, v in grid.items()}
            for key, values in grid.items():
                if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
                    raise p.error(f"[grid] {key} = {values!r}: expected a list of values")
                if len(values) == 0:
                    raise p.error(f"[grid] {key} = []: expected a non-empty list of values")
            canonical = {k: [self._value(p, "grid", k, v) for v in vals] for k, vals in grid.items()}
            for key, vals in canonical.items():
                dup = [v for i, v in enumerate(vals) if v in vals[:i]]
                if dup:
                    raise p.error(f"[grid] {key} lists {_fmt(dup[0])} more than once")
            self.parameters = tuple(canonical)
            combos = [dict(zip(self.parameters, vals)) for vals in itertools.product(*canonical.values())]
            self.design = design or ("grid" if self.parameters else "single")
        else:
            combos = [dict(c) for c in (combinations or [{}])]
            keys = list(combos[0]) if combos else []
            for c in combos:
                if list(c) != keys:
                    raise p.error(f"every combination must set the same keys; got {list(c)} and {keys}")
            for k in keys:
                p.check_key("random" if design == "random" else "grid", k)
            self.parameters = tuple(keys)
            self.design = design or ("grid" if keys else "single")
        if not combos:
            raise p.error("the design has no combinations")

        self.variants = self._check_variants(p, variants, self.parameters)
        if self.variants and self.design == "single":
            self.design = "grid"
        swept = self.parameters
        self.parameters = tuple(self.variants) + swept
        choices = list(itertools.product(*[[(f, name) for name in levels] for f, levels in self.variants.items()]))
        crossed = []  # (labels, updates) per combination: variant levels outermost
        for choice in choices:
            settings: dict[str, Any] = {}
            for factor, name in choice:
                settings.update(self.variants[factor][name])
            for combo in combos:
                crossed.append(({**dict(choice), **combo}, {**settings, **combo}))

        self.configs: list[Config] = []
        self.combinations: list[dict[str, Any]] = []
        for k, (combo, updates) in enumerate(crossed):
            try:
                cfg = self.base.replace(updates)
                n_steps = int(round(cfg.simulation.duration / cfg.simulation.dt))
                if n_steps < 1:
                    raise ConfigError(f"simulation.duration = {cfg.simulation.duration!r}: expected at least one step "
                                      f"of simulation.dt = {cfg.simulation.dt!r} s")
                check_runnable(cfg)
            except ConfigError as exc:
                raise p.error(f"combination {k} ({format_params(combo)}): {exc}") from None
            self.configs.append(cfg)
            self.combinations.append({**{f: combo[f] for f in self.variants}, **{key: _get(cfg, key) for key in swept}})

    def _check_variants(self, p: _Parser, variants, swept: Sequence[str]) -> dict[str, dict[str, dict[str, Any]]]:
        """factor → level → {key: canonical value}, checked: names, keys, whole levels on the base config,
        no key set twice (by two factors, or by a factor and the grid), no two levels alike."""
        if variants is None:
            return {}
        if not isinstance(variants, Mapping):
            raise p.error(f"variants = {variants!r}: expected tables [variants.<factor>] of level = {{dotted keys}}")
        out: dict[str, dict[str, dict[str, Any]]] = {}
        owner: dict[str, str] = {key: "[grid]" for key in swept}
        for factor, levels in variants.items():
            where = f"[variants.{factor}]"
            if not isinstance(factor, str) or not factor or "." in factor:
                raise p.error(f"{where}: a variant factor name must be a non-empty name without dots "
                              "(it names a results column; dotted names are config keys)")
            if factor in swept or factor == "profile" or factor in _RESULT_COLUMNS or factor in METRICS:
                raise p.error(f"{where}: the factor name {factor!r} clashes with a results column; rename it")
            if not isinstance(levels, Mapping):
                raise p.error(f"{where} = {levels!r}: expected a table of levels, e.g. "
                              f"name = {{ \"sonar.error\" = \"none\" }}")
            if not levels:
                raise p.error(f"{where} is empty: expected at least one level name = {{dotted config keys}}")
            out[factor] = {}
            built: dict[str, Config] = {}
            for name, settings in levels.items():
                lwhere = f"[variants.{factor}] {name}"
                if not isinstance(settings, Mapping):
                    raise p.error(f"{lwhere} = {settings!r}: expected a table of dotted config keys, e.g. "
                                  f"{{ \"sonar.error\" = \"none\" }} ({{}} = the base values)")
                flat = p.flatten(lwhere, settings, lambda v: False)
                for key in flat:
                    p.check_key(f"variants.{factor}.{name}", key)
                    if key in owner and owner[key] != where:
                        raise p.error(f"{lwhere} sets {key}, which {owner[key]} also sets: a key belongs to one "
                                      "factor")
                    owner[key] = where
                try:
                    cfg = self.base.replace(flat) if flat else self.base
                except ConfigError as exc:
                    raise p.error(f"{lwhere}: {exc}") from None
                for other, other_cfg in built.items():
                    if other_cfg == cfg:
                        raise p.error(f"{where}: levels {other!r} and {name!r} give the same configuration")
                built[name] = cfg
                out[factor][name] = {key: _get(cfg, key) for key in flat}
        return out

    def _value(self, p: _Parser, table: str, key: str, value):
        """The canonical form of one swept value (as a Config holds it), checked on the base config."""
        try:
            return _get(self.base.replace({key: value}), key)
        except ConfigError as exc:
            raise p.error(f"[{table}] {exc}") from None

    # -------------------------------------------------------------------------------- constructors

    @classmethod
    def from_toml(cls, source: str | Path) -> "Sweep":
        """A sweep from a TOML file path or TOML text. ``[base] config`` paths are relative to the file."""
        path = Path(source) if not (isinstance(source, str) and "\n" in source) else None
        if path is not None:
            try:
                is_file = path.is_file()
            except OSError:
                is_file = False
            if not is_file:
                if isinstance(source, str) and ("=" in source or source.lstrip().startswith("[")):
                    path = None
                elif not path.exists():
                    raise SweepError(f"sweep file {str(path)!r} does not exist")
                else:
                    raise SweepError(f"sweep file {str(path)!r} is not a file")
        if path is not None:
            try:
                text = path.read_text()
            except UnicodeDecodeError:
                raise SweepError(f"{path}: not a text (TOML) file") from None
            except OSError as exc:
                raise SweepError(f"cannot read sweep file {str(path)!r}: {exc.strerror or exc}") from None
            name, base_dir = str(path), path.parent
        else:
            text, name, base_dir = str(source), "sweep", Path.cwd()
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SweepError(f"{name}: invalid TOML: {exc}") from None
        return cls.from_dict(data, base_dir=base_dir, source=name, text=text)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base_dir: str | Path | None = None, source: str = "sweep",
                  text: str | None = None) -> "Sweep":
        """A sweep from the parsed TOML tables (see the module docstring for the format)."""
        p = _Parser(source)
        if not isinstance(data, Mapping):
            raise p.error(f"expected a table of sweep keys, got {type(data).__name__}")
        for key in data:
            if key not in TOP_KEYS:
                section_hint = (f"; config sections go under [base.{key}] and swept keys under [grid]"
                                if key in SECTIONS else "")
                raise p.error(f"unknown key {key!r}{_suggest(key, TOP_KEYS)}; allowed: {', '.join(TOP_KEYS)}{section_hint}")
        base_dir = Path.cwd() if base_dir is None else Path(base_dir)

        description = data.get("description", "")
        if not isinstance(description, str):
            raise p.error(f"description = {description!r}: expected a string")
        metrics = data.get("metrics")
        if metrics is not None and (not isinstance(metrics, list) or not all(isinstance(m, str) for m in metrics)):
            raise p.error(f"metrics = {metrics!r}: expected a list of metric names ({', '.join(METRICS)})")
        duration = data.get("duration")
        if duration is not None and (not _is_number(duration) or not math.isfinite(duration) or duration <= 0):
            raise p.error(f"duration = {duration!r}: expected a number of seconds > 0")

        base = cls._base_from_table(p, data.get("base", {}), base_dir)
        variants = data.get("variants")
        if variants is not None and not isinstance(variants, Mapping):
            raise p.error(f"variants = {variants!r}: expected tables [variants.<factor>] of level = {{dotted keys}}")

        if "grid" in data and "random" in data:
            raise p.error("found both [grid] and [random]: a sweep uses one design")
        grid = combinations = design = None
        if "grid" in data:
            table = data["grid"]
            if not isinstance(table, Mapping):
                raise p.error(f"grid = {table!r}: expected a table [grid] of dotted keys -> lists")
            grid = p.flatten("grid", table, lambda v: any(k in v for k in _SPEC_KEYS))
            if not grid and not variants:
                raise p.error("[grid] is empty: expected dotted config keys -> lists of values")
        elif "random" in data:
            combinations = cls._random_design(p, data["random"], base, data.get("seed", 0), duration)
            design = "random"
        return cls(base, grid, replicates=data.get("replicates", DEFAULT_REPLICATES), seed=data.get("seed", 0),
                   duration=duration, metrics=metrics, combinations=combinations, design=design, source=source,
                   text=text, description=description, variants=variants)

    @staticmethod
    def _base_from_table(p: _Parser, table, base_dir: Path) -> Config:
        if not isinstance(table, Mapping):
            raise p.error(f"base = {table!r}: expected a table [base] (config = 'scenario.toml' and/or sections)")
        inline: dict[str, Any] = {}
        cfg_path = None
        for key, value in table.items():
            if key == "config":
                if not isinstance(value, str) or not value:
                    raise p.error(f"[base] config = {value!r}: expected the path of a scenario TOML file")
                cfg_path = Path(value) if Path(value).is_absolute() else base_dir / value
            elif key == "profile":
                inline["profile"] = value
            elif key in SECTIONS:
                if not isinstance(value, Mapping):
                    raise p.error(f"[base] {key} = {value!r}: expected a table [base.{key}]")
                for k, v in value.items():
                    try:
                        check_key(key, k)
                    except ConfigError as exc:
                        raise p.error(f"[base] {exc}") from None
                    inline[f"{key}.{k}"] = v
            else:
                allowed = ["config", "profile", *SECTIONS]
                raise p.error(f"[base] unknown key {key!r}{_suggest(key, allowed)}; allowed: config, profile, "
                              f"or a config section table [base.<section>] ({', '.join(SECTIONS)})")
        try:
            if cfg_path is not None:
                if not cfg_path.is_file():
                    raise ConfigError(f"config = {str(cfg_path)!r}: scenario file does not exist")
                try:
                    cfg = load_scenario(cfg_path)
                except ConfigError as exc:
                    msg = str(exc)
                    raise ConfigError(msg if str(cfg_path) in msg else f"{cfg_path}: {msg}") from None
            else:
                cfg = load_scenario(None)
            if "profile" in inline and not isinstance(inline["profile"], str):
                raise ConfigError(f"profile = {inline['profile']!r}: expected a string")
            return cfg.replace(inline) if inline else cfg
        except ConfigError as exc:
            raise p.error(f"[base] {exc}") from None

    @staticmethod
    def _random_design(p: _Parser, table, base: Config, seed, duration) -> list[dict[str, Any]]:
        if not isinstance(table, Mapping):
            raise p.error(f"random = {table!r}: expected a table [random] with n_samples and dotted keys -> specs")
        table = dict(table)
        if "n_samples" not in table:
            raise p.error("[random] needs n_samples = <number of parameter samples>")
        n = p.integer("[random] n_samples", table.pop("n_samples"), 1)
        specs = p.flatten("random", table, lambda v: any(k in v for k in _SPEC_KEYS))
        if not specs:
            raise p.error("[random] has no parameters: expected dotted keys -> {low, high} or {choices}")
        seed = p.integer("seed", seed, 0, 2**63 - 1)
        draws: dict[str, Callable[[np.random.Generator], Any]] = {}
        for key, spec in specs.items():
            p.check_key("random", key)
            where = f"[random] {key}"
            if not isinstance(spec, Mapping):
                raise p.error(f"{where} = {spec!r}: expected {{low = .., high = ..}} or {{choices = [..]}}")
            unknown = [k for k in spec if k not in _SPEC_KEYS]
            if unknown:
                raise p.error(f"{where}: unknown key {unknown[0]!r}{_suggest(unknown[0], _SPEC_KEYS)}; "
                              f"allowed: low, high, log (or choices)")
            kind = _field_kind(key)
            if "choices" in spec:
                if set(spec) != {"choices"}:
                    raise p.error(f"{where}: give either choices or low/high, not both")
                choices = spec["choices"]
                if not isinstance(choices, list) or not choices:
                    raise p.error(f"{where}.choices = {choices!r}: expected a non-empty list of values")
                draws[key] = lambda rng, c=list(choices): c[int(rng.integers(len(c)))]
                continue
            if "low" not in spec or "high" not in spec:
                raise p.error(f"{where} = {dict(spec)!r}: expected both low and high (or choices)")
            lo, hi, log = spec["low"], spec["high"], spec.get("log", False)
            if kind not in ("int", "float"):
                raise p.error(f"{where}: {key} takes {kind} values; use {{choices = [..]}} instead of low/high")
            for name, v in (("low", lo), ("high", hi)):
                if not _is_number(v) or not math.isfinite(v):
                    raise p.error(f"{where}.{name} = {v!r}: expected a finite number")
                if kind == "int" and not isinstance(v, int):
                    raise p.error(f"{where}.{name} = {v!r}: {key} is an integer key; expected an integer")
            if not isinstance(log, bool):
                raise p.error(f"{where}.log = {log!r}: expected true or false")
            if not lo < hi:
                raise p.error(f"{where}: low = {lo!r}, high = {hi!r}: expected low < high")
            if log and lo <= 0:
                raise p.error(f"{where}: log = true needs low > 0, got low = {lo!r}")
            if kind == "int":
                if log:
                    draws[key] = lambda rng, a=lo, b=hi: int(min(b, math.floor(math.exp(rng.uniform(math.log(a), math.log(b + 1))))))
                else:
                    draws[key] = lambda rng, a=lo, b=hi: int(rng.integers(a, b + 1))
            elif log:
                draws[key] = lambda rng, a=lo, b=hi: float(math.exp(rng.uniform(math.log(a), math.log(b))))
            else:
                draws[key] = lambda rng, a=lo, b=hi: float(rng.uniform(a, b))
        rng = np.random.default_rng(np.random.SeedSequence([seed, _SEED_TAG_DESIGN]))
        return [{key: draw(rng) for key, draw in draws.items()} for _ in range(n)]

    # -------------------------------------------------------------------------------- the runs

    @property
    def n_combinations(self) -> int:
        return len(self.configs)

    @property
    def n_runs(self) -> int:
        return self.n_combinations * self.replicates

    def run_seed(self, combination: int, replicate: int) -> int:
        """The seed of replicate ``replicate`` of ``combination`` (depends on the sweep seed, k and r only)."""
        return _seed_for(self.seed, combination, replicate)

    def runs(self) -> list[Run]:
        """Every run, in run-id order (run_id = combination * replicates + replicate)."""
        return [Run(k * self.replicates + r, k, r, self.run_seed(k, r), self.combinations[k])
                for k in range(self.n_combinations) for r in range(self.replicates)]

    def fingerprint(self) -> str:
        """Hash of everything that decides the results (configs, replicates, seed, metrics)."""
        content = {"configs": [c.to_dict() for c in self.configs], "parameters": list(self.parameters),
                   "replicates": self.replicates, "seed": self.seed, "metrics": list(self.metrics)}
        if self.variants:  # level names are results columns too (unchanged hash for sweeps without variants)
            content["levels"] = [{f: c[f] for f in self.variants} for c in self.combinations]
        payload = json.dumps(content, sort_keys=True, default=str)
        return hashlib.sha256(payload.encode()).hexdigest()

    def __repr__(self):
        return (f"Sweep({self.design}: {self.n_combinations} combinations of {list(self.parameters)} x "
                f"{self.replicates} replicates = {self.n_runs} runs of {self.duration:g} s, metrics {list(self.metrics)})")


# ------------------------------------------------------------------------------------------ workers

_THREADS_LIMITED = False


def _limit_threads() -> None:
    """One numba thread per worker process: each run is a single environment, parallelism is across runs."""
    global _THREADS_LIMITED
    if not _THREADS_LIMITED:
        try:
            import numba

            numba.set_num_threads(1)
        except Exception:  # pragma: no cover - best effort
            pass
        _THREADS_LIMITED = True


def _worker_init() -> None:
    _limit_threads()


def _execute(task: Mapping[str, Any]) -> dict[str, Any]:
    """Run one task in a worker: build its config, call the runner, catch its exception. Top-level (picklable)."""
    from .config import config_from_dict

    if task.get("single_thread"):
        _limit_threads()
    names = task["metrics"]
    out: dict[str, Any] = {"run_id": task["run_id"]}
    t0 = time.perf_counter()
    try:
        cfg = config_from_dict(task["config"])
        runner = task.get("runner")
        if runner is None:
            values = run_episode(cfg, task["seed"], 0, names)
        else:
            values = runner(cfg, task["seed"], 0)
        missing = [m for m in names if m not in values]
        if missing:
            raise KeyError(f"the runner returned no value for metric(s) {', '.join(missing)}")
        out.update({m: float(values[m]) for m in names})
        out["status"], out["error"] = "ok", ""
    except Exception as exc:  # a failing run is a result, not a crash of the sweep
        out.update({m: math.nan for m in names})
        out["status"], out["error"] = "error", f"{type(exc).__name__}: {exc}"
    out["elapsed"] = time.perf_counter() - t0
    return out


def _lost(task, exc: BaseException) -> dict[str, Any]:
    """Row of a run whose worker failed (no result came back); it gets no part, so resume retries it."""
    row = {"run_id": task["run_id"], **{m: math.nan for m in task["metrics"]}, "status": "error",
           "error": f"{type(exc).__name__}: {exc} (the worker failed; the run is retried by resume)",
           "elapsed": math.nan, "_no_part": True}
    return row


def _run_serial(tasks: list[dict]) -> Iterator[dict]:
    for task in tasks:
        yield _execute(task)


def _run_process(tasks: list[dict], workers: int) -> Iterator[dict]:
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    # spawn: numba's OpenMP threads make fork unsafe; the workers import finkensim afresh
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_init)
    pending: dict = {}
    todo = iter(tasks)
    try:
        def fill():
            while len(pending) < 4 * workers:
                task = next(todo, None)
                if task is None:
                    return
                pending[pool.submit(_execute, task)] = task

        fill()
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                exc = fut.exception()
                yield _lost(task, exc) if exc is not None else fut.result()
            fill()
    finally:
        pool.shutdown(wait=not pending, cancel_futures=True)


def _dask_client(workers: int, scheduler: str | None):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise SweepError("executor 'dask' needs dask.distributed: pip install 'finkensim[dask]'") from None
    import logging

    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise SweepError(f"cannot connect to the Dask scheduler at {scheduler!r}: {exc}") from None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


def _run_dask(tasks: list[dict], workers: int, client) -> Iterator[dict]:
    from distributed import as_completed

    n_inflight = 4 * max(1, len(client.scheduler_info().get("workers", {})) or workers)
    pending: dict = {}
    todo = iter(tasks)
    ac = as_completed()
    try:
        def fill():
            while len(pending) < n_inflight:
                task = next(todo, None)
                if task is None:
                    return
                fut = client.submit(_execute, task, pure=False)
                pending[fut] = task
                ac.add(fut)

        fill()
        for fut in ac:
            task = pending.pop(fut)
            if fut.status == "finished":
                yield fut.result()
            else:
                try:
                    exc = fut.exception()
                except Exception as e:  # pragma: no cover - cancelled futures
                    exc = e
                yield _lost(task, exc)
            fill()
    finally:
        for fut in pending:
            fut.cancel()


# ------------------------------------------------------------------------------------------ output

def _arrow_schema(sweep: Sweep):
    import pyarrow as pa

    fields = [pa.field("run_id", pa.int64()), pa.field("combination", pa.int64())]
    for key in sweep.parameters:
        vals = [c[key] for c in sweep.combinations]
        if all(isinstance(v, bool) for v in vals):
            t = pa.bool_()
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
            t = pa.int64()
        elif all(_is_number(v) for v in vals):
            t = pa.float64()
        else:
            t = pa.string()
        fields.append(pa.field(key, t))
    fields += [pa.field("replicate", pa.int64()), pa.field("seed", pa.int64())]
    fields += [pa.field(m, pa.float64()) for m in sweep.metrics]
    fields += [pa.field("status", pa.string()), pa.field("error", pa.string()), pa.field("elapsed", pa.float64())]
    return pa.schema(fields)


def _column_value(v):
    return json.dumps(list(v)) if isinstance(v, tuple) else v


def _row(run: Run, result: Mapping[str, Any], sweep: Sweep) -> dict[str, Any]:
    row = {"run_id": run.run_id, "combination": run.combination}
    row.update({k: _column_value(run.params[k]) for k in sweep.parameters})
    row.update({"replicate": run.replicate, "seed": run.seed})
    row.update({m: result[m] for m in sweep.metrics})
    row.update({"status": result["status"], "error": result["error"], "elapsed": result["elapsed"]})
    return row


def _part_path(parts: Path, run_id: int) -> Path:
    return parts / f"run-{run_id:05d}.parquet"


def _write_atomic(path: Path, write: Callable[[Path], None]) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _write_part(parts: Path, row: Mapping[str, Any], schema) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist([dict(row)], schema=schema)
    _write_atomic(_part_path(parts, row["run_id"]), lambda p: pq.write_table(table, p))


def _read_parts(parts: Path, sweep: Sweep, schema) -> dict[int, dict]:
    """Rows of the parts present in ``parts`` (unreadable or foreign parts are skipped with a warning)."""
    import pyarrow.parquet as pq

    rows: dict[int, dict] = {}
    if not parts.is_dir():
        return rows
    for path in sorted(parts.glob("run-*.parquet")):
        try:
            run_id = int(path.stem.split("-", 1)[1])
            table = pq.read_table(path)
            row = table.to_pylist()[0]
            if row["run_id"] != run_id or run_id >= sweep.n_runs or table.schema.names != schema.names:
                raise ValueError("it does not belong to this sweep")
        except Exception as exc:
            warnings.warn(f"ignoring {path} ({exc}); its run will be run again", RuntimeWarning, stacklevel=3)
            continue
        rows[run_id] = row
    return rows


def _prepare_out(out: Path, sweep: Sweep, resume: bool, overwrite: bool) -> None:
    parts = out / "parts"
    meta = out / "sweep.json"
    existing = sorted(parts.glob("run-*.parquet")) if parts.is_dir() else []
    outputs = [out / n for n in ("results.parquet", "summary.csv", "summary.png")]
    fingerprint = sweep.fingerprint()
    if resume and (existing or meta.exists()):
        try:
            old = json.loads(meta.read_text())["fingerprint"]
        except (OSError, ValueError, KeyError, TypeError):
            old = None
        if old != fingerprint and not overwrite:
            raise SweepError(f"{out} holds results of a different sweep (its sweep.json does not match "
                             f"{sweep.source}); choose another --out or pass --overwrite to start again")
        if old != fingerprint:
            resume = False
    if not resume and (existing or any(p.exists() for p in outputs)):
        if not overwrite:
            raise SweepError(f"{out} already holds results of a sweep ({len(existing)} finished runs); pass --resume "
                             "to finish it, --overwrite to start again, or choose another --out")
        for p in existing + [p for p in outputs if p.exists()]:
            p.unlink()
    try:
        parts.mkdir(parents=True, exist_ok=True)
        for stale in parts.glob(".run-*.tmp-*"):
            stale.unlink()
        info = {"fingerprint": fingerprint, "finkensim": __version__, "source": sweep.source,
                "description": sweep.description, "design": sweep.design, "parameters": list(sweep.parameters),
                "variants": {f: {n: {k: _column_value(v) for k, v in lv.items()} for n, lv in levels.items()}
                             for f, levels in sweep.variants.items()},
                "combinations": [{k: _column_value(v) for k, v in c.items()} for c in sweep.combinations],
                "replicates": sweep.replicates, "seed": sweep.seed, "duration": sweep.duration,
                "metrics": list(sweep.metrics), "n_runs": sweep.n_runs, "sweep_toml": sweep.text,
                "base_config": sweep.base.to_dict()}
        _write_atomic(meta, lambda p: p.write_text(json.dumps(info, indent=1, default=str)))
    except OSError as exc:
        raise SweepError(f"cannot write to output directory {str(out)!r}: {exc.strerror or exc}") from None


def load_results(out: str | Path):
    """The results table of a finished sweep directory (``out/results.parquet``) as a DataFrame."""
    import pandas as pd

    return pd.read_parquet(Path(out) / "results.parquet")


def summarize(results, parameters: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
              confidence: float = 0.95):
    """Per combination: n_runs, n_ok, n_error and ``<metric>_mean``, ``_ci_low``, ``_ci_high``.

    The interval is the Student-t confidence interval of the mean over successful runs with a
    finite value: mean ± t_{(1+confidence)/2, n−1} · s / √n (NaN when n < 2).
    """
    import pandas as pd
    from scipy.special import stdtrit  # Student-t quantile (scipy.stats takes a second to import)

    metrics = [m for m in (metrics or METRICS) if m in results.columns]
    if parameters is None:
        fixed = {"run_id", "combination", "replicate", "seed", "status", "error", "elapsed", *METRICS}
        parameters = [c for c in results.columns if c not in fixed]
    rows = []
    for k, g in results.groupby("combination", sort=True):
        ok = g[g["status"] == "ok"]
        row = {"combination": int(k), **{p: g[p].iloc[0] for p in parameters},
               "n_runs": len(g), "n_ok": len(ok), "n_error": len(g) - len(ok)}
        for m in metrics:
            v = ok[m].to_numpy(dtype=float)
            v = v[np.isfinite(v)]
            mean = float(v.mean()) if v.size else math.nan
            if v.size >= 2:
                half = float(stdtrit(v.size - 1, 0.5 + confidence / 2) * v.std(ddof=1) / math.sqrt(v.size))
            else:
                half = math.nan
            row.update({f"{m}_mean": mean, f"{m}_ci_low": mean - half, f"{m}_ci_high": mean + half})
        rows.append(row)
    return pd.DataFrame(rows)


def _factorial_layout(summary, parameters: Sequence[str]):
    """(groups, series) for a full-factorial summary of >= 2 parameters: the last parameter as coloured
    series, the others as x groups (file order), each (group, series) pair exactly one row; else None."""
    if len(parameters) < 2 or len(summary) > 60:
        return None
    *outer, last = parameters
    keys = [tuple(summary[p].iloc[i] for p in outer) for i in range(len(summary))]
    series = list(dict.fromkeys(summary[last].tolist()))
    groups = list(dict.fromkeys(keys))
    pairs = set(zip(keys, summary[last].tolist()))
    if len(series) < 2 or len(pairs) != len(summary) or len(groups) * len(series) != len(summary):
        return None
    return groups, series


def plot_summary(summary, parameters: Sequence[str], metrics: Sequence[str]):
    """A matplotlib Figure: one panel per metric, mean ± CI (error bars) for each combination.

    A full-factorial design of two or more parameters is drawn grouped: the last parameter as
    coloured, side-by-side markers (legend), the other parameters' combinations along x.
    """
    from matplotlib.figure import Figure

    n = len(metrics)
    ncols = min(3, n)
    nrows = math.ceil(n / ncols)
    K = len(summary)
    layout = _factorial_layout(summary, parameters)
    n_x = len(layout[0]) if layout else K
    width = max(4.5 * ncols, min(24.0, (0.3 * n_x + 1.5 + (0.6 if layout else 0.0)) * ncols))
    fig = Figure(figsize=(width, 3.4 * nrows + (1.2 if K > 1 else 0.4)), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    if layout:
        groups, series = layout
        *outer, last = parameters
        x_of = np.array([groups.index(tuple(summary[p].iloc[i] for p in outer)) for i in range(K)], dtype=float)
        s_of = np.array([series.index(v) for v in summary[last]])
        span = min(0.7, 0.18 * len(series))
        x_of = x_of + (s_of - (len(series) - 1) / 2) * (span / max(1, len(series) - 1))
        x = np.arange(len(groups))
        labels = [", ".join(_fmt(v) for v in g) for g in groups]
        xlabel = ", ".join(outer)
    else:
        x = x_of = np.arange(K)
        s_of = np.zeros(K, dtype=int)
        series = [None]
        if len(parameters) == 1:
            labels = [_fmt(v) for v in summary[parameters[0]]]
            xlabel = parameters[0]
        elif parameters:
            labels = [", ".join(_fmt(summary[p].iloc[i]) for p in parameters) for i in range(K)]
            xlabel = ", ".join(parameters)
        else:
            labels, xlabel = ["base"], ""
    for i, m in enumerate(metrics):
        ax = axes[i // ncols][i % ncols]
        mean = summary[f"{m}_mean"].to_numpy(dtype=float)
        lo = mean - summary[f"{m}_ci_low"].to_numpy(dtype=float)
        hi = summary[f"{m}_ci_high"].to_numpy(dtype=float) - mean
        for j, value in enumerate(series):
            sel = s_of == j
            label = _fmt(value) if value is not None else None
            ax.errorbar(x_of[sel], mean[sel], yerr=np.vstack([np.nan_to_num(lo[sel]), np.nan_to_num(hi[sel])]),
                        fmt="o", capsize=3, ms=4, label=label)
        info = METRICS.get(m)
        ax.set_title(m)
        ax.set_ylabel(info.unit if info else "")
        ax.grid(alpha=0.3)
        if len(x) <= 40:
            slanted = len(x) > 4 or len(parameters) > (2 if layout else 1)
            ax.set_xticks(x, labels, rotation=45 if slanted else 0, ha="right" if slanted else "center",
                          fontsize=7 if len(x) > 12 else 8)
        else:
            ax.set_xlabel("combination")
        if xlabel and len(x) <= 40:
            ax.set_xlabel(xlabel, fontsize=8)
        if layout and i == 0:
            ax.legend(fontsize=7, title=parameters[-1], title_fontsize=7, loc="best")
    for j in range(n, nrows * ncols):
        axes[j // ncols][j % ncols].set_visible(False)
    fig.suptitle("sweep summary: mean ± 95 % CI per combination", fontsize=10)
    return fig


# ------------------------------------------------------------------------------------------ running

def _check_executor(executor: str, scheduler: str | None) -> str:
    if executor not in EXECUTORS:
        raise SweepError(f"executor = {executor!r}: expected one of {', '.join(map(repr, EXECUTORS))}"
                         f"{_suggest(executor, EXECUTORS)}")
    if scheduler and executor != "dask":
        raise SweepError(f"scheduler = {scheduler!r} needs executor 'dask', got {executor!r}")
    return executor


def run_sweep(sweep: Sweep | str | Path | Mapping[str, Any], out: str | Path | None = None, *,
              executor: str = "process", workers: int | None = None, scheduler: str | None = None,
              resume: bool = False, overwrite: bool = False, progress: bool = True,
              runner: Callable[..., Mapping[str, float]] | None = None):
    """Run every run of ``sweep`` and return the results as a pandas DataFrame sorted by run id.

    Args:
        sweep: a :class:`Sweep`, a sweep TOML path or text, or the parsed tables.
        out: output directory (see the module docstring); None keeps the results in memory only.
        executor: "process" (local process pool, the default), "serial" (in this process, for
            debugging) or "dask" (a Dask cluster: ``scheduler`` address, or a LocalCluster).
        workers: worker processes (default: all cores) for "process" and the Dask LocalCluster.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``); its workers need finkensim.
        resume: run only the runs whose part is missing in ``out`` (same sweep only).
        overwrite: start again in an ``out`` that holds results (otherwise that is an error).
        progress: show a tqdm progress bar.
        runner: ``f(cfg, seed, env_id) -> {metric: value}`` called instead of
            :func:`~finkensim.episode.run_episode`; must be a picklable top-level function.

    Returns:
        DataFrame with ``run_id, combination, <parameters>, replicate, seed, <metrics>, status,
        error, elapsed``. ``df.attrs``: "ran" (run ids executed by this call), "failed" (run ids
        with status "error"), "out" (the directory or None).

    Raises:
        SweepError: before any run starts, for a bad sweep, executor, worker count, scheduler or ``out``.
    """
    if not isinstance(sweep, Sweep):
        sweep = Sweep.from_dict(sweep) if isinstance(sweep, Mapping) else Sweep.from_toml(sweep)
    executor = _check_executor(executor, scheduler)
    n_cpu = os.cpu_count() or 1
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise SweepError(f"workers = {workers!r}: expected a positive integer")
    workers = workers or n_cpu
    if runner is not None and not callable(runner):
        raise SweepError(f"runner = {runner!r}: expected a function f(cfg, seed, env_id) -> dict of metrics")
    if resume and out is None:
        raise SweepError("resume needs an output directory (out)")

    import pyarrow as pa

    with warnings.catch_warnings():  # tqdm.auto warns in Jupyter without ipywidgets, then falls back to text
        warnings.simplefilter("ignore")
        from tqdm.auto import tqdm

    schema = _arrow_schema(sweep)
    runs = sweep.runs()
    out_dir = Path(out) if out is not None else None
    dask: list = []  # [client, cluster or None] once connected
    if executor == "dask" and scheduler:
        dask[:] = _dask_client(workers, scheduler)  # an unreachable scheduler fails before out is touched
    results: Iterator[dict] = iter(())
    try:
        done: dict[int, dict] = {}
        if out_dir is not None:
            _prepare_out(out_dir, sweep, resume, overwrite)
            if resume:
                done = _read_parts(out_dir / "parts", sweep, schema)
        todo = [r for r in runs if r.run_id not in done]
        cfg_dicts = [c.to_dict() for c in sweep.configs]
        tasks = [{"run_id": r.run_id, "config": cfg_dicts[r.combination], "seed": r.seed,
                  "metrics": list(sweep.metrics), "runner": runner, "single_thread": executor != "serial"}
                 for r in todo]
        if executor == "serial":
            results = _run_serial(tasks)
        elif executor == "process":
            results = _run_process(tasks, min(workers, max(1, len(tasks)))) if tasks else iter(())
        elif tasks:
            if not dask:
                dask[:] = _dask_client(workers, None)
            results = _run_dask(tasks, workers, dask[0])

        by_id = {r.run_id: r for r in runs}
        rows = dict(done)
        ran: list[int] = []
        n_failed = sum(1 for r in done.values() if r["status"] != "ok")
        with tqdm(total=sweep.n_runs, initial=len(done), desc="sweep", unit="run", disable=not progress,
                  dynamic_ncols=True, file=sys.stderr) as bar:
            for result in results:
                run = by_id[result["run_id"]]
                row = _row(run, result, sweep)
                if out_dir is not None and not result.get("_no_part"):
                    _write_part(out_dir / "parts", row, schema)
                rows[run.run_id] = row
                ran.append(run.run_id)
                n_failed += row["status"] != "ok"
                bar.update(1)
                if n_failed:
                    bar.set_postfix(failed=n_failed, refresh=False)
    finally:
        close = getattr(results, "close", None)
        if close is not None:
            close()  # shuts a process pool down, cancels pending Dask futures
        if dask:
            dask[0].close()
            if dask[1] is not None:
                dask[1].close()

    table = pa.Table.from_pylist([rows[k] for k in sorted(rows)], schema=schema)
    df = table.to_pandas()
    if out_dir is not None:
        import pyarrow.parquet as pq

        _write_atomic(out_dir / "results.parquet", lambda p: pq.write_table(table, p))
        summary = summarize(df, sweep.parameters, sweep.metrics)
        _write_atomic(out_dir / "summary.csv", lambda p: summary.to_csv(p, index=False))
        fig = plot_summary(summary, sweep.parameters, sweep.metrics)
        from .viz import save_png  # a 256-colour palette PNG: the same picture at about a third of the size

        _write_atomic(out_dir / "summary.png", lambda p: save_png(fig, p, dpi=110))
    df.attrs["ran"] = sorted(ran)
    df.attrs["failed"] = [int(i) for i in df.loc[df["status"] != "ok", "run_id"]]
    df.attrs["out"] = str(out_dir) if out_dir is not None else None
    return df
