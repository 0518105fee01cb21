"""Arena rectangle and Bernoulli curtain walls.

Frame: origin at a corner, x along the width (3 m), y along the length (4 m), yaw CCW from +x.

Each of the four walls is a row of ``n_segments`` plates hanging from a horizontal hinge at
``hinge_height``. A copter closer than ``threshold`` to a plate pulls it into the arena
(Bernoulli: the rotor wash lowers the pressure on the arena side). The hinge angle θ (rad,
positive = lower edge swings into the arena) follows a damped second-order model::

    I θ'' = τ_motor − m g (L/2) sin θ,        I = m L² / 3     (rod hinged at one end)

    copter within threshold:  τ_motor = clip(P e + I_gain ∫e − D θ', ±joint_force),
                              e = θ_target − θ,  θ_target = max_amplitude · f(x),
                              x = (threshold − d) / threshold,
                              f(x) = 3.3 x³ − 7 x² + 4.8 x
    otherwise:                τ_motor = −friction · θ'   (motor off; integral reset)

d is the distance from the plate's rest line to the nearest copter body. The sensors see
the plate surface at flight height, displaced into the arena by ``lever · sin θ`` with
``lever = hinge_height − altitude``. A plate cannot swing through a copter: θ is capped where
that surface would touch the nearest body, lever · sin θ ≤ d.

Modelling choices (see docs/user-guide/walls.md): the report's 40 kg plate cannot hang at 30°
against a 15 N·m motor (it needs ≈ 98 N·m), so the default plate is a 0.3 kg curtain strip
and ``profile = "seed"`` keeps 40 kg. The report's friction "3" is applied as viscous
damping: as a Coulomb torque of 3 N·m it would hold a light plate at any angle forever.

Numerics: ``substeps`` semi-implicit Euler steps per world step; the gravity torque's sin θ is the
polynomial :func:`~finkensim.kernels.trig.sin_half_pi` (θ is stopped at ±π/2; error ≤ 2·10⁻¹⁵, a fifth of
libm's cost — this sine is the hinge's hottest operation).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .config import ArenaConfig, WallConfig
from .kernels.geometry import nearest_body_distance_env
from .kernels.trig import sin_fast_array, sin_half_pi

GRAVITY = 9.81  # m/s²


def amplitude_law(x):
    """f(x) = 3.3x³ − 7x² + 4.8x, the report's fit of plate amplitude vs closeness x ∈ [0, 1].

    f(0) = 0, f(0.5) = 1.0625, f(1) = 1.1. Multiply by the maximum amplitude for the angle.
    """
    x = np.asarray(x, dtype=float)
    return ((3.3 * x - 7.0) * x + 4.8) * x


@njit(cache=True, inline="always")
def _amplitude_law(x):
    return ((3.3 * x - 7.0) * x + 4.8) * x


@njit(cache=True, inline="always")
def target_angle(d, threshold, max_amplitude):
    """Target hinge angle (rad) for nearest-body distance d (m); 0 at or beyond the threshold."""
    if d >= threshold:
        return 0.0
    x = (threshold - d) / threshold
    return max_amplitude * _amplitude_law(x)


def target_angles(d, threshold=1.0, max_amplitude=np.deg2rad(30.0)):
    """Vectorised :func:`target_angle`: d (...) m → (...) rad."""
    d = np.asarray(d, dtype=float)
    x = np.clip((threshold - d) / threshold, 0.0, None)
    return np.where(d >= threshold, 0.0, max_amplitude * amplitude_law(x))


class HingeParams(NamedTuple):
    """Scalars of the hinge model in SI units (angles in rad), as passed to the kernels."""

    bending: bool
    threshold: float
    max_amplitude: float
    p: float
    i: float
    d: float
    joint_force: float
    friction: float
    inertia: float  # kg m²
    gravity_torque: float  # m g L/2, N m (times sin θ)
    substeps: int
    # the curtain bulge (walls.model "bulge" / "hinge+bulge"; amplitude 0: none): see bulge_step_env
    bulge_amplitude: float = 0.0  # m
    bulge_reach: float = 0.3  # m
    bulge_shape: float = 2.0
    bulge_response: float = 0.0  # s
    bulge_cutoff: float = 0.0  # m, beyond it the bulge target is 0 in float64 (0 without a bulge)
    bulge_hinge: float = 0.0  # the hinge law's weight in the bulge's target, [0, 1] (walls.bulge_hinge)


@njit(cache=True, inline="always")
def hinge_substeps(theta, omega, integ, target, active, hp, dt):
    """Advance one plate by one world step ``dt`` in ``hp.substeps`` semi-implicit Euler substeps.

    Returns the new (theta, omega, integ). ``active`` is True while a copter is within threshold.
    """
    if not hp.bending:
        return 0.0, 0.0, 0.0
    h = dt / hp.substeps
    if not active:
        integ = 0.0
    for _ in range(hp.substeps):
        if active:
            e = target - theta
            integ += e * h
            # anti-windup: the integral alone never asks for more than the motor can give
            if hp.i > 0.0:
                lim = hp.joint_force / hp.i
                integ = min(lim, max(-lim, integ))
            tau = hp.p * e + hp.i * integ - hp.d * omega
            tau = min(hp.joint_force, max(-hp.joint_force, tau))
            acc = (tau - hp.gravity_torque * sin_half_pi(theta)) / hp.inertia
            omega += acc * h
        else:
            # viscous friction integrated implicitly: stable for any friction / inertia ratio
            omega = (omega - hp.gravity_torque * sin_half_pi(theta) / hp.inertia * h) / (1.0 + hp.friction / hp.inertia * h)
        theta += omega * h
        if theta > 0.5 * np.pi:
            theta = 0.5 * np.pi
            omega = min(omega, 0.0)
        elif theta < -0.5 * np.pi:
            theta = -0.5 * np.pi
            omega = max(omega, 0.0)
    return theta, omega, integ


@njit(cache=True, inline="always")
def _advance_stopped(th, om, h, half_pi):
    """(θ + ω·h, ω) with θ stopped at ±π/2 (the plate lies flat): ω is then cut to what moves it back."""
    th += om * h
    if th > half_pi:
        th = half_pi
        om = min(om, 0.0)
    elif th < -half_pi:
        th = -half_pi
        om = max(om, 0.0)
    return th, om


@njit(cache=True, inline="always")
def contact_angle(d, lever):
    """Largest angle (rad) at which the plate surface at flight height (moved lever·sin θ inward)
    still clears a copter body d (m) away from the rest line: asin(min(1, d / lever))."""
    if lever <= 0.0 or d >= lever:
        return 0.5 * np.pi
    return np.arcsin(d / lever)


@njit(cache=True, inline="always")
def walls_step_env(theta, omega, integ, dist, hp, lever, dt):
    """One environment: update every plate (S,) in place from nearest-body distances ``dist`` (S,) m.

    A curtain cannot swing through a copter: the angle is capped at :func:`contact_angle`, and
    a plate stopped there loses its inward angular velocity.

    Same arithmetic as :func:`hinge_substeps` followed by the cap, plate by plate (bit-identical;
    ``tests/test_arena.py`` compares), but with the substep loop outside the plate loop: each plate
    is a serial chain of ``substeps`` dependent updates (a sine each), and interleaving the plates lets
    the CPU overlap the chains. Plates are split into motor-on and motor-off lists so the inner loops
    do not branch. A plate exactly at rest (θ = ω = +0.0) with the motor off stays exactly at rest under
    the friction update — ω ← (+0 − g·sin(+0)/I·h) / (1 + f/I·h) = +0 and θ ← +0 + (+0)·h = +0, the
    cap (≥ 0) never binds — so it is skipped when the parameters keep those signs (g ≥ 0, I > 0,
    h > 0, 1 + f/I·h > 0, all finite) and the distance is ≥ 0 (cap ≥ 0).
    """
    S = theta.shape[0]
    if not hp.bending:
        for s in range(S):
            theta[s] = 0.0
            omega[s] = 0.0
            integ[s] = 0.0
            cap = contact_angle(dist[s], lever)
            if theta[s] > cap:  # never (cap >= 0); kept so the result equals hinge_substeps + cap exactly
                theta[s] = cap
                omega[s] = min(omega[s], 0.0)
        return
    h = dt / hp.substeps
    half_pi = 0.5 * np.pi
    fric = 1.0 + hp.friction / hp.inertia * h
    rest_ok = (np.isfinite(hp.gravity_torque) and hp.gravity_torque >= 0.0 and np.isfinite(hp.inertia)
               and hp.inertia > 0.0 and np.isfinite(h) and h > 0.0 and np.isfinite(fric) and fric > 0.0)
    # order[:n_on] motor-on plates, order[n_on:n_on + n_off] motor-off plates that move; tg_a[q] the target of
    # motor-on plate order[q]
    order = np.empty(S, dtype=np.int64)
    tg_a = np.empty(S)
    n_on = 0
    for s in range(S):
        if dist[s] < hp.threshold:
            tg_a[n_on] = target_angle(dist[s], hp.threshold, hp.max_amplitude)
            order[n_on] = s
            n_on += 1
    n_off = 0
    for s in range(S):
        if not (dist[s] < hp.threshold):
            integ[s] = 0.0
            if (rest_ok and dist[s] >= 0.0 and theta[s] == 0.0 and omega[s] == 0.0 and math.copysign(1.0, theta[s]) > 0.0
                    and math.copysign(1.0, omega[s]) > 0.0):
                continue  # exactly at rest and stays so (see above)
            order[n_on + n_off] = s
            n_off += 1
    jf = hp.joint_force
    if hp.i > 0.0:
        lim = hp.joint_force / hp.i
    else:
        lim = 0.0
    # the moving plates' state gathered into contiguous arrays: the substep loops then run without indirection
    n_mov = n_on + n_off
    th_a = np.empty(n_mov)
    om_a = np.empty(n_mov)
    ig_a = np.empty(n_on)
    for q in range(n_mov):
        s = order[q]
        th_a[q] = theta[s]
        om_a[q] = omega[s]
        if q < n_on:
            ig_a[q] = integ[s]
    use_i = hp.i > 0.0
    p_gain = hp.p
    i_gain = hp.i
    d_gain = hp.d
    g_t = hp.gravity_torque
    inertia = hp.inertia
    for _ in range(hp.substeps):
        for q in range(n_on):
            th = th_a[q]
            om = om_a[q]
            e = tg_a[q] - th
            ig = ig_a[q] + e * h
            # anti-windup: the integral alone never asks for more than the motor can give
            if use_i:
                ig = min(lim, max(-lim, ig))
            tau = p_gain * e + i_gain * ig - d_gain * om
            tau = min(jf, max(-jf, tau))
            acc = (tau - g_t * sin_half_pi(th)) / inertia
            om += acc * h
            th_a[q], om_a[q] = _advance_stopped(th, om, h, half_pi)
            ig_a[q] = ig
        for q in range(n_on, n_mov):
            th = th_a[q]
            # viscous friction integrated implicitly: stable for any friction / inertia ratio
            om = (om_a[q] - g_t * sin_half_pi(th) / inertia * h) / fric
            th_a[q], om_a[q] = _advance_stopped(th, om, h, half_pi)
    for q in range(n_mov):  # scatter back, then the contact cap
        s = order[q]
        theta[s] = th_a[q]
        omega[s] = om_a[q]
        if q < n_on:
            integ[s] = ig_a[q]
        cap = contact_angle(dist[s], lever)
        if theta[s] > cap:
            theta[s] = cap
            omega[s] = min(omega[s], 0.0)


def bulge_cutoff(reach: float, shape: float) -> float:
    """The distance (m) beyond which the bulge target ``exp(−(d/reach)^shape)`` is below 1e-300 (0 for the
    simulator: the world step measures plate distances up to it only)."""
    return float(reach * (300.0 * np.log(10.0)) ** (1.0 / shape))


def bulge_law(d, amplitude, reach, shape, hinge):
    """The curtain bulge's target displacement (m, toward the arena) of plates d m from the nearest copter body:
    ``amplitude · ((1 − hinge)·exp(−(d/reach)^shape) + hinge·f(x)/f(1))``, x = clip(1 − d/reach, 0, 1) and f the
    walls' own polynomial amplitude law (:func:`amplitude_law`; 0 beyond ``reach``, which plays the hinge's threshold).
    shape 2 is a Gaussian, larger a flat bulge that ends sharply near reach; hinge 0 the exponential law alone.

    The one law of the simulator's bulge (compiled as :func:`bulge_target`, d a float) and of the gap effect
    ``wall_bulge`` and its flexible refit (:func:`finkensim.gap.model.bulge.bulge_target`, d an array).

    Parameters
    ----------
    d : float or numpy.ndarray
        m, each plate's distance to the nearest copter body.
    amplitude : float
        m, the displacement at d = 0.
    reach : float
        m > 0, the distance scale.
    shape : float
        > 0, the exponent of the exponential law.
    hinge : float
        In [0, 1], the weight of the hinge law.

    Returns
    -------
    float or numpy.ndarray
        m, the target displacement, shaped like ``d``.
    """
    target = amplitude * np.exp(-(d / reach) ** shape)
    if hinge == 0.0:
        return target
    x = np.minimum(np.maximum(1.0 - d / reach, 0.0), 1.0)
    return (1.0 - hinge) * target + hinge * amplitude * _amplitude_law(x) / _amplitude_law(1.0)


#: :func:`bulge_law` compiled for one plate (d a float; numba kernels inline it)
bulge_target = njit(cache=True, inline="always", error_model="numpy")(bulge_law)


@njit(cache=True, inline="always", error_model="numpy")
def bulge_alpha(dt, response):
    """The first-order response's step factor ``1 − exp(−dt/response)`` over dt s (1 for response 0: at once)."""
    return 1.0 if response <= 0.0 else -np.expm1(-dt / response)


@njit(cache=True, inline="always", error_model="numpy")
def bulge_step_env(bulge, dist, hp, dt, first):
    """Advance the plates' bulge (S,) m in place to the nearest-body distances dist (S,) m: at once to the target
    when ``first`` (at rest on it, as the diagnosis starts), else ``x += alpha·(target − x)`` with
    :func:`bulge_alpha` (the curtain keeps bending after the copter passed). ``hp``: a :class:`HingeParams`."""
    alpha = 1.0 if first else bulge_alpha(dt, hp.bulge_response)
    for s in range(bulge.shape[0]):
        target = bulge_target(dist[s], hp.bulge_amplitude, hp.bulge_reach, hp.bulge_shape, hp.bulge_hinge)
        bulge[s] = target if first else bulge[s] + alpha * (target - bulge[s])


def initial_bulge(geo, hp, pos: np.ndarray, radius: float) -> np.ndarray:
    """(B, S) m: each plate of ``geo`` (a :class:`WallGeometry`) at rest on its bulge target for copter centres
    pos (B, N, 2) m of body radius m; (B, 0) when ``hp`` (a :class:`HingeParams`) has no bulge."""
    out = np.zeros((pos.shape[0], geo.seg_a.shape[0] if hp.bulge_cutoff > 0.0 else 0))
    for b in range(out.shape[0] if out.shape[1] else 0):
        d = np.empty(out.shape[1])
        nearest_body_distance_env(geo.seg_a, geo.seg_b, np.ascontiguousarray(pos[b]), float(radius), d)
        bulge_step_env(out[b], d, hp, 0.0, True)
    return out


@njit(cache=True, inline="always")
def shift_plates_env(shift, normal, pa, pb):
    """Move each plate's ends pa, pb (S, 2) m in place by shift (S,) m along its inward normal (S, 2) (the bulge
    on top of the hinge's displacement; the gap replay shifts the same way)."""
    for p in range(shift.shape[0]):
        pa[p, 0] += shift[p] * normal[p, 0]
        pa[p, 1] += shift[p] * normal[p, 1]
        pb[p, 0] += shift[p] * normal[p, 0]
        pb[p, 1] += shift[p] * normal[p, 1]


@njit(cache=True, parallel=True)
def walls_step(theta, omega, integ, dist, hp, lever, dt):
    """Batched hinge update in place. theta, omega, integ, dist: (B, S); lever (m) as in :class:`Arena`."""
    for b in prange(theta.shape[0]):
        walls_step_env(theta[b], omega[b], integ[b], dist[b], hp, lever, dt)


@dataclass(frozen=True)
class Arena:
    """Static wall geometry plus hinge parameters, derived from the config.

    Plates are ordered wall by wall: south (y = 0, x increasing), east (x = W), north (y = L),
    west (x = 0), each with ``n_segments`` plates, S = 4 · n_segments in all.

    Attributes (arrays, m):
        width, length, altitude: arena size and flight height.
        seg_a, seg_b (S, 2): each segment's full-pitch rest line at flight height (for distances).
        plate_a, plate_b (S, 2): the plate's own width (fraction of the pitch), centred in its pitch.
        normal (S, 2): unit inward normal of each plate's wall.
        wall_index (S,): 0 south, 1 east, 2 north, 3 west.
        lever: hinge height − altitude (m); the surface at flight height moves lever · sin θ inward.
        hinge: :class:`HingeParams`.
    """

    width: float
    length: float
    altitude: float
    seg_a: np.ndarray
    seg_b: np.ndarray
    plate_a: np.ndarray
    plate_b: np.ndarray
    normal: np.ndarray
    wall_index: np.ndarray
    lever: float
    hinge: HingeParams

    @classmethod
    def from_config(cls, arena: ArenaConfig, walls: WallConfig) -> "Arena":
        W, L, n = arena.width, arena.length, walls.n_segments
        corners = [((0.0, 0.0), (W, 0.0)), ((W, 0.0), (W, L)), ((W, L), (0.0, L)), ((0.0, L), (0.0, 0.0))]
        normals = [(0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (1.0, 0.0)]
        seg_a, seg_b, plate_a, plate_b, nrm, widx = [], [], [], [], [], []
        frac = walls.plate_width_fraction
        for w, ((x0, y0), (x1, y1)) in enumerate(corners):
            for k in range(n):
                a = np.array([x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n])
                b = np.array([x0 + (x1 - x0) * (k + 1) / n, y0 + (y1 - y0) * (k + 1) / n])
                mid, half = 0.5 * (a + b), 0.5 * (b - a) * frac
                seg_a.append(a)
                seg_b.append(b)
                plate_a.append(mid - half)
                plate_b.append(mid + half)
                nrm.append(normals[w])
                widx.append(w)
        m, Lp = walls.plate_mass, walls.plate_length
        hinge_on = walls.model in ("hinge", "hinge+bulge")
        bulge = walls.bending and walls.model in ("bulge", "hinge+bulge") and walls.bulge_amplitude != 0.0
        hinge = HingeParams(
            bending=bool(walls.bending and hinge_on),
            threshold=walls.threshold,
            max_amplitude=np.deg2rad(walls.max_amplitude_deg),
            p=walls.pid_p,
            i=walls.pid_i,
            d=walls.pid_d,
            joint_force=walls.joint_force,
            friction=walls.friction,
            inertia=m * Lp * Lp / 3.0,
            gravity_torque=m * GRAVITY * Lp / 2.0,
            substeps=walls.substeps,
            bulge_amplitude=walls.bulge_amplitude if bulge else 0.0,
            bulge_reach=walls.bulge_reach,
            bulge_shape=walls.bulge_shape,
            bulge_response=walls.bulge_response,
            bulge_cutoff=bulge_cutoff(walls.bulge_reach, walls.bulge_shape) if bulge else 0.0,
            bulge_hinge=walls.bulge_hinge,
        )
        arr = lambda v: np.ascontiguousarray(np.array(v, dtype=float))  # noqa: E731
        return cls(
            width=W, length=L, altitude=arena.altitude,
            seg_a=arr(seg_a), seg_b=arr(seg_b), plate_a=arr(plate_a), plate_b=arr(plate_b),
            normal=arr(nrm), wall_index=np.array(widx, dtype=np.int64),
            lever=max(0.0, walls.hinge_height - arena.altitude), hinge=hinge,
        )

    @property
    def n_plates(self) -> int:
        return self.seg_a.shape[0]

    def displacement(self, theta):
        """Inward displacement (m) of each plate surface at flight height: lever · sin θ. (..., S) → (..., S).
        The sine of the sonar kernels (:func:`~finkensim.kernels.trig.sin_fast`)."""
        return self.lever * sin_fast_array(np.asarray(theta, dtype=np.float64))

    def plate_surfaces(self, theta):
        """Plate surfaces at flight height as line segments the sensors see.

        theta (B, S) rad → (a, b), each (B, S, 2) m: the plate (its own width) shifted along the
        inward normal by lever · sin θ.
        """
        shift = self.displacement(np.asarray(theta))[..., None] * self.normal
        return self.plate_a + shift, self.plate_b + shift

    def max_equilibrium_angle(self) -> float:
        """Largest angle (rad) the motor can hold against gravity: asin(joint_force / (m g L/2)), capped at π/2."""
        r = self.hinge.joint_force / self.hinge.gravity_torque
        return float(np.arcsin(min(1.0, r)))


class WallGeometry(NamedTuple):
    """The arena as the kernels see it (the world step, the sonar ray cast, the gap replay).

    seg_a, seg_b (S, 2) m: each plate's full-pitch rest line (for body distances); plate_a, plate_b
    (S, 2) m: the plate's own width; normal (S, 2): unit inward normals; lever m: hinge height −
    altitude; width, length m: the arena rectangle.
    """

    seg_a: np.ndarray
    seg_b: np.ndarray
    plate_a: np.ndarray
    plate_b: np.ndarray
    normal: np.ndarray
    lever: float
    width: float
    length: float


def wall_geometry(arena) -> WallGeometry:
    """:class:`WallGeometry` of an :class:`Arena` (a WallGeometry is returned as is)."""
    if isinstance(arena, WallGeometry):
        return arena
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    return WallGeometry(f(arena.seg_a), f(arena.seg_b), f(arena.plate_a), f(arena.plate_b), f(arena.normal),
                        float(arena.lever), float(arena.width), float(arena.length))
