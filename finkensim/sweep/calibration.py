"""Calibration uncertainty in a sweep: ``calibration = "sample"`` draws each replicate's calibrated parameters.

``finkensim gap --out DIR`` writes ``DIR/calibrated.toml`` and, when the selected effects' parameters have bootstrap
distributions (:mod:`finkensim.gap.quantify.intervals`), ``DIR/calibration_samples.json``: draws of every key the
calibration set (format ``finkensim-calibration-samples``, version 1: ``{"samples": [{dotted key: value}, ...]}``).
A sweep whose ``[base] config`` is that ``calibrated.toml`` and whose top level says ``calibration = "sample"``
runs each replicate under one of those draws, chosen from (sweep seed, combination, replicate) alone, so a
headline metric's spread over the replicates includes what the calibration's own uncertainty causes. Keys the
sweep's ``[grid]``, ``[random]`` or variants set are left to them. ``calibration = "fixed"`` (the default) runs
every replicate at the fitted values.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .parsing import SweepError

__all__ = ["CALIBRATION_MODES", "SAMPLES_FILE", "read_samples", "samples_for_base", "sample_for"]

CALIBRATION_MODES = ("fixed", "sample")
SAMPLES_FILE = "calibration_samples.json"  # the name finkensim.gap.quantify.calibrate writes
SAMPLES_FORMAT = "finkensim-calibration-samples"


def read_samples(path: str | Path) -> list[dict[str, Any]]:
    """The calibration draws of ``path`` (a list of {dotted key: value}); a :class:`SweepError` naming the file and
    what is wrong otherwise."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise SweepError(f"calibration = 'sample': {str(path)!r} does not exist (finkensim gap --out writes it "
                         "beside calibrated.toml when the fitted parameters have intervals)") from None
    except (OSError, ValueError) as exc:
        raise SweepError(f"calibration = 'sample': {path}: not a readable JSON file ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != SAMPLES_FORMAT or data.get("version") != 1:
        got = (data.get("format"), data.get("version")) if isinstance(data, dict) else type(data).__name__
        raise SweepError(f"{path}: format, version = {got!r}: expected ({SAMPLES_FORMAT!r}, 1)")
    samples = data.get("samples")
    if not isinstance(samples, list) or not samples or not all(isinstance(s, dict) for s in samples):
        raise SweepError(f"{path}: samples: expected a non-empty list of tables of dotted config keys")
    return samples


def samples_for_base(mode, base_table, base_dir: Path) -> list[dict[str, Any]] | None:
    """The draws a sweep samples for ``calibration = mode`` (None for "fixed"): the samples file beside the
    ``[base] config`` file of ``base_table``."""
    if mode not in CALIBRATION_MODES:
        raise SweepError(f"calibration = {mode!r}: expected one of {', '.join(map(repr, CALIBRATION_MODES))}")
    if mode == "fixed":
        return None
    cfg = base_table.get("config") if isinstance(base_table, dict) else None
    if not isinstance(cfg, str) or not cfg:
        raise SweepError("calibration = 'sample' needs [base] config = the calibrated.toml of finkensim gap --out")
    path = Path(cfg) if Path(cfg).is_absolute() else Path(base_dir) / cfg
    return read_samples(path.with_name(SAMPLES_FILE))


def sample_for(samples: list[dict[str, Any]], seed: int, combination: int, replicate: int,
               swept=()) -> dict[str, Any]:
    """The draw of replicate ``replicate`` of ``combination`` (depends on the sweep seed and both indices only),
    without the keys in ``swept``."""
    i = int(np.random.default_rng([int(seed), 0xCA11B, int(combination), int(replicate)]).integers(len(samples)))
    return {k: v for k, v in samples[i].items() if k not in swept}
