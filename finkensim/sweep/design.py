"""The sweep design: a base scenario, the variant factors and swept keys, their combinations (each
built and checked as a :class:`~finkensim.config.Config`), replicates, seeds and metrics.

The sweep file format is in :mod:`finkensim.sweep.sweepfile`; run numbering and seeds in
:mod:`finkensim.sweep.keys`.
"""
from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from ..budget import check_memory, sweep_objects
from ..config import Config, ConfigError
from ..episode import check_runnable
from ..metrics import METRICS, check_metric_names
from ..scenario import load_scenario
from .parsing import Parser, SweepError, config_value, is_duration
from .keys import DEFAULT_REPLICATES, Run, content_hash, format_params, format_value, seed_for
from .calibration import sample_for
from .sweepfile import read_sweep_toml, sweep_arguments
from .tables import RESULT_COLUMNS


MAX_COMBINATIONS = 100_000
"""Most combinations a sweep may have: each is built into a checked Config before the first run (2-16 ms each
measured on 2 busy cores with a 2000-point grid, so 10^5 take minutes; more runs come from ``replicates``)."""


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
        replicates: runs per combination.
        seed: the sweep's random seed.
        duration: episode length, s.
        metrics: the metric names recorded.
        design: ``"grid"``, ``"random"`` or ``"single"``.
        source: where the design came from (a file name, or ``"sweep"``).
        text: the design's TOML text, when it came from one.
    """

    def __init__(self, base: Config | str | Path | Mapping | None = None,
                 grid: Mapping[str, Sequence[Any]] | None = None, *, replicates: int = DEFAULT_REPLICATES,
                 seed: int = 0, duration: float | None = None, metrics: Iterable[str] | None = None,
                 combinations: Sequence[Mapping[str, Any]] | None = None, design: str | None = None,
                 source: str = "sweep", text: str | None = None, description: str = "",
                 variants: Mapping[str, Mapping[str, Mapping[str, Any]]] | None = None,
                 calibration_samples: Sequence[Mapping[str, Any]] | None = None):
        p = Parser(source)
        self.calibration_samples = [dict(s) for s in calibration_samples] if calibration_samples else None
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
                if not is_duration(duration):
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
                    raise p.error(f"[grid] {key} lists {format_value(dup[0])} more than once")
            self.parameters = tuple(canonical)
            n_grid = math.prod(len(v) for v in canonical.values())
            n_variants = math.prod(len(levels) for levels in (variants or {}).values()
                                   if isinstance(levels, Mapping)) if variants else 1
            self._check_size(p, n_grid * n_variants)
            combos = [dict(zip(self.parameters, vals)) for vals in itertools.product(*canonical.values())]
            self.design = design or ("grid" if self.parameters else "single")
        else:
            self._check_size(p, len(combinations or [{}]))
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
            self.combinations.append({**{f: combo[f] for f in self.variants}, **{key: config_value(cfg, key) for key in swept}})

    def _check_size(self, p: Parser, n_combinations: int) -> None:
        """Refuse a design whose combinations x replicates would not fit in memory, or of more than
        :data:`MAX_COMBINATIONS` combinations, before building any of it."""
        if n_combinations > MAX_COMBINATIONS:
            raise p.error(f"the design has {n_combinations:.3g} combinations, more than {MAX_COMBINATIONS}: every "
                          "combination's config is built and checked before the first run (milliseconds each), so "
                          "that alone would take hours; shorten the [grid] lists, lower [random] n_samples, or split "
                          "the sweep into several files")
        try:
            check_memory(sweep_objects(n_combinations, self.replicates),
                         f"a sweep of {n_combinations:.3g} combinations x {self.replicates} replicates",
                         "lower replicates, shorten the [grid] lists or lower [random] n_samples")
        except ConfigError as exc:
            raise p.error(str(exc)) from None

    def _check_variants(self, p: Parser, variants, swept: Sequence[str]) -> dict[str, dict[str, dict[str, Any]]]:
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
            if factor in swept or factor == "profile" or factor in RESULT_COLUMNS or factor in METRICS:
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
                out[factor][name] = {key: config_value(cfg, key) for key in flat}
        return out

    def _value(self, p: Parser, table: str, key: str, value):
        """The canonical form of one swept value (as a Config holds it), checked on the base config."""
        try:
            return config_value(self.base.replace({key: value}), key)
        except ConfigError as exc:
            raise p.error(f"[{table}] {exc}") from None

    # -------------------------------------------------------------------------------- constructors

    @classmethod
    def from_toml(cls, source: str | Path) -> "Sweep":
        """A sweep from a TOML file path or TOML text. ``[base] config`` paths are relative to the file."""
        data, base_dir, name, text = read_sweep_toml(source)
        return cls.from_dict(data, base_dir=base_dir, source=name, text=text)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base_dir: str | Path | None = None, source: str = "sweep",
                  text: str | None = None) -> "Sweep":
        """A sweep from the parsed TOML tables (see :mod:`finkensim.sweep.sweepfile` for the format)."""
        return cls(**sweep_arguments(data, base_dir, source, text))

    # -------------------------------------------------------------------------------- the runs

    @property
    def n_combinations(self) -> int:
        """The number of parameter combinations (configs)."""
        return len(self.configs)

    @property
    def n_runs(self) -> int:
        """The number of runs: combinations x replicates."""
        return self.n_combinations * self.replicates

    def run_seed(self, combination: int, replicate: int) -> int:
        """The seed of replicate ``replicate`` of ``combination`` (depends on the sweep seed, k and r only)."""
        return seed_for(self.seed, combination, replicate)

    def runs(self) -> list[Run]:
        """Every run, in run-id order (run_id = combination * replicates + replicate)."""
        return [Run(k * self.replicates + r, k, r, self.run_seed(k, r), self.combinations[k])
                for k in range(self.n_combinations) for r in range(self.replicates)]

    def run_config(self, run: Run) -> Config:
        """The config of ``run``: its combination's, under its calibration draw with ``calibration = "sample"``
        (:mod:`finkensim.sweep.calibration`; keys the design sets stay the design's)."""
        cfg = self.configs[run.combination]
        if not self.calibration_samples:
            return cfg
        swept = set(self.parameters) | {k for levels in self.variants.values() for lv in levels.values() for k in lv}
        try:
            return cfg.replace(sample_for(self.calibration_samples, self.seed, run.combination, run.replicate, swept))
        except ConfigError as exc:
            raise SweepError(f"{self.source}: calibration sample of run {run.run_id}: {exc}") from None

    def fingerprint(self) -> str:
        """Hash of everything that decides the results (configs, replicates, seed, metrics)."""
        content = {"configs": [c.to_dict() for c in self.configs], "parameters": list(self.parameters),
                   "replicates": self.replicates, "seed": self.seed, "metrics": list(self.metrics)}
        if self.variants:  # level names are results columns too (unchanged hash for sweeps without variants)
            content["levels"] = [{f: c[f] for f in self.variants} for c in self.combinations]
        if self.calibration_samples:  # unchanged hash for sweeps at the fitted values
            content["calibration_samples"] = self.calibration_samples
        return content_hash(content)

    def __repr__(self):
        return (f"Sweep({self.design}: {self.n_combinations} combinations of {list(self.parameters)} x "
                f"{self.replicates} replicates = {self.n_runs} runs of {self.duration:g} s, metrics {list(self.metrics)})")

