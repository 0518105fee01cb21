"""Kinematic copters at fixed altitude: commanded velocity and yaw rate with lag and limits.

Per copter and step (dt), with v the world-frame velocity (m/s) and ω the yaw rate (rad/s)::

    v_cmd  ← v_cmd scaled to |v_cmd| ≤ max_speed
    v_lag  = v + (v_cmd − v)(1 − exp(−dt/τ_v))          (first-order lag; τ_v = 0 → v_cmd)
    a      = (v_lag − v)/dt, scaled to |a| ≤ max_accel
    v     ← v + a dt;  p ← p + v dt                      (semi-implicit Euler)
    ω     ← same lag toward clip(ω_cmd, ±max_yaw_rate) with τ_ψ;  ψ ← wrap(ψ + ω dt)

A copter whose body would cross a wall is put back on the wall (centre at least one radius
inside) and loses its velocity component into the wall; the recorded acceleration includes that
stop. A wall contact is counted when the touch begins; it ends once the body is more than
``WALL_RELEASE_GAP`` (2 cm) away again. Two copters whose bodies overlap (centre distance < 2 radius) are in collision;
a collision is counted for each copter when its overlap begins. Overlaps are counted, not
resolved (the kinematic model has no contact forces).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .config import ArenaConfig, CopterConfig
from .kernels.cellgrid import any_within_env, build_env, grid_layout


class CopterParams(NamedTuple):
    """Scalars of the copter model in SI units, as passed to the kernels."""

    radius: float
    max_speed: float
    max_accel: float
    velocity_tau: float
    max_yaw_rate: float
    yaw_tau: float
    width: float
    length: float

    @classmethod
    def from_config(cls, copters: CopterConfig, arena: ArenaConfig) -> "CopterParams":
        return cls(
            radius=copters.radius,
            max_speed=copters.max_speed,
            max_accel=copters.max_accel,
            velocity_tau=copters.velocity_tau,
            max_yaw_rate=np.deg2rad(copters.max_yaw_rate_deg),
            yaw_tau=copters.yaw_tau,
            width=arena.width,
            length=arena.length,
        )


@njit(cache=True, inline="always")
def _lag_factor(tau, dt):
    return 1.0 if tau <= 0.0 else 1.0 - np.exp(-dt / tau)


@njit(cache=True, inline="always")
def wrap_angle(a):
    """Wrap an angle (rad) to [−π, π)."""
    x = a + np.pi
    two_pi = 2.0 * np.pi
    # the remainder of an x already in [0, 2π) is x itself (exactly): skip the call to fmod that numba's % makes
    w = (x if 0.0 <= x < two_pi else x % two_pi) - np.pi
    if w >= np.pi:  # the float remainder can round up to 2π for a + π just below 0
        w -= 2.0 * np.pi
    return w


@njit(cache=True, inline="always")
def move_copter(pos, vel, yaw, yaw_rate, acc, cmd_v, cmd_w, copter, dt):
    """Advance one copter in place. pos, vel, acc, cmd_v: (2,) arrays; yaw, yaw_rate, cmd_w: floats.

    Writes the world-frame acceleration of the step into ``acc`` (m/s²): the velocity change over
    dt including the stop at a wall, which an accelerometer would feel. Returns (yaw, yaw_rate,
    gap_to_wall) where gap_to_wall (m) is the smallest distance from the body to a wall (0 = touching).
    """
    v0x = vel[0]
    v0y = vel[1]
    cx, cy = cmd_v[0], cmd_v[1]
    speed = np.sqrt(cx * cx + cy * cy)
    if speed > copter.max_speed:
        cx *= copter.max_speed / speed
        cy *= copter.max_speed / speed
    k = _lag_factor(copter.velocity_tau, dt)
    ax = (cx - vel[0]) * k / dt
    ay = (cy - vel[1]) * k / dt
    an = np.sqrt(ax * ax + ay * ay)
    if an > copter.max_accel:
        ax *= copter.max_accel / an
        ay *= copter.max_accel / an
    vel[0] += ax * dt
    vel[1] += ay * dt
    pos[0] += vel[0] * dt
    pos[1] += vel[1] * dt
    r = copter.radius
    clamped = False
    if pos[0] < r:
        pos[0] = r
        vel[0] = max(vel[0], 0.0)
        clamped = True
    elif pos[0] > copter.width - r:
        pos[0] = copter.width - r
        vel[0] = min(vel[0], 0.0)
        clamped = True
    if pos[1] < r:
        pos[1] = r
        vel[1] = max(vel[1], 0.0)
        clamped = True
    elif pos[1] > copter.length - r:
        pos[1] = copter.length - r
        vel[1] = min(vel[1], 0.0)
        clamped = True
    acc[0] = (vel[0] - v0x) / dt
    acc[1] = (vel[1] - v0y) / dt
    # exactly 0 when clamped: W − (W − r) − r need not round to 0
    gap = 0.0 if clamped else min(min(pos[0], copter.width - pos[0]), min(pos[1], copter.length - pos[1])) - r
    w_cmd = min(copter.max_yaw_rate, max(-copter.max_yaw_rate, cmd_w))
    yaw_rate += (w_cmd - yaw_rate) * _lag_factor(copter.yaw_tau, dt)
    yaw = wrap_angle(yaw + yaw_rate * dt)
    return yaw, yaw_rate, max(0.0, gap)


# A wall contact begins when the body touches a wall and ends only once it is this far away again,
# so a copter sliding along a wall with a wobbling command counts one contact, not one per wobble.
WALL_RELEASE_GAP = 0.02  # m
"""Distance (m) from a wall at which a wall contact ends (see the comment above)."""


@njit(cache=True, inline="always")
def update_contacts_env(pos, radius, wall_gap, in_wall, wall_contacts, in_collision, collisions, grid, cells):
    """Count contact onsets for one environment (N copters) in place.

    wall_gap (N,) m: body-to-wall distance this step (0 = touching). A wall contact begins at
    gap 0 and ends when the gap exceeds :data:`WALL_RELEASE_GAP`. Updates in_wall/in_collision
    flags and increments wall_contacts/collisions (N,) where a contact begins. Two copters touch when their
    centres are closer than 2·radius. grid: a :class:`~finkensim.kernels.cellgrid.GridParams` (or a record with
    its fields, such as :class:`~finkensim.kernels.cellgrid.EngineGrid`); when on, the
    overlaps are found with the cell grid in ``cells`` = (cell_start, order, spos, cell_of) of this environment
    (rebuilt here), else by the brute force — the same test either way.
    """
    N = pos.shape[0]
    lim2 = (2.0 * radius) ** 2
    if grid.on:
        cell_start, order, spos, cell_of = cells[0], cells[1], cells[2], cells[3]
        build_env(pos, grid_layout(grid), cell_start, order, spos, cell_of)
    for i in range(N):
        overlap = False
        if grid.on:
            overlap = any_within_env(pos[i, 0], pos[i, 1], 2.0 * radius, i, grid_layout(grid), cell_start, order, spos)
        else:
            # every pair tested, no early exit: whether two copters touch is unpredictable near the walls
            for j in range(N):
                dx = pos[i, 0] - pos[j, 0]
                dy = pos[i, 1] - pos[j, 1]
                overlap = overlap | ((dx * dx + dy * dy < lim2) & (j != i))
        if overlap and not in_collision[i]:
            collisions[i] += 1
        in_collision[i] = overlap
        if wall_gap[i] <= 0.0:
            if not in_wall[i]:
                wall_contacts[i] += 1
            in_wall[i] = True
        elif wall_gap[i] > WALL_RELEASE_GAP:
            in_wall[i] = False
