"""Tools for property-based tests of finkensim and of what users build on it.

    from finkensim.testing import assert_inside_arena, assert_no_overlap, assert_reproducible, assert_flightlog_valid
    from finkensim.testing import strategies as fst         # Hypothesis strategies (needs only hypothesis)

* :mod:`.strategies` — Hypothesis strategies generating only valid objects: configs, scenarios, world states,
  sensor models, flight logs, recordings, gap effects.
* assertions (:mod:`.assertions`) — invariant checks whose failure messages name the copter, step, values and
  what was expected.
* :mod:`.profiles` — the ``fast`` / ``thorough`` Hypothesis profiles (``FINKENSIM_HYPOTHESIS``).

* plug-in checkers (:mod:`finkensim.plugin_checkers`) — :func:`~finkensim.plugin_checkers.check_behaviour`,
  :func:`~finkensim.plugin_checkers.check_task` and :func:`~finkensim.plugin_checkers.check_effect`;
  :func:`finkensim.determinism.check_determinism` is the checker of a configuration.

Importing this package loads neither Hypothesis nor pytest: ``strategies`` and ``profiles`` are imported on first
use, so the assertions work without the test extras.
"""
from __future__ import annotations

from ..lazy import lazy_exports
from ..plugin_checkers import PluginError, check_behaviour, check_effect, check_task
from .assertions import assert_flightlog_valid, assert_inside_arena, assert_no_overlap, assert_reproducible

__all__ = ["assert_inside_arena", "assert_no_overlap", "assert_reproducible", "assert_flightlog_valid",
           "check_behaviour", "check_effect", "check_task", "PluginError", "strategies", "profiles"]

__getattr__, __dir__ = lazy_exports(__name__, {}, ("strategies", "profiles"))
