"""The diagnosis end to end: prepare the logs (:class:`~finkensim.gap.diagnosis.Diagnosis`: replay, tables, splits),
then detect, attribute and quantify (:func:`~finkensim.gap.attribute.selection.run_diagnosis`) — ``fs.diagnose``."""
from __future__ import annotations

from ..config import Config
from .diagnosis import Diagnosis
from .report.result import GapReport
from .attribute.selection import run_diagnosis

__all__ = ["diagnose"]


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
