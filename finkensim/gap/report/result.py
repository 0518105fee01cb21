"""The result of a diagnosis: :class:`GapReport` (the spec's fields, ``docs/formats/gap-report.md``) with its
:class:`GapDetails` (what the Markdown report and the figures add for people).

``report.to_spec()`` is the JSON document of the spec, to the letter; ``report.write(out)`` writes it as
``report.json`` beside ``report.md`` and the figures. ``report["verdict"]`` etc. read the spec fields.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["SPEC_KEYS", "FORMAT", "GapDetails", "GapReport", "json_safe"]

FORMAT = "finkensim-gap-report/1"
SPEC_KEYS = ("format", "flights", "score", "gap_before", "locations", "effects", "verdict", "correction")


def json_safe(x):
    """JSON-safe copy: NaN/inf → None, NumPy scalars → Python, tuples → lists."""
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


@dataclass
class GapDetails:
    """What a diagnosis found beyond the spec's fields.

    gap_before_ci (2,), gap_before_p: block-bootstrap CI and p-value of ``gap_before`` itself (the held-out gap averaged over the sensors with a significant gap, or every sensor when none has one); score_before: mean
    held-out score of the configured model; per_sensor: sensor → {gap, ci, p, significant}; gap_sensors:
    the sensors with a significant gap; waterfall: the forward-selection steps ({step, effect, gap_heldout,
    ci, params}); added: the effects selected in order; total_shrink: 1 − gap after all added / gap before
    on the gap sensors; ties: effects within ``tie_tolerance`` of the best; significant_locations: indices
    into ``locations``; scales: sensor → score scale; sensors, n_readings: what was compared; seconds:
    wall time; block_seconds: bootstrap block length (s); catch_all: catch-all effects among the
    candidates; tie_tolerance, unexplained_shrink: the settings used; remaining: gap sensor → {gap, ci, p,
    significant}, the held-out gap left under the selected effects (two-sided test; a significant gap is
    'unexplained' only when the shrink is under ``unexplained_shrink`` and some remainder is significant); calibration_gap, calibration_ci: the
    held-out mean of E|X − y| − E|X − X'| (zero-mean when the logs could have come from the model; the
    significance test) and its CI; best_score: the best held-out score of any predictive built (the
    reference of the score term of the shrink, :mod:`~finkensim.gap.attribute.shrink`); censoring: sensor → {lo, hi, no_echo} of the threshold-weighted
    score; correction: the fitted :class:`~finkensim.gap.quantify.correction.Correction` or None; targeted: when the omnibus
    test found no gap but a structured effect's held-out improvement did (:func:`~finkensim.gap.pipeline.run_diagnosis`),
    {effect, sensors, improvement, ci, p, threshold, passed}, else None; correction_skipped: sensor (or "all") →
    why no correction was fitted although the verdict is unexplained; limit_notes: sensor → range limit taken from
    the logs (:mod:`~finkensim.gap.detect.limits`); sample_sizes: sensor → {heldout, train, blocks}; too_little_data:
    sensor → the "too little data to decide ..." sentence (:mod:`~finkensim.gap.detect.sufficiency`); residuals: per location
    (same order), the median of reading − model median in the sensor's unit (m for ultrasonic and ranging);
    at_bound: effect name → its fitted parameters at a bound of their range (:func:`~finkensim.gap.attribute.effects.at_bound`);
    added_params: effect → its fitted parameters in the final selection (after any joint refit); config: the
    diagnosed :class:`~finkensim.config.Config` (what :meth:`GapReport.calibrated_config` starts from);
    param_intervals: effect → parameter → its bootstrap distribution and interval
    (:func:`~finkensim.gap.quantify.intervals.parameter_intervals`; empty with ``gap.param_intervals = false``).
    """

    gap_before_ci: list = field(default_factory=lambda: [math.nan, math.nan])
    gap_before_p: float = math.nan
    score_before: float = math.nan
    per_sensor: dict = field(default_factory=dict)
    gap_sensors: list = field(default_factory=list)
    waterfall: list = field(default_factory=list)
    added: list = field(default_factory=list)
    total_shrink: float = 0.0
    ties: list = field(default_factory=list)
    significant_locations: list = field(default_factory=list)
    scales: dict = field(default_factory=dict)
    sensors: list = field(default_factory=list)
    n_readings: dict = field(default_factory=dict)
    seconds: float = math.nan
    block_seconds: float = math.nan
    catch_all: list = field(default_factory=list)
    tie_tolerance: float = 0.1
    unexplained_shrink: float = 0.7
    remaining: dict = field(default_factory=dict)
    calibration_gap: float = math.nan
    calibration_ci: list = field(default_factory=lambda: [math.nan, math.nan])
    best_score: float = math.nan
    censoring: dict = field(default_factory=dict)
    correction: object = None
    targeted: dict | None = None
    correction_skipped: dict = field(default_factory=dict)
    limit_notes: dict = field(default_factory=dict)
    sample_sizes: dict = field(default_factory=dict)
    too_little_data: dict = field(default_factory=dict)
    residuals: list = field(default_factory=list)
    at_bound: dict = field(default_factory=dict)
    added_params: dict = field(default_factory=dict)
    config: object = None
    param_intervals: dict = field(default_factory=dict)


@dataclass
class GapReport:
    """A sim-to-real gap report: the spec's fields (``docs/formats/gap-report.md``) and :class:`GapDetails`.

    ``report["verdict"]`` reads a spec field as in the JSON document; :meth:`to_spec` is that document.
    Gaps and scores are mean values per reading on the held-out flights (lower is better).

    Parameters
    ----------
    flights : dict
        ``{"train": [names], "heldout": [names]}``.
    score : str
        The discrepancy score's name (``"crps"``).
    gap_before : float
        Mean held-out gap of the configured model.
    locations : list of dict
        Ranked bins ``{sensor, channel, feature, low, high, gap, ci, n, significant}``, largest gap first.
    effects : list of dict
        Every candidate's fit ``{name, params, score_heldout, gap_after_train, gap_after_heldout,
        shrink_heldout}``, best held-out score first.
    verdict : dict
        ``{effect, effects, ambiguous, shrink_heldout, unexplained, significant_gap}``.
    correction : dict or None
        ``{sensor, features, shrink_heldout, method}`` when the gap is unexplained, else None.
    details : GapDetails
        Everything else the diagnosis measured (not part of the JSON document).
    format : str
        ``"finkensim-gap-report/1"``.
    """

    flights: dict
    score: str
    gap_before: float
    locations: list
    effects: list
    verdict: dict
    correction: dict | None = None
    details: GapDetails = field(default_factory=GapDetails)
    format: str = FORMAT

    def __getitem__(self, key: str):
        """The spec field ``key`` (``report["verdict"]``), as in the JSON document."""
        if key not in SPEC_KEYS:
            raise KeyError(f"{key!r} is not a gap-report field; fields: {', '.join(SPEC_KEYS)} (details: .details)")
        return getattr(self, key)

    def to_spec(self) -> dict:
        """The JSON document of ``docs/formats/gap-report.md``: exactly its keys, JSON-safe (non-finite → null).

        Returns
        -------
        dict
            The document (``correction`` only when there is one).
        """
        return json_safe({k: getattr(self, k) for k in SPEC_KEYS if k != "correction" or self.correction is not None})

    def to_json(self) -> str:
        """:meth:`to_spec` as JSON text (strict: no NaN).

        Returns
        -------
        str
            The JSON text, ending with a newline.
        """
        return json.dumps(self.to_spec(), indent=1, allow_nan=False) + "\n"

    def calibrated_config(self):
        """The diagnosed config plus every selected effect the simulator can fly, at its fitted parameters (a
        :class:`~finkensim.config.Config`; :func:`finkensim.gap.quantify.calibrate.calibration` says which effects are not
        flown yet)."""
        from ..quantify.calibrate import calibrated_config

        return calibrated_config(self)

    def write(self, out: str | Path, max_locations_md: int = 15) -> dict[str, Path]:
        """Write report.json, report.md, the figures and, when the diagnosed config is known, calibrated.toml
        (:mod:`finkensim.gap.quantify.calibrate`) into directory ``out``.

        Parameters
        ----------
        out : str or Path
            The directory (created if missing).
        max_locations_md : int
            How many locations report.md lists (report.json has them all).

        Returns
        -------
        dict of str to Path
            Every file written, by kind.
        """
        from ..quantify.calibrate import write_calibrated
        from .write import write_report

        paths = write_report(self, out, max_locations_md)
        if self.details.config is not None:
            paths["calibrated"] = write_calibrated(self, Path(out) / "calibrated.toml")
        return paths
