"""Optuna studies over scenario parameters (needs the ``[tune]`` extra).

    from finkensim.tune import run_study, parse_study
    res = run_study("examples/tune.toml", out="out/tune")      # or: finkensim tune examples/tune.toml --out out/tune
    res.best, res.comparison

See :mod:`finkensim.tune.studyfile` for the study file and :mod:`finkensim.tune.run` for what is written.
"""
from __future__ import annotations

from ..lazy import lazy_exports

# each name is imported from its module on first use: `finkensim tune --help` and the other commands' argument
# parsing do not import numba and optuna
_EXPORTS = {"run_study": ".run", "parse_study": ".studyfile", "StudySpec": ".studyfile", "StudyResult": ".run",
            "Param": ".studyfile", "evaluate": ".evaluate", "compare": ".evaluate", "mean_ci": ".evaluate",
            "select_best": ".run", "storage_url": ".run"}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
