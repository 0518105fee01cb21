"""What a parameter fit reads from a diagnosis: the objective it minimises and the replayed data it may use.

A fit (the generic one of :meth:`~finkensim.gap.diagnosis.Diagnosis.fit`, a catalogued effect's own ``fit``, a
user's) sees the diagnosis only through :class:`FitObjective`; a :class:`~finkensim.gap.diagnosis.Diagnosis` is
one. An effect's own fit is :data:`EffectFit`: ``fit(objective, effect, current, values) -> values``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Protocol, Sequence

if TYPE_CHECKING:
    import numpy as np

    from ..model.params import ModelParams
    from ..model.replay import Flight
    from .effects import Effect, Param

__all__ = ["FitObjective", "EffectFit"]


class FitObjective(Protocol):
    """The diagnosis as a fit sees it.

    Attributes
    ----------
    flights : list of Flight
        The replayed flights (:class:`~finkensim.gap.model.replay.Flight`: the log, its samples, geometry, ``dt``).
    tables : dict
        Sensor name → its table of readings (:mod:`finkensim.gap.model.predictive`); a sensor without readings
        has none.
    rows_fit : dict
        Sensor name → the training rows of its table, int array (n,): what a fit may look at.
    base : ModelParams
        The configured model.
    seed : int
        Seed of the predictive draws (common random numbers: every model is drawn with the same numbers).
    M : int
        Draws per reading.
    """

    flights: list[Flight]
    tables: dict[str, Any]
    rows_fit: dict[str, np.ndarray]
    base: ModelParams
    seed: int
    M: int

    def objective(self, effect: Any, current: ModelParams, sensors: Sequence[str], values: dict) -> float:
        """The training score of ``effect`` at ``values`` on top of ``current`` (lower is better).

        Parameters
        ----------
        effect : Effect
            Anything with ``apply(current, values) -> ModelParams``.
        current : ModelParams
            The model the effect is added to.
        sensors : sequence of str
            The sensors scored (a sensor without readings adds nothing).
        values : dict
            Parameter name → value.

        Returns
        -------
        float
            The sum over ``sensors`` of the mean normalised CRPS on their training rows.
        """

    def fit_group(self, effect: Effect, current: ModelParams, sensors: Sequence[str], vals: dict,
                  group: Sequence[Param]) -> dict:
        """The generic search over the parameters ``group`` of ``effect`` (the others fixed at ``values``).

        Parameters
        ----------
        effect : Effect
            The effect fitted.
        current : ModelParams
            The model it is added to.
        sensors : sequence of str
            The sensors scored.
        vals : dict
            Parameter name → starting value.
        group : sequence of Param
            The parameters searched together.

        Returns
        -------
        dict
            ``vals`` with the group's parameters at the best point found.
        """


#: an effect's own fit: ``fit(objective, effect, current, values) -> values`` (parameter name → fitted value)
EffectFit = Callable[["FitObjective", "Effect", "ModelParams", dict], dict]
