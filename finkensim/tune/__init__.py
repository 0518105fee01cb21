"""Optuna studies over scenario parameters (needs the ``[tune]`` extra).

    from finkensim.tune import run_study, parse_study
    res = run_study("examples/tune.toml", out="out/tune")      # or: finkensim tune examples/tune.toml --out out/tune
    res.best, res.comparison

See :mod:`finkensim.tune.studyfile` for the study file and :mod:`finkensim.tune.run` for what is written.
"""
from __future__ import annotations

from .evaluate import compare, evaluate, mean_ci
from .run import StudyResult, run_study, select_best, storage_url
from .studyfile import Param, StudySpec, parse_study

__all__ = ["run_study", "parse_study", "StudySpec", "StudyResult", "Param", "evaluate", "compare", "mean_ci",
           "select_best", "storage_url"]
