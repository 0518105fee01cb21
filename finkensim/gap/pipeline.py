"""The diagnosis end to end (``fs.diagnose``): prepare the logs (:class:`~finkensim.gap.diagnosis.Diagnosis`: replay,
tables, splits), then :func:`run_diagnosis`, one named step per stage — detect (:mod:`.detect`), attribute
(:mod:`.attribute`), quantify (:mod:`.quantify`), report (:mod:`.report`)."""
from __future__ import annotations

import time

from ..config import Config
from .attribute.joint import join_second, pair_lead, pair_when_unexplained, refit_jointly, swap_second
from .attribute.hinge import refit_as_hinge
from .attribute.selection import Selection, candidates, first_round, keep_earned, select_greedy
from .attribute.targeted import apply_targeted
from .detect.significance import detect_gap
from .diagnosis import Diagnosis
from .quantify.verdict import correct, quantify
from .report.assemble import assemble_report
from .report.result import GapReport

__all__ = ["diagnose", "run_diagnosis"]


def diagnose(logs, names, cfg: Config | None = None, heldout=None, progress=None, effect_names=None,
             limits: str = "config") -> GapReport:
    """Diagnose the sim-to-real gap of flight logs against the simulator configured by ``cfg``.

    Parameters
    ----------
    logs : list of FlightLog
        The flights (:class:`~finkensim.flightlog.FlightLog`; geometry is taken from each log).
    names : list of str
        One name per log (file names), used in the report.
    cfg : Config, optional
        The simulator's configuration (default: the defaults): error models, wall model, ``[gap]`` settings.
    heldout : list of str, optional
        Names of the held-out flights (default: every other flight; a single flight is split in halves).
    progress : callable, optional
        ``progress(message)``, told what the diagnosis is doing.
    effect_names : list of str, optional
        The candidate effects (default ``cfg.gap.effects``, else the whole catalogue).
    limits : {"config", "from-log"}
        "config": readings beyond a sensor's configured ``max_range`` are a named error; "from-log": such limits
        are raised to the logs' largest reading (:mod:`.limits`).

    Returns
    -------
    GapReport
        The report (:class:`~finkensim.gap.report.result.GapReport`; ``.to_spec()`` is the JSON document,
        ``.write(out)`` writes it with report.md and the figures).

    Raises
    ------
    GapInputError
        No logs, logs without sensor readings or with too few samples, unknown held-out flights or effects.
    """
    cfg = Config() if cfg is None else cfg
    diag = Diagnosis(logs, names, cfg, heldout=heldout, progress=progress, limits=limits)
    report = run_diagnosis(diag, effect_names)
    if cfg.gap.param_intervals and report.details.added_params:
        from .quantify.intervals import parameter_intervals

        diag.say("  bootstrap intervals of the fitted parameters")
        report.details.param_intervals = parameter_intervals(diag, report.details.added_params, diag.seed)
    return report


def run_diagnosis(diag: Diagnosis, effect_names=None, max_added: int = 4, refit_top: int = 4,
                  with_correction: bool = True) -> GapReport:
    """Detect, attribute, quantify and report on a prepared :class:`~finkensim.gap.diagnosis.Diagnosis`.

    Parameters
    ----------
    diag : Diagnosis
        The prepared diagnosis (replayed flights, tables, splits).
    effect_names : list of str, optional
        The candidate effects (default ``gap.effects``, else the whole catalogue).
    max_added : int
        At most this many effects are selected.
    refit_top : int
        Each selection step refits on top of what was added every remaining effect on a sensor with a significant
        gap, and up to this many in all.
    with_correction : bool
        Fit the data-driven correction when the gap stays unexplained.

    Returns
    -------
    GapReport
        The report (``docs/formats/gap-report.md``).
    """
    t0 = time.perf_counter()
    cands = candidates(diag, effect_names)
    found = detect_gap(diag)  # detect: the configured model's gap per sensor, and where it lies
    first = first_round(diag, cands)  # attribute: every candidate fitted
    apply_targeted(diag, found, first)  # detect, with the fits: a gap the omnibus test missed
    sel = Selection.start(diag, found, first)
    select_greedy(sel, max_added, refit_top)
    for joint_step in (refit_jointly, swap_second, pair_when_unexplained, join_second, pair_lead):
        joint_step(sel)
    keep_earned(sel)  # parsimony: a catch-all stays only against a flexible refit of its structured neighbour
    refit_as_hinge(sel)  # the selected wall bulge as the simulator's hinge walls, kept when significantly better
    out = quantify(sel)  # quantify: waterfall, shrink, verdict
    correct(sel, out, with_correction)
    return assemble_report(sel, out, seconds=time.perf_counter() - t0)
