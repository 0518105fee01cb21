"""One effect fitted and scored: :class:`FitResult`, what the attribution stage hands from step to step
(:meth:`~finkensim.gap.diagnosis.Diagnosis.fit` makes one, :meth:`~finkensim.gap.diagnosis.Diagnosis.score_heldout`
scores it; ``finkensim.gap.diagnosis.FitResult`` is the same class)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..model.params import ModelParams

__all__ = ["FitResult"]


@dataclass
class FitResult:
    """One effect fitted by :meth:`~finkensim.gap.diagnosis.Diagnosis.fit` and, once scored, by
    :meth:`~finkensim.gap.diagnosis.Diagnosis.score_heldout`.

    Scores and gaps are per reading, normalised by each sensor's scale and averaged over the sensors (lower
    is better); NaN until scored.

    Parameters
    ----------
    name : str
        The effect's name.
    values : dict
        Fitted parameter values (name → value, in the parameters' units).
    params : ModelParams
        The model with the effect added at ``values``.
    score_train : float
        Mean CRPS on the training rows (the fit's objective).
    score_heldout : float
        Mean CRPS on the held-out rows.
    gap_train : float
        Mean gap on the training rows.
    gap_heldout : float
        Mean gap on the held-out rows.
    rows_score : dict
        Sensor → per-row held-out CRPS, shape (n,).
    rows_gap : dict
        Sensor → per-row held-out gap, shape (n,).
    """

    name: str
    values: dict
    params: ModelParams
    score_train: float
    score_heldout: float = math.nan
    gap_train: float = math.nan
    gap_heldout: float = math.nan
    rows_score: dict = field(default_factory=dict, repr=False)  # sensor → per-row held-out score
    rows_gap: dict = field(default_factory=dict, repr=False)  # sensor → per-row held-out gap
