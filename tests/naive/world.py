"""Plain-NumPy reference of one world step (``finkensim.world.World.step``), for tests only.

Vectorised over environments and copters, written from the model equations in
``finkensim/copters.py`` and ``finkensim/arena.py`` (and docs/user-guide/walls.md). Parameters are
derived here from the :class:`~finkensim.config.Config` itself (degrees to radians, plate inertia,
gravity torque, wall segments), so the kernels' parameter conversion is checked too.

One step, in order:
  1. copters: command clipped to max_speed; first-order velocity lag; acceleration clipped to
     max_accel; semi-implicit Euler; centre clamped to [r, W - r] x [r, L - r] with the velocity
     component into the wall removed (a touch); yaw rate lag toward the clipped command; yaw wrapped.
  2. contacts: onsets of wall touches and of body overlaps (centre distance < 2 r) are counted.
  3. walls: d = distance from each plate's rest line to the nearest copter body; within threshold a
     PID (with anti-windup) drives theta toward max_amplitude * f(x); otherwise viscous friction
     (implicit); ``substeps`` semi-implicit Euler substeps; theta clamped to [-pi/2, pi/2].

What it shares and why: the discretisation (semi-implicit Euler, the anti-windup clip, the implicit friction step) is
the engine's numerical scheme, so this reference restates it and checks the compiled loops against it to rounding. Whether
that scheme solves the plate's ODE is checked apart from it: against scipy's ``solve_ivp`` on the ODE written from
DESIGN, with the engine's own substep-halving change as the error bound
(``tests/test_arena.py::test_hinge_matches_an_independent_ode_solution``).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from tests.naive.geometry import segment_copter_distances

GRAVITY = 9.81


def params(cfg):
    """SI parameters of the copter and wall models, from the config."""
    a, w, c = cfg.arena, cfg.walls, cfg.copters
    return SimpleNamespace(
        width=a.width, length=a.length, dt=cfg.simulation.dt,
        radius=c.radius, max_speed=c.max_speed, max_accel=c.max_accel, velocity_tau=c.velocity_tau,
        max_yaw_rate=math.radians(c.max_yaw_rate_deg), yaw_tau=c.yaw_tau,
        bending=w.bending, threshold=w.threshold, max_amplitude=math.radians(w.max_amplitude_deg),
        p=w.pid_p, i=w.pid_i, d=w.pid_d, joint_force=w.joint_force, friction=w.friction,
        inertia=w.plate_mass * w.plate_length**2 / 3.0,  # rod hinged at one end
        gravity_torque=w.plate_mass * GRAVITY * w.plate_length / 2.0,  # times sin(theta)
        substeps=w.substeps,
        lever=max(0.0, w.hinge_height - a.altitude),  # surface at flight height moves lever·sin(theta)
        release_gap=0.02,  # m, a wall contact ends once the body is this far from the wall
    )


def wall_segments(cfg):
    """Rest lines of the S = 4 n plates' pitches: south, east, north, west walls, each walked corner to corner."""
    W, L, n = cfg.arena.width, cfg.arena.length, cfg.walls.n_segments
    corners = [(0.0, 0.0), (W, 0.0), (W, L), (0.0, L), (0.0, 0.0)]
    a, b = [], []
    for (x0, y0), (x1, y1) in zip(corners[:-1], corners[1:]):
        for k in range(n):
            a.append((x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n))
            b.append((x0 + (x1 - x0) * (k + 1) / n, y0 + (y1 - y0) * (k + 1) / n))
    return np.array(a), np.array(b)


def lag_factor(tau, dt):
    """Fraction of the gap to the command closed in one step by a first-order lag (1 without lag)."""
    return 1.0 if tau <= 0.0 else 1.0 - math.exp(-dt / tau)


def scale_to_norm(v, limit):
    """Scale the 2-vectors v (..., 2) down so that |v| <= limit (unchanged when already inside)."""
    n = np.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2)
    factor = np.where(n > limit, limit / np.where(n > 0, n, 1.0), 1.0)
    return v * factor[..., None]


def move_copters(pos, vel, yaw, yaw_rate, cmd_v, cmd_w, p):
    """New (pos, vel, acc, yaw, yaw_rate, wall_gap) for all copters (B, N, ...).

    acc is the velocity change over dt including the stop at a wall; wall_gap (m) the body-to-wall distance.
    """
    dt = p.dt
    vel0 = vel
    cmd = scale_to_norm(cmd_v, p.max_speed)
    acc = scale_to_norm((cmd - vel) * lag_factor(p.velocity_tau, dt) / dt, p.max_accel)
    vel = vel + acc * dt
    pos = pos + vel * dt
    # wall clamp: centre at least one radius inside; the velocity component into the wall is lost
    r = p.radius
    lo = np.array([r, r])
    hi = np.array([p.width - r, p.length - r])
    below, above = pos < lo, pos > hi
    pos = np.clip(pos, lo, hi)
    vel = np.where(below, np.maximum(vel, 0.0), vel)
    vel = np.where(above, np.minimum(vel, 0.0), vel)
    acc = (vel - vel0) / dt
    wall_gap = np.maximum(0.0, np.minimum(np.minimum(pos[..., 0], p.width - pos[..., 0]),
                                          np.minimum(pos[..., 1], p.length - pos[..., 1])) - r)
    wall_gap = np.where(np.any(below | above, axis=-1), 0.0, wall_gap)  # clamped = touching, exactly
    w_cmd = np.clip(cmd_w, -p.max_yaw_rate, p.max_yaw_rate)
    yaw_rate = yaw_rate + (w_cmd - yaw_rate) * lag_factor(p.yaw_tau, dt)
    yaw = np.mod(yaw + yaw_rate * dt + np.pi, 2.0 * np.pi) - np.pi
    yaw = np.where(yaw >= np.pi, yaw - 2.0 * np.pi, yaw)
    return pos, vel, acc, yaw, yaw_rate, wall_gap


def overlapping(pos, radius):
    """(B, N) bool: the copter's body overlaps another's (centre distance < 2 r)."""
    diff = pos[:, :, None, :] - pos[:, None, :, :]
    d2 = np.sum(diff * diff, axis=-1)
    n = pos.shape[1]
    d2[:, np.arange(n), np.arange(n)] = np.inf  # not with itself
    return np.any(d2 < (2.0 * radius) ** 2, axis=-1)


def amplitude_law(x):
    return 3.3 * x**3 - 7.0 * x**2 + 4.8 * x


def hinge_step(theta, omega, integ, dist, p):
    """One world step of every plate (B, S) from nearest-body distances ``dist`` (B, S)."""
    if not p.bending:
        return np.zeros_like(theta), np.zeros_like(omega), np.zeros_like(integ)
    active = dist < p.threshold
    x = np.where(active, (p.threshold - dist) / p.threshold, 0.0)
    target = np.where(active, p.max_amplitude * amplitude_law(x), 0.0)
    integ = np.where(active, integ, 0.0)  # motor off: integral reset
    h = p.dt / p.substeps
    for _ in range(p.substeps):
        gravity = p.gravity_torque * np.sin(theta)
        # motor on: PID torque (integral clipped so it alone never exceeds the motor), torque limit
        e = target - theta
        integ_on = integ + e * h
        if p.i > 0.0:
            integ_on = np.clip(integ_on, -p.joint_force / p.i, p.joint_force / p.i)
        tau = np.clip(p.p * e + p.i * integ_on - p.d * omega, -p.joint_force, p.joint_force)
        omega_on = omega + (tau - gravity) / p.inertia * h
        # motor off: viscous friction, integrated implicitly
        omega_off = (omega - gravity / p.inertia * h) / (1.0 + p.friction / p.inertia * h)
        omega = np.where(active, omega_on, omega_off)
        integ = np.where(active, integ_on, integ)
        theta = theta + omega * h
        # the plate cannot swing past horizontal
        over, under = theta > 0.5 * np.pi, theta < -0.5 * np.pi
        theta = np.clip(theta, -0.5 * np.pi, 0.5 * np.pi)
        omega = np.where(over, np.minimum(omega, 0.0), np.where(under, np.maximum(omega, 0.0), omega))
    # a curtain cannot swing through a copter: lever·sin(theta) <= distance to the nearest body
    cap = np.where((p.lever > 0.0) & (dist < p.lever), np.arcsin(np.minimum(1.0, dist / max(p.lever, 1e-300))),
                   0.5 * np.pi)
    capped = theta > cap
    theta = np.where(capped, cap, theta)
    omega = np.where(capped, np.minimum(omega, 0.0), omega)
    return theta, omega, integ


def world_step(cfg, state, cmd_vel, cmd_yaw_rate=None):
    """The state after one step: a new :class:`~finkensim.world.WorldState` (input untouched)."""
    p = params(cfg)
    B, N = state.pos.shape[:2]
    cmd_v = np.broadcast_to(np.asarray(cmd_vel, dtype=float), (B, N, 2))
    cmd_w = np.zeros((B, N)) if cmd_yaw_rate is None else np.broadcast_to(np.asarray(cmd_yaw_rate, float), (B, N))
    pos, vel, acc, yaw, yaw_rate, wall_gap = move_copters(state.pos, state.vel, state.yaw, state.yaw_rate,
                                                          cmd_v, cmd_w, p)
    overlap = overlapping(pos, p.radius)
    touching = wall_gap <= 0.0
    wall_contacts = state.wall_contacts + (touching & ~state.in_wall)
    in_wall = np.where(touching, True, np.where(wall_gap > p.release_gap, False, state.in_wall))
    collisions = state.collisions + (overlap & ~state.in_collision)
    seg_a, seg_b = wall_segments(cfg)
    dist = segment_copter_distances(seg_a, seg_b, pos, p.radius)
    theta, omega, integ = hinge_step(state.theta, state.omega, state.integ, dist, p)
    return state._replace(
        pos=pos, vel=vel, acc=acc, yaw=yaw, yaw_rate=yaw_rate, theta=theta, omega=omega, integ=integ,
        in_wall=in_wall, in_collision=overlap, wall_contacts=wall_contacts, collisions=collisions,
        step=state.step + 1, env_ids=state.env_ids.copy(),
    )
