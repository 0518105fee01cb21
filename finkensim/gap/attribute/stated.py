"""What the logs state about a catch-all's quantity, and what a fit of it may claim beyond that.

A log's ``meta.tracking_sigma_xy`` / ``tracking_sigma_yaw`` (or the config's ``gap.tracking_sigma_*``, which override
them) state the tracking noise of its poses; the configured model already draws the poses with it. The ``pose_noise``
catch-all fits the total tracking noise: it may not go below what the logs state (the fit starts at the largest
stated value, so a flight is never given less noise than its log claims), and the report gives the *excess* beyond
the stated value, added in quadrature: σ_excess = √(σ² − σ_stated²). Whether that excess is real is the selection's
held-out test against the configured model, which has the stated noise already.
"""
from __future__ import annotations

import math

__all__ = ["STATED", "stated_floor", "stated_excess", "stated_fields"]

#: effect name → parameter name → the :class:`~finkensim.gap.model.replay.Flight` attribute holding what its log states
STATED = {"pose_noise": {"sigma_xy": "sigma_xy", "sigma_yaw": "sigma_yaw"}}


def stated_floor(flights, effect_name: str) -> dict[str, float]:
    """The lower bound of each parameter of ``effect_name`` that the logs state: the largest stated value over the
    flights (m, rad); empty when the effect re-fits nothing a log states or no log states anything (0).

    Parameters
    ----------
    flights : list of Flight
        The diagnosis's flights (:func:`~finkensim.gap.model.replay.prepare_flights`).
    effect_name : str
        A catalogued effect's name.

    Returns
    -------
    dict of str to float
        Parameter name → the largest stated value, only for values > 0.
    """
    out = {}
    for param, attr in STATED.get(effect_name, {}).items():
        v = max((float(getattr(f, attr)) for f in flights), default=0.0)
        if v > 0:
            out[param] = v
    return out


def stated_excess(values: dict, floor: dict) -> dict[str, float]:
    """The fitted values beyond the stated ones, in quadrature: √(max(0, v² − stated²)) per stated parameter.

    Parameters
    ----------
    values : dict
        The fitted parameter values (total noise, m or rad).
    floor : dict
        :func:`stated_floor` of the same effect.

    Returns
    -------
    dict of str to float
        Parameter name → the excess (same unit), for the parameters in ``floor``.
    """
    return {k: math.sqrt(max(0.0, float(values[k]) ** 2 - s ** 2)) for k, s in floor.items() if k in values}


def stated_fields(flights, effect_name: str, values: dict) -> dict:
    """The report's additions to an effect that re-fits what the logs state: ``{"stated": {...}, "excess": {...}}``
    (:func:`stated_floor`, :func:`stated_excess`), or {} when the logs state nothing it re-fits.

    Parameters
    ----------
    flights : list of Flight
        The diagnosis's flights.
    effect_name : str
        The effect's name.
    values : dict
        Its fitted values.

    Returns
    -------
    dict
        The keys to add to the effect's entry in the report (none, or ``stated`` and ``excess``).
    """
    floor = stated_floor(flights, effect_name)
    if not floor:
        return {}
    return {"stated": dict(floor), "excess": stated_excess(values, floor)}
