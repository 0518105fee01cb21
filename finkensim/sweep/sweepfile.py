"""The sweep file: from TOML text or tables to the arguments of a :class:`~finkensim.sweep.design.Sweep`.

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
"""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ..budget import check_memory, sweep_objects
from ..config import SECTIONS, Config, ConfigError, check_key
from ..usertext import loads_toml, suggest
from ..metrics import METRICS
from ..scenario import load_scenario
from .parsing import Parser, SweepError, field_kind, is_duration, is_number
from .calibration import samples_for_base
from .keys import DEFAULT_REPLICATES, SEED_TAG_DESIGN

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

TOP_KEYS = ("description", "replicates", "duration", "seed", "metrics", "base", "variants", "grid", "random",
            "calibration")
SPEC_KEYS = ("low", "high", "log", "choices")  # keys of a [random] parameter spec


def read_sweep_toml(source: str | Path) -> tuple[dict[str, Any], Path, str, str]:
    """The tables of a sweep TOML file path or TOML text: (tables, base_dir, source name, text).

    ``base_dir`` (the file's folder, or the working directory for text) anchors ``[base] config`` paths.
    """
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
        data = loads_toml(text)
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"{name}: invalid TOML: {exc}") from None
    return data, base_dir, name, text

def sweep_arguments(data: Mapping[str, Any], base_dir: str | Path | None = None, source: str = "sweep",
                    text: str | None = None) -> dict[str, Any]:
    """The keyword arguments of :class:`~finkensim.sweep.design.Sweep` for the parsed TOML tables ``data``
    (see the module docstring for the format), after checking everything the tables alone decide."""
    p = Parser(source)
    if not isinstance(data, Mapping):
        raise p.error(f"expected a table of sweep keys, got {type(data).__name__}")
    for key in data:
        if key not in TOP_KEYS:
            section_hint = (f"; config sections go under [base.{key}] and swept keys under [grid]"
                            if key in SECTIONS else "")
            raise p.error(f"unknown key {key!r}{suggest(key, TOP_KEYS)}; allowed: {', '.join(TOP_KEYS)}{section_hint}")
    base_dir = Path.cwd() if base_dir is None else Path(base_dir)

    description = data.get("description", "")
    if not isinstance(description, str):
        raise p.error(f"description = {description!r}: expected a string")
    metrics = data.get("metrics")
    if metrics is not None and (not isinstance(metrics, list) or not all(isinstance(m, str) for m in metrics)):
        raise p.error(f"metrics = {metrics!r}: expected a list of metric names ({', '.join(METRICS)})")
    duration = data.get("duration")
    if duration is not None and not is_duration(duration):
        raise p.error(f"duration = {duration!r}: expected a number of seconds > 0")

    base = base_from_table(p, data.get("base", {}), base_dir)
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
        grid = p.flatten("grid", table, lambda v: any(k in v for k in SPEC_KEYS))
        if not grid and not variants:
            raise p.error("[grid] is empty: expected dotted config keys -> lists of values")
    elif "random" in data:
        combinations = random_design(p, data["random"], data.get("seed", 0))
        design = "random"
    try:
        samples = samples_for_base(data.get("calibration", "fixed"), data.get("base", {}), base_dir)
    except SweepError as exc:
        raise p.error(str(exc)) from None
    return dict(base=base, grid=grid, replicates=data.get("replicates", DEFAULT_REPLICATES), seed=data.get("seed", 0),
                duration=duration, metrics=metrics, combinations=combinations, design=design, source=source,
                text=text, description=description, variants=variants, calibration_samples=samples)

def base_from_table(p: Parser, table, base_dir: Path) -> Config:
    """The base config of the ``[base]`` table: its ``config`` scenario file (relative to ``base_dir``) or the
    built-in scenario, with its inline ``profile`` and ``[base.<section>]`` keys applied."""
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
            raise p.error(f"[base] unknown key {key!r}{suggest(key, allowed)}; allowed: config, profile, "
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

def range_spec(p, where: str, key: str, kind: str, spec) -> tuple:
    """(low, high, log) of a ``{low, high[, log]}`` range of config key ``key`` (of type ``kind``), checked:
    finite numbers (integers for an integer key), low < high, log a bool that needs low > 0. ``p.error``
    builds the error; ``where`` names the range in it."""
    if "low" not in spec or "high" not in spec:
        raise p.error(f"{where} = {dict(spec)!r}: expected both low and high (or choices)")
    lo, hi, log = spec["low"], spec["high"], spec.get("log", False)
    if kind not in ("int", "float"):
        raise p.error(f"{where}: {key} takes {kind} values; use {{choices = [..]}} instead of low/high")
    for name, v in (("low", lo), ("high", hi)):
        if not is_number(v) or not math.isfinite(v):
            raise p.error(f"{where}.{name} = {v!r}: expected a finite number")
        if kind == "int" and not isinstance(v, int):
            raise p.error(f"{where}.{name} = {v!r}: {key} is an integer key; expected an integer")
    if not isinstance(log, bool):
        raise p.error(f"{where}.log = {log!r}: expected true or false")
    if not lo < hi:
        raise p.error(f"{where}: low = {lo!r}, high = {hi!r}: expected low < high")
    if log and lo <= 0:
        raise p.error(f"{where}: log = true needs low > 0, got low = {lo!r}")
    return lo, hi, log


def param_spec(p, section: str, key: str, spec) -> tuple:
    """(kind, choices, (low, high, log)) of one parameter spec ``{low, high[, log]}`` or ``{choices = [..]}`` of
    config key ``key`` in table ``[section]``, checked (a known key; a table with only known spec keys; choices a
    non-empty list, alone; a valid range, see :func:`range_spec`). choices is None for a range, and the range
    (None, None, False) for choices. Sweep files' ``[random]`` and study files' ``[params]`` share it."""
    p.check_key(section, key)
    where = f"[{section}] {key}"
    if not isinstance(spec, Mapping):
        raise p.error(f"{where} = {spec!r}: expected {{low = .., high = ..}} or {{choices = [..]}}")
    unknown = [k for k in spec if k not in SPEC_KEYS]
    if unknown:
        raise p.error(f"{where}: unknown key {unknown[0]!r}{suggest(unknown[0], SPEC_KEYS)}; "
                      f"allowed: low, high, log (or choices)")
    kind = field_kind(key)
    if "choices" in spec:
        if set(spec) != {"choices"}:
            raise p.error(f"{where}: give either choices or low/high, not both")
        choices = spec["choices"]
        if not isinstance(choices, list) or not choices:
            raise p.error(f"{where}.choices = {choices!r}: expected a non-empty list of values")
        return kind, tuple(choices), (None, None, False)
    return kind, None, range_spec(p, where, key, kind, spec)


def random_design(p: Parser, table, seed) -> list[dict[str, Any]]:
    """The combinations of a ``[random]`` table: ``n_samples`` dicts of dotted key -> drawn value, drawn in
    file order from SeedSequence([seed, 2])."""
    if not isinstance(table, Mapping):
        raise p.error(f"random = {table!r}: expected a table [random] with n_samples and dotted keys -> specs")
    table = dict(table)
    if "n_samples" not in table:
        raise p.error("[random] needs n_samples = <number of parameter samples>")
    n = p.integer("[random] n_samples", table.pop("n_samples"), 1)
    try:  # before drawing: each sample becomes a combination
        check_memory(sweep_objects(n), f"[random] n_samples = {n}", "lower n_samples")
    except ConfigError as exc:
        raise p.error(str(exc)) from None
    specs = p.flatten("random", table, lambda v: any(k in v for k in SPEC_KEYS))
    if not specs:
        raise p.error("[random] has no parameters: expected dotted keys -> {low, high} or {choices}")
    seed = p.integer("seed", seed, 0, 2**63 - 1)
    draws: dict[str, Callable[[np.random.Generator], Any]] = {}
    for key, spec in specs.items():
        kind, choices, (lo, hi, log) = param_spec(p, "random", key, spec)
        if choices is not None:
            draws[key] = lambda rng, c=list(choices): c[int(rng.integers(len(c)))]
            continue
        if kind == "int":
            if log:
                draws[key] = lambda rng, a=lo, b=hi: int(min(b, math.floor(math.exp(rng.uniform(math.log(a), math.log(b + 1))))))
            else:
                draws[key] = lambda rng, a=lo, b=hi: int(rng.integers(a, b + 1))
        elif log:
            draws[key] = lambda rng, a=lo, b=hi: float(math.exp(rng.uniform(math.log(a), math.log(b))))
        else:
            draws[key] = lambda rng, a=lo, b=hi: float(rng.uniform(a, b))
    rng = np.random.default_rng(np.random.SeedSequence([seed, SEED_TAG_DESIGN]))
    return [{key: draw(rng) for key, draw in draws.items()} for _ in range(n)]
