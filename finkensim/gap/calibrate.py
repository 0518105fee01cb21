"""A calibrated scenario out of a diagnosis: the diagnosed config plus every selected effect the simulator can fly.

The diagnosis names effects and fits their parameters against its predictive model; the simulator flies the same
effects through config keys (each catalogued :class:`~finkensim.gap.effects.Effect` with a ``calibrate`` mapping
says which). :func:`calibrated_config` applies the selected effects in the order the selection added them, each on
top of the config the previous ones produced (as the diagnosis applied them to its model), and
:func:`calibrated_toml` writes the result as a scenario file that ``finkensim run``, ``sweep`` and ``tune`` read as
it is, with a comment at each key an effect set (which effect, its fitted parameters, its held-out shrink).

A selected effect without a ``calibrate`` mapping is not flown by the simulator yet: the file lists it in its
header and :func:`calibration` marks it ``flown=False``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..atomic import write_text_atomic
from ..config import Config
from . import effects as fx

__all__ = ["CalibratedEffect", "calibration", "calibrated_config", "calibrated_toml", "correction_tables",
           "write_calibrated"]


@dataclass(frozen=True)
class CalibratedEffect:
    """One selected effect: its fitted ``params``, the config ``updates`` (dotted key → value) that fly it, whether
    the simulator flies it (``flown``), and its held-out shrink alone (``shrink_heldout``, NaN if unknown)."""

    name: str
    params: dict
    updates: dict
    flown: bool
    shrink_heldout: float


def _diagnosed_config(report) -> Config:
    cfg = report.details.config
    if not isinstance(cfg, Config):
        raise ValueError("this report does not carry the config it was diagnosed with (a report read back from "
                         "report.json has none): run the diagnosis (fs.diagnose or finkensim gap) to calibrate")
    return cfg


def _walk(report, correction_file: str | Path | None = None) -> tuple[Config, list[CalibratedEffect]]:
    cfg = _diagnosed_config(report)
    alone = {e["name"]: e.get("shrink_heldout", float("nan")) for e in report.effects}
    steps = []
    for name, params in report.details.added_params.items():
        effect = fx.REGISTRY.get(name)
        if effect is None or effect.calibrate is None:
            steps.append(CalibratedEffect(name, dict(params), {}, False, alone.get(name, float("nan"))))
            continue
        updates = effect.calibrate(params, cfg)
        cfg = cfg.replace(updates)
        steps.append(CalibratedEffect(name, dict(params), dict(updates), True, alone.get(name, float("nan"))))
    if correction_file is not None:
        cfg = cfg.replace({"sonar.correction_file": str(correction_file)})
    return cfg, steps


def correction_tables(report) -> dict:
    """The learned correction's tables of ``report`` (sensor → :class:`~finkensim.sensors.correction_table.
    CorrectionTable`; empty without a correction)."""
    corr = report.details.correction
    return dict(getattr(corr, "tables", None) or {})


def calibration(report) -> list[CalibratedEffect]:
    """The selected effects of ``report`` (a :class:`~finkensim.gap.result.GapReport` of this session), in the
    order the selection added them, with the config updates that fly each."""
    return _walk(report)[1]


def calibrated_config(report, correction_file: str | Path | None = None) -> Config:
    """The diagnosed config with every selected, flyable effect at its fitted parameters (and
    ``sonar.correction_file`` set to ``correction_file`` when given: :func:`write_calibrated` writes it)."""
    return _walk(report, correction_file)[0]


def _plain(v):
    """TOML-ready value: tuples (also nested) as lists."""
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


def _fmt_params(params: dict) -> str:
    return ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in params.items())


def calibrated_toml(report, correction_file: str | Path | None = None) -> str:
    """The calibrated config as TOML text: every key of every section, the keys an effect set commented
    (``correction_file``: the learned correction's table file, referenced as ``sonar.correction_file``)."""
    import tomlkit

    cfg, steps = _walk(report, correction_file)
    v = report.verdict
    shrink = report.details.total_shrink
    doc = tomlkit.document()
    doc.add(tomlkit.comment("Calibrated by finkensim gap: the diagnosed config plus the selected effects at their "
                            "fitted parameters."))
    doc.add(tomlkit.comment(f"flights: {', '.join(report.flights.get('train', []) + report.flights.get('heldout', []))}"))
    state = "unexplained" if v.get("unexplained") else ("no significant gap" if not v.get("significant_gap")
                                                       else "explained")
    doc.add(tomlkit.comment(f"verdict: {state}; the selected effects together remove {100 * shrink:.0f} % of the "
                            "held-out gap"))
    for s in steps:
        if not s.flown:
            doc.add(tomlkit.comment(f"NOT FLOWN: {s.name} ({_fmt_params(s.params)}) has no simulator counterpart yet"))
    if not steps:
        doc.add(tomlkit.comment("no effect was selected: this is the diagnosed config unchanged"))
    tables = correction_tables(report)
    for sensor in sorted(set(tables) - {"ultrasonic"}):
        doc.add(tomlkit.comment(f"NOT FLOWN: the learned correction of {sensor} (the simulator applies the "
                                "ultrasonic table only)"))
    set_by = {key: s for s in steps for key in s.updates}
    data = cfg.to_dict()
    doc.add("profile", data.pop("profile"))
    for section, values in data.items():
        table = tomlkit.table()
        for key, value in values.items():
            table.add(key, _plain(value))
            s = set_by.get(f"{section}.{key}")
            if s is not None:
                alone = f"; alone it removes {100 * s.shrink_heldout:.0f} % of the held-out gap" \
                    if s.shrink_heldout == s.shrink_heldout else ""
                table[key].comment(f"set by {s.name} ({_fmt_params(s.params)}){alone}")
            elif f"{section}.{key}" == "sonar.correction_file" and correction_file is not None:
                table[key].comment("the learned correction (residual quantiles on a grid of the model median) "
                                   "of the unexplained gap")
        doc.add(section, table)
    return tomlkit.dumps(doc)


def write_calibrated(report, path: str | Path) -> Path:
    """Write :func:`calibrated_toml` to ``path`` atomically; returns the path. With a learned correction of the
    sonars, its table goes beside it as ``correction.json`` (:mod:`finkensim.sensors.correction_table`),
    referenced from the config by its absolute path."""
    from ..sensors.correction_table import write_correction

    path = Path(path)
    tables = correction_tables(report)
    corr = None
    if "ultrasonic" in tables:
        corr = write_correction(path.with_name("correction.json"), tables,
                                {"flights": report.flights, "method": report.details.correction.method}).resolve()
    write_text_atomic(path, calibrated_toml(report, corr))
    return path
