"""A calibrated scenario out of a diagnosis: the diagnosed config plus every selected effect the simulator can fly.

The diagnosis names effects and fits their parameters against its predictive model; the simulator flies the same
effects through config keys (each catalogued :class:`~finkensim.gap.attribute.effects.Effect` with a ``calibrate`` mapping
says which). :func:`calibrated_config` applies the selected effects in the order the selection added them, each on
top of the config the previous ones produced (as the diagnosis applied them to its model), and
:func:`calibrated_toml` writes the result as a scenario file that ``finkensim run``, ``sweep`` and ``tune`` read as
it is, with a comment at each key an effect set (which effect, its fitted parameters, its held-out shrink).

A selected effect without a ``calibrate`` mapping is not flown by the simulator yet: the file lists it in its header
and :func:`calibration` marks it ``flown=False``. (The flexible refit of ``wall_bulge``, :mod:`finkensim.gap.attribute.parsimony`,
fits a hinge-law weight beyond the catalogue's parameters: its mapping writes it to ``walls.bulge_hinge``.)
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from ...atomic import write_text_atomic
from ...config import Config
from ..attribute import effects as fx

__all__ = ["CalibratedEffect", "calibration", "calibrated_config", "calibrated_toml", "calibration_samples",
           "correction_files", "correction_tables", "write_calibrated", "SAMPLES_FILE", "CORRECTION_KEYS"]

#: sensor of a learned correction → the config key through which the simulator flies its table
CORRECTION_KEYS = {"ultrasonic": "sonar.correction_file", "ranging": "ranging.correction_file",
                   "imu": "imu.correction_file"}


@dataclass(frozen=True)
class CalibratedEffect:
    """One selected effect: its fitted ``params``, the config ``updates`` (dotted key → value) that fly it, whether
    the simulator flies it (``flown``), its held-out shrink alone (``shrink_heldout``, NaN if unknown) and its
    parameters' bootstrap distributions (``intervals``: parameter → {value, lo, hi, unit, values, probabilities},
    :mod:`finkensim.gap.quantify.intervals`; empty when not computed)."""

    name: str
    params: dict
    updates: dict
    flown: bool
    shrink_heldout: float
    intervals: dict = field(default_factory=dict)


def _diagnosed_config(report) -> Config:
    cfg = report.details.config
    if not isinstance(cfg, Config):
        raise ValueError("this report does not carry the config it was diagnosed with (a report read back from "
                         "report.json has none): run the diagnosis (fs.diagnose or finkensim gap) to calibrate")
    return cfg


def correction_files(cfg: Config) -> dict:
    """The learned-correction files ``cfg`` flies: config key (of :data:`CORRECTION_KEYS`) → path, the set ones only."""
    out = {}
    for key in CORRECTION_KEYS.values():
        section, name = key.split(".")
        path = getattr(getattr(cfg, section), name)
        if path:
            out[key] = path
    return out


def _flown_tables(report) -> list:
    """The sensors of the report's learned correction that the simulator flies (keys of :data:`CORRECTION_KEYS`)."""
    return [s for s in correction_tables(report) if s in CORRECTION_KEYS]


def _walk(report, correction_file: str | Path | None = None) -> tuple[Config, list[CalibratedEffect]]:
    cfg = _diagnosed_config(report)
    alone = {e["name"]: e.get("shrink_heldout", float("nan")) for e in report.effects}
    intervals = getattr(report.details, "param_intervals", None) or {}
    steps = []
    for name, params in report.details.added_params.items():
        effect = fx.REGISTRY.get(name)
        iv = dict(intervals.get(name, {}))
        if effect is None or effect.calibrate is None:
            steps.append(CalibratedEffect(name, dict(params), {}, False, alone.get(name, float("nan")), iv))
            continue
        updates = effect.calibrate(params, cfg)
        cfg = cfg.replace(updates)
        steps.append(CalibratedEffect(name, dict(params), dict(updates), True, alone.get(name, float("nan")), iv))
    if correction_file is not None:
        cfg = cfg.replace({CORRECTION_KEYS[s]: str(correction_file) for s in _flown_tables(report)})
    return cfg, steps


def correction_tables(report) -> dict:
    """The learned correction's tables of ``report``: sensor →
    :class:`~finkensim.sensors.correction_table.CorrectionTable` (empty without a correction)."""
    corr = report.details.correction
    return dict(getattr(corr, "tables", None) or {})


def calibration(report) -> list[CalibratedEffect]:
    """The selected effects of ``report`` (a :class:`~finkensim.gap.report.result.GapReport` of this session), in the
    order the selection added them, with the config updates that fly each."""
    return _walk(report)[1]


def calibrated_config(report, correction_file: str | Path | None = None) -> Config:
    """The diagnosed config with every selected, flyable effect at its fitted parameters (and, when
    ``correction_file`` is given, the ``correction_file`` key of each sensor with a learned correction set to it:
    :func:`write_calibrated` writes it)."""
    return _walk(report, correction_file)[0]


def _plain(v):
    """TOML-ready value: tuples (also nested) as lists."""
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def _fmt_params(params: dict) -> str:
    return ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in params.items())


def _fmt_intervals(intervals: dict) -> str:
    parts = [f"{k} in [{d['lo']:.4g}, {d['hi']:.4g}]{(' ' + d['unit']) if d.get('unit') else ''}"
             for k, d in intervals.items()]
    return f"; 95 % interval: {', '.join(parts)}" if parts else ""


def calibration_samples(report, n: int = 200, seed: int = 0) -> list[dict]:
    """``n`` draws of the calibration (each a dict dotted key → value, the updates of every flown effect): each
    selected effect's parameters drawn independently from their bootstrap distributions (a parameter without one at
    its fit), mapped to config keys in the selection's order as :func:`calibrated_config` does. Empty when no flown
    effect has a distribution."""
    import numpy as np

    steps = calibration(report)
    if not any(s.flown and s.intervals for s in steps):
        return []
    rng = np.random.default_rng(seed)
    base = _diagnosed_config(report)
    out = []
    for _ in range(n):
        cfg, sample = base, {}
        for s in steps:
            if not s.flown:
                continue
            values = dict(s.params)
            for name, d in s.intervals.items():
                values[name] = float(rng.choice(np.asarray(d["values"], float), p=np.asarray(d["probabilities"])))
            updates = fx.REGISTRY[s.name].calibrate(values, cfg)
            cfg = cfg.replace(updates)
            sample.update(updates)
        out.append({k: _plain(v) for k, v in sample.items()})
    return out


#: the calibration-samples file beside calibrated.toml (``finkensim sweep``'s ``calibration = "sample"`` reads it)
SAMPLES_FILE = "calibration_samples.json"
SAMPLES_FORMAT = "finkensim-calibration-samples"


def calibrated_toml(report, correction_file: str | Path | None = None) -> str:
    """The calibrated config as TOML text: every key of every section, the keys an effect set commented
    (``correction_file``: the learned correction's table file, referenced by the ``correction_file`` key of each
    sensor it corrects, :data:`CORRECTION_KEYS`)."""
    import tomlkit

    cfg, steps = _walk(report, correction_file)
    v = report.verdict
    shrink = report.details.total_shrink
    doc = tomlkit.document()
    doc.add(tomlkit.comment("Calibrated by finkensim gap: the diagnosed config plus the selected effects at their "
                            "fitted parameters."))
    # a log split into training and held-out parts is one flight
    flights = dict.fromkeys(report.flights.get("train", []) + report.flights.get("heldout", []))
    doc.add(tomlkit.comment(f"flights: {', '.join(flights)}"))
    state = "unexplained" if v.get("unexplained") else ("no significant gap" if not v.get("significant_gap")
                                                       else "explained")
    doc.add(tomlkit.comment(f"verdict: {state}; the selected effects together remove {100 * shrink:.0f} % of the "
                            "held-out gap"))
    if v.get("unexplained") and steps:
        doc.add(tomlkit.comment("the verdict names no effect: the effects set below are the diagnosis's best partial "
                                "explanation, kept because the learned correction (if any) is fitted on top of them"))
    for s in steps:
        if not s.flown:
            doc.add(tomlkit.comment(f"NOT FLOWN: {s.name} ({_fmt_params(s.params)}) has no simulator counterpart yet"))
    if not steps:
        doc.add(tomlkit.comment("no effect was selected: this is the diagnosed config unchanged"))
    if any(s.intervals for s in steps):
        doc.add(tomlkit.comment(f"parameter intervals: block bootstrap of the training readings; {SAMPLES_FILE} "
                                "beside this file holds draws for finkensim sweep's calibration = \"sample\""))
    tables = correction_tables(report)
    for sensor in sorted(set(tables) - set(CORRECTION_KEYS)):
        doc.add(tomlkit.comment(f"NOT FLOWN: the learned correction of {sensor} (the simulator applies the "
                                f"tables of {', '.join(CORRECTION_KEYS)} only)"))
    corrected = {CORRECTION_KEYS[s]: s for s in _flown_tables(report)} if correction_file is not None else {}
    set_by = {key: s for s in steps for key in s.updates}
    data = cfg.to_dict()
    doc.add("profile", data.pop("profile"))
    for section, values in data.items():
        table = tomlkit.table()
        for key, value in values.items():
            item = tomlkit.item(_plain(value))  # an item, not the value: a bool read back from a table takes no comment
            s = set_by.get(f"{section}.{key}")
            if s is not None:
                alone = f"; alone it removes {100 * s.shrink_heldout:.0f} % of the held-out gap" \
                    if s.shrink_heldout == s.shrink_heldout else ""
                item.comment(f"set by {s.name} ({_fmt_params(s.params)}){alone}{_fmt_intervals(s.intervals)}")
            elif f"{section}.{key}" in corrected:
                item.comment(f"the learned correction of {corrected[f'{section}.{key}']} (residual quantiles on a "
                             "grid of the model median) of the unexplained gap")
            table.add(key, item)
        doc.add(section, table)
    return tomlkit.dumps(doc)


def write_calibrated(report, path: str | Path) -> Path:
    """Write :func:`calibrated_toml` to ``path`` atomically; returns the path. With a learned correction of a sensor
    the simulator flies (:data:`CORRECTION_KEYS`), its tables go beside it as ``correction.json``
    (:mod:`finkensim.sensors.correction_table`), referenced from the config by its absolute path."""
    from ...sensors.correction_table import write_correction

    path = Path(path)
    tables = correction_tables(report)
    corr = None
    if _flown_tables(report):
        corr = write_correction(path.with_name("correction.json"), tables,
                                {"flights": report.flights, "method": report.details.correction.method}).resolve()
    samples = calibration_samples(report)
    if samples:
        write_text_atomic(path.with_name(SAMPLES_FILE), json.dumps(
            {"format": SAMPLES_FORMAT, "version": 1, "samples": samples}, indent=1))
    write_text_atomic(path, calibrated_toml(report, corr))
    return path
