"""Sim-to-real gap diagnosis: where simulated sensor data disagrees with real flight logs, which unmodelled
effect explains it, and how far the gap shrinks once that effect is added.

``diagnose(logs, names, cfg)`` returns a :class:`GapReport`; :class:`Diagnosis` and :func:`run_diagnosis`
split preparation (replay, tables, scales) from the search, so a notebook can register its own effects
(:func:`finkensim.gap.attribute.effects.register`) and rerun the search on the same prepared data.

The names are imported on first use, so ``finkensim.gap.model.inputs`` (the checks the command line makes before
reading a flight) loads without numba and scipy.
"""
from __future__ import annotations

from ..lazy import lazy_exports

_EXPORTS = {
    "diagnose": ".pipeline", "run_diagnosis": ".pipeline", "Diagnosis": ".diagnosis", "GapReport": ".report.result",
    "GapDetails": ".report.result", "ModelParams": ".model.params", "Effect": ".attribute.effects",
    "Param": ".attribute.effects", "register": ".attribute.effects", "GapInputError": ".model.inputs",
    "check_heldout": ".model.inputs", "check_effects": ".attribute.selection",
}
__all__ = ["diagnose", "run_diagnosis", "Diagnosis", "GapReport", "GapDetails", "ModelParams", "Effect", "Param",
           "register", "GapInputError", "check_heldout", "check_effects"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
