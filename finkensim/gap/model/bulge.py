"""The ``wall_bulge`` effect's plate displacement: a target set by each plate's distance to the nearest copter body,
followed with a first-order response time. Its parameters are what a log shows (how far readings shorten, how close a
copter must come, how sharply the bulge ends, how slowly the curtain follows), not hinge height or altitude."""
from __future__ import annotations

import numpy as np
from numba import njit

from ...arena import bulge_law, wall_geometry
from ...world import walls_from_positions


def bulge_target(plate_distance: np.ndarray, amplitude: float, reach: float, shape: float = 2.0,
                 hinge: float = 0.0) -> np.ndarray:
    """The plates' target displacement (same shape as ``plate_distance``) m: ``amplitude · ((1 − hinge) ·
    exp(−(d/reach)^shape) + hinge · f(1 − d/reach) / f(1))``, with f the seed's polynomial amplitude law of the hinged
    walls (:func:`finkensim.arena.amplitude_law`, 0 for d ≥ reach: ``reach`` plays the hinge's threshold).

    hinge 0 (the default) is the ``wall_bulge`` effect's catalogue law, hinge 1 the law the project's own walls follow
    (a hinge driven toward ``maxAmplitude·f(x)``, x = (threshold − d)/threshold); the family in between is the
    flexible version a catch-all must beat before it is named beside a bulge (:mod:`finkensim.gap.attribute.parsimony`).

    Parameters
    ----------
    plate_distance : numpy.ndarray
        d, m: each plate's distance to the nearest copter body, any shape.
    amplitude : float
        Displacement (m) at d = 0.
    reach : float
        m > 0: the distance scale (the hinge law's threshold).
    shape : float
        > 0: the exponent of the catalogue law (2 a Gaussian).
    hinge : float
        In [0, 1]: the weight of the hinge law.

    Returns
    -------
    numpy.ndarray
        The target displacement, m, shaped like ``plate_distance``.
    """
    if not reach > 0:
        raise ValueError(f"bulge reach = {reach!r}: expected > 0 m")
    if not shape > 0:
        raise ValueError(f"bulge shape = {shape!r}: expected > 0")
    if not 0.0 <= hinge <= 1.0:
        raise ValueError(f"bulge hinge = {hinge!r}: expected a weight in [0, 1]")
    return bulge_law(np.asarray(plate_distance, dtype=float), amplitude, reach, shape, hinge)


def bulge_displacement(plate_distance: np.ndarray, amplitude: float, reach: float, response: float = 0.0,
                       t: np.ndarray | None = None, shape: float = 2.0, hinge: float = 0.0) -> np.ndarray:
    """Displacement (T, S_p) m of each plate, plate_distance (T, S_p) m from the nearest copter body: the target
    ``amplitude · exp(−(d/reach)^shape)`` — the ``wall_bulge`` effect's form, set by what a log shows (how far
    readings shorten, how close a copter must come, how sharply the bulge ends, how slowly the curtain follows),
    not by hinge height or altitude. shape 2 is a Gaussian; a larger one a flat bulge that ends sharply near
    reach (a hinged plate driven toward a near-constant angle within a threshold distance looks like that). With
    ``response`` τ > 0 s the plates follow the target as a first-order lag on the log's times t (T,) s:
    x_k = x_{k−1} + (1 − exp(−Δt_k/τ))·(target_k − x_{k−1}), starting at rest on the first target (a curtain keeps
    bending after the copter has passed, as the hinge does). ``hinge`` in [0, 1] blends in the walls' own polynomial
    law (:func:`bulge_target`; 0, the default, is the catalogue's law alone)."""
    if amplitude == 0.0:
        return np.zeros_like(plate_distance)
    target = bulge_target(plate_distance, amplitude, reach, shape, hinge)
    if response == 0.0:
        return target
    if not response > 0 or t is None or t.shape[0] != target.shape[0]:
        raise ValueError(f"bulge response = {response!r}: expected >= 0 s with the log's times (T,)")
    alpha = -np.expm1(-np.diff(t) / response)
    target = np.ascontiguousarray(target, dtype=np.float64)
    return first_order_lag(target, np.ascontiguousarray(alpha), target)  # in place: one (T, S_p) array of a long log


@njit(cache=True)
def first_order_lag(target, alpha, out):
    """out (T, S): out[0] = target[0], out[k] = out[k−1] + alpha[k−1]·(target[k] − out[k−1]); alpha (T−1,).
    ``out`` may be ``target`` itself (each target[k] is read before out[k] is written); returns ``out``."""
    T, S = target.shape
    for s in range(S):
        out[0, s] = target[0, s]
    for k in range(1, T):
        a = alpha[k - 1]
        for s in range(S):
            out[k, s] = out[k - 1, s] + a * (target[k, s] - out[k - 1, s])
    return out


#: the parameters of the ``wall_bulge`` effect's hinge version (:mod:`finkensim.gap.attribute.hinge`), named as the
#: config keys ``walls.*`` that fly them: deg, m, m
HINGE_KEYS = ("max_amplitude_deg", "threshold", "hinge_height")


def as_hinge_walls(base, values: dict):
    """``base`` (a :class:`~finkensim.gap.model.params.ModelParams`) with its walls replaced by the simulator's hinge
    walls at ``values`` (:data:`HINGE_KEYS`): the plates follow the hinge driven by the logged copters (gain 1), no
    bulge on top. The ``wall_bulge`` effect's hinge version: a plate angle under a PID toward
    ``max_amplitude · f(x)`` within ``threshold``, against gravity, moving the surface by ``lever · sin θ``."""
    return base.with_(wall_gain=1.0, bulge_amplitude=0.0, bulge_hinge=0.0,
                      walls_hinge=tuple(float(values[k]) for k in HINGE_KEYS))


def hinge_replay(arena, pos, t, radius, walls_hinge):
    """(plate angles (T, S) rad, :class:`~finkensim.arena.WallGeometry`) of ``arena``'s walls as the simulator's
    hinge with ``walls_hinge`` = (max_amplitude_deg, threshold m, hinge_height m), the other hinge parameters
    ``arena``'s, driven by the copters at pos (T, N, 2) m, times t (T,) s, body radius m
    (:func:`~finkensim.world.walls_from_positions`); the lever is hinge_height − ``arena.altitude`` (≥ 0)."""
    amp, threshold, height = (float(v) for v in walls_hinge)
    hp = arena.hinge._replace(bending=True, max_amplitude=float(np.deg2rad(amp)), threshold=threshold)
    lever = max(0.0, height - arena.altitude)
    theta = np.empty((t.shape[0], arena.seg_a.shape[0]))
    dist = np.empty_like(theta)
    walls_from_positions(pos, t, arena.seg_a, arena.seg_b, radius, hp, lever, theta, dist)
    return theta, wall_geometry(arena)._replace(lever=lever)
