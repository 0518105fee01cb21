"""Sim-to-real gap diagnosis: where simulated sensor data disagrees with real flight logs, which unmodelled
effect explains it, and how far the gap shrinks once that effect is added.

``diagnose(logs, names, cfg)`` returns a :class:`GapReport`; :class:`Diagnosis` and :func:`run_diagnosis`
split preparation (replay, tables, scales) from the search, so a notebook can register its own effects
(:func:`finkensim.gap.attribute.effects.register`) and rerun the search on the same prepared data.
"""
from .diagnosis import Diagnosis, check_heldout
from .attribute.effects import Effect, Param, register
from .model.params import ModelParams
from .model.replay import GapInputError
from .report.result import GapDetails, GapReport
from .pipeline import diagnose, run_diagnosis
from .attribute.selection import check_effects

__all__ = ["diagnose", "run_diagnosis", "Diagnosis", "GapReport", "GapDetails", "ModelParams", "Effect", "Param",
           "register", "GapInputError", "check_heldout", "check_effects"]
