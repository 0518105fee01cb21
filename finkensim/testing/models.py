"""Hypothesis strategies for simulator objects built from a configuration: :func:`world_states` (a batched
state a :class:`~finkensim.world.World` accepts), :func:`sensor_models` (the sensor records the kernels fly) and
:func:`effects` (a catalogued gap effect with parameter values inside its declared bounds).

Ranges come from the objects' own declarations: the config (arena, copter radius and speed, plate count), the
effect's :class:`~finkensim.gap.attribute.effects.Param` bounds. Shrinking goes toward copters at rest in the arena's
lower-left region, plates hanging, and each effect's lower bounds.
"""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

__all__ = ["world_states", "sensor_models", "effects", "SENSOR_KINDS"]

PLATE_ANGLE_MAX = 1.5  # rad: plates drawn within +-86 deg (the world's own swing stays within +-90 deg)

SENSOR_KINDS = ("sonar", "ranging", "imu")
"""What :func:`sensor_models` builds: SonarModel, RangingModel, ImuModel."""


def sizes(value, lo: int, hi: int) -> st.SearchStrategy:
    """An int, a (low, high) pair or a strategy, as a strategy of ints in [lo, hi]."""
    if isinstance(value, st.SearchStrategy):
        return value
    if isinstance(value, tuple):
        return st.integers(max(lo, value[0]), min(hi, value[1]))
    return st.just(int(value))


def _unit(draw, shape) -> np.ndarray:
    """Floats in [0, 1] of ``shape`` (shrink toward 0)."""
    return draw(hnp.arrays(np.float64, shape, elements=st.floats(0.0, 1.0)))


def _separated(draw, frac: np.ndarray, lo: np.ndarray, hi: np.ndarray, min_distance: float) -> np.ndarray:
    """Positions lo + frac (hi - lo) (B, N, 2) m with every pair at least ``min_distance`` apart: a copter too
    close to an earlier one is placed on a grid cell of that spacing that no earlier copter is near."""
    pos = lo + frac * (hi - lo)
    B, N, _ = pos.shape
    if N < 2 or min_distance <= 0:
        return pos
    from hypothesis import assume

    extent = hi - lo
    spacing = np.maximum(min_distance, extent / (2 * N))  # at most (2 N + 1)^2 cells, each pair >= min_distance
    nx, ny = (np.floor(extent / spacing) + 1).astype(int)
    assume(nx * ny >= N)  # rare: the arena holds fewer copters on a grid than the config allows packed
    grid = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"), -1).reshape(-1, 2)
    cells = lo + spacing * grid
    for b in range(B):
        for i in range(1, N):
            d = np.sqrt(((pos[b, :i] - pos[b, i]) ** 2).sum(-1))
            if d.min() >= min_distance:
                continue
            free = [c for c in cells if np.sqrt(((pos[b, :i] - c) ** 2).sum(-1)).min() >= min_distance]
            assume(free)
            pos[b, i] = free[draw(st.integers(0, len(free) - 1))]
    return pos


@st.composite
def world_states(draw, cfg=None, *, n_envs=(1, 3), separated: bool = False, clearance: float = 0.0,
                 moving: bool = True, plates: bool = True, seed=st.integers(0, 2**63 - 1)):
    """A :class:`~finkensim.world.WorldState` for ``cfg`` (a Config; None = defaults): B = ``n_envs``
    environments (an int, a (low, high) pair or a strategy) of ``copters.n`` copters.

    Copter centres lie in [r, width − r] x [r, length − r] (where the world keeps them); with ``separated`` no
    two bodies overlap and ``clearance`` m lies between any two (centres ≥ 2 r + clearance apart). Yaw in
    [−π, π). With ``moving``, velocities within ``copters.max_speed`` (m/s) and yaw rates within
    ``copters.max_yaw_rate_deg``; with ``plates``, plate angles within ±1.5 rad, their rates within ±3 rad/s and
    PID integrals within ±8 rad s (else hanging still). Contact flags and counters start at 0 (the world
    recomputes them at the next step). Build worlds for random configs by drawing both::

        cfg = draw(fst.scenarios()); state = draw(fst.world_states(cfg))
    """
    from ..config import Config
    from ..world import World

    cfg = Config() if cfg is None else cfg
    world = World(cfg)
    B = draw(sizes(n_envs, 1, 10**6))
    N, S = cfg.copters.n, world.arena.n_plates
    r = cfg.copters.radius
    lo = np.array([r, r])
    hi = np.array([cfg.arena.width - r, cfg.arena.length - r])
    frac = _unit(draw, (B, N, 2))
    pos = _separated(draw, frac, lo, hi, 2 * r + clearance) if separated else lo + frac * (hi - lo)
    pos = np.clip(pos, lo, hi)  # rounding in lo + frac (hi - lo) must not leave [lo, hi]
    yaw = draw(hnp.arrays(np.float64, (B, N), elements=st.floats(-math.pi, math.pi, exclude_max=True)))
    state = world.init(n_envs=B, seed=draw(seed) if isinstance(seed, st.SearchStrategy) else int(seed),
                       positions=pos, yaw=yaw)
    if moving:
        v = cfg.copters.max_speed
        speed = v * _unit(draw, (B, N))
        heading = 2 * math.pi * _unit(draw, (B, N))
        vel = np.stack([speed * np.cos(heading), speed * np.sin(heading)], -1)
        w = math.radians(cfg.copters.max_yaw_rate_deg)
        state = state._replace(vel=vel, yaw_rate=draw(hnp.arrays(np.float64, (B, N), elements=st.floats(-w, w))))
    if plates:
        amp = PLATE_ANGLE_MAX
        state = state._replace(theta=draw(hnp.arrays(np.float64, (B, S), elements=st.floats(-amp, amp))),
                        omega=draw(hnp.arrays(np.float64, (B, S), elements=st.floats(-3.0, 3.0))),
                        integ=draw(hnp.arrays(np.float64, (B, S), elements=st.floats(-8.0, 8.0))))
    return state


@st.composite
def sensor_models(draw, kinds: Iterable[str] = SENSOR_KINDS, cfg=None):
    """A sensor record the kernels fly, built from a config as the simulator builds it: a
    :class:`~finkensim.sensors.sonar_model.SonarModel`, :class:`~finkensim.sensors.ranging.RangingModel` or
    :class:`~finkensim.sensors.imu.ImuModel` (one of ``kinds``), from ``cfg`` (a Config or a strategy of
    Configs; default: :func:`~finkensim.testing.configs.scenarios` varying that sensor's section)."""
    from ..sensors.imu import ImuModel
    from ..sensors.ranging import RangingModel
    from ..sensors.sonar_model import SonarModel
    from .configs import scenarios

    kinds = list(kinds)
    unknown = [k for k in kinds if k not in SENSOR_KINDS]
    if unknown or not kinds:
        raise ValueError(f"kinds = {kinds!r}: expected a non-empty subset of {SENSOR_KINDS}")
    kind = draw(st.sampled_from(kinds))
    if cfg is None:
        cfg = scenarios(sections=("arena", "copters", "simulation", kind), fixed={f"{kind}.enabled": True})
    c = draw(cfg) if isinstance(cfg, st.SearchStrategy) else cfg
    if kind == "sonar":
        return SonarModel.from_config(c)
    if kind == "ranging":
        return RangingModel.from_config(c.ranging)
    return ImuModel.from_config(c.imu, c.simulation.dt)


@st.composite
def effects(draw, names: Iterable[str] | None = None, sensors: Iterable[str] | None = None):
    """``(effect, values)``: a catalogued :class:`~finkensim.gap.attribute.effects.Effect` (from ``names``, default every
    registered one, optionally only those touching one of ``sensors``) and a value for each of its parameters
    inside the parameter's bounds (whole numbers for integer parameters). ``effect.apply(base, values)`` is then
    a valid model."""
    from ..gap.attribute.effects import REGISTRY

    pool = sorted(REGISTRY) if names is None else list(names)
    unknown = [n for n in pool if n not in REGISTRY]
    if unknown:
        raise ValueError(f"names: unknown effect(s) {unknown}; registered: {', '.join(sorted(REGISTRY))}")
    if sensors is not None:
        wanted = set(sensors)
        pool = [n for n in pool if wanted & set(REGISTRY[n].sensors)]
    if not pool:
        raise ValueError(f"no registered effect matches names = {names!r}, sensors = {sensors!r}")
    effect = REGISTRY[draw(st.sampled_from(pool))]
    values = {}
    for p in effect.params:
        if p.integer:
            values[p.name] = draw(st.integers(math.ceil(p.lo), math.floor(p.hi)))
        else:
            values[p.name] = draw(st.floats(p.lo, p.hi, allow_nan=False, allow_subnormal=False))
    return effect, values
