"""Determinism self-check of a simulator configuration (in the spirit of Gymnasium's ``check_env``).

:func:`check_determinism` verifies the reproducibility promise of :mod:`finkensim.world` and
:mod:`finkensim.swarm` (sensors and behaviours included): a result
depends on (seed, environment index, step, copter, sensor) only. It is cheap (a few batched rollouts)
and is meant to be run on any new config, controller or kernel::

    from finkensim.determinism import check_determinism
    check_determinism(load_config("scenario.toml"))        # raises AssertionError on a mismatch
"""
from __future__ import annotations

from dataclasses import fields, is_dataclass
from typing import Callable

import numpy as np

from .config import Config, load_config

__all__ = ["check_determinism", "first_difference"]


def first_difference(a, b):
    """Index (tuple) of the first element where arrays ``a`` and ``b`` differ, or None if equal.

    NaN equals NaN here (a deterministic NaN is still deterministic); shapes and dtypes must agree.
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return ("shape", a.shape, b.shape)
    if a.dtype != b.dtype:
        return ("dtype", a.dtype, b.dtype)
    if a.dtype.kind in "fc":
        diff = ~((a == b) | (np.isnan(a) & np.isnan(b)))
    else:
        diff = a != b
    if not diff.any():
        return None
    return tuple(int(i) for i in np.argwhere(diff)[0])


def _leaves(x, prefix: str = ""):
    """(name, value) of every leaf of a dataclass / NamedTuple / dict tree (states, trajectories, records)."""
    if is_dataclass(x) and not isinstance(x, type):
        items = [(f.name, getattr(x, f.name)) for f in fields(x)]
    elif isinstance(x, tuple) and hasattr(x, "_fields"):
        items = list(x._asdict().items())
    elif isinstance(x, dict):
        items = list(x.items())
    else:
        yield prefix, x
        return
    for k, v in items:
        yield from _leaves(v, f"{prefix}.{k}" if prefix else str(k))


def _compare(what: str, x, y, name_x: str, name_y: str) -> None:
    """Raise AssertionError naming the first differing array/index of two states, trajectories or records."""
    for (name, vx), (_, vy) in zip(_leaves(x), _leaves(y)):
        label = f"{what}.{name}" if name else what
        if vx is None or vy is None:
            if (vx is None) != (vy is None):
                raise AssertionError(f"{label}: {name_x} is {'None' if vx is None else 'set'} but {name_y} is "
                                     f"{'None' if vy is None else 'set'}")
        elif isinstance(vx, np.ndarray) or isinstance(vy, np.ndarray):
            where = first_difference(vx, vy)
            if where is None:
                continue
            if where[0] in ("shape", "dtype"):
                raise AssertionError(f"{label}: {where[0]} {where[1]} ({name_x}) != {where[2]} ({name_y})")
            raise AssertionError(f"{label}[{', '.join(map(str, where))}]: {np.asarray(vx)[where].item()!r} "
                                 f"({name_x}) != {np.asarray(vy)[where].item()!r} ({name_y})")
        elif vx is not vy and vx != vy:
            raise AssertionError(f"{label}: {vx!r} ({name_x}) != {vy!r} ({name_y})")


def _select_run(rec, k):
    """Environment k of a trajectory or record, keeping a batch axis of 1: per-step arrays (T, B, ...) on
    axis 1, per-episode dicts of (B, ...) arrays on axis 0, everything else as is."""
    if rec is None:
        return None
    out = {}
    for name in (rec._fields if hasattr(rec, "_fields") else [f.name for f in fields(rec)]):
        v = getattr(rec, name)
        if isinstance(v, dict):
            v = {n: np.ascontiguousarray(a[k:k + 1]) for n, a in v.items()}
        elif isinstance(v, np.ndarray) and v.ndim >= 2:
            v = np.ascontiguousarray(v[:, k:k + 1])
        out[name] = v
    return type(rec)(**out)


def check_determinism(sim_or_cfg, n_envs: int = 3, n_steps: int = 50, seed: int = 0,
                      controller: Callable | None = None) -> None:
    """Check that rollouts are reproducible and batch-independent; raise AssertionError on the first mismatch.

    Runs ``sim.rollout(sim.init(n_envs, seed), n_steps)`` — a :class:`~finkensim.swarm.SwarmSim` (world,
    every enabled sensor and the behaviour, recording everything it can) or a :class:`~finkensim.world.World`
    with a controller — and checks that

    1. the same rollout run twice gives identical final states and records;
    2. the initial state passed in is left unchanged (rollouts are pure);
    3. environment k of the batch equals a lone run from ``init(env_ids=[k], seed=seed)``, for every k;
    4. the batch with its environment indices reversed gives the same environments, reversed.

    Arrays are compared exactly (bit for bit, NaN equal to NaN). The message names the check, the array
    and the first differing index (records are compared before final states, so it is the earliest
    step that differs), e.g. ``lone env 2 vs batch: traj.sonar[7, 0, 3, 1]: 1.25 (lone) != 1.2500001 (batch)``.

    Args:
        sim_or_cfg: a :class:`~finkensim.swarm.SwarmSim`, a :class:`~finkensim.world.World`, a
            :class:`~finkensim.config.Config`, or anything :func:`~finkensim.config.load_config` takes
            (path, TOML text, dict, None for defaults). A config is checked with a SwarmSim, or with a World
            when ``controller`` is given.
        n_envs: environments in the batch (>= 1).
        n_steps: steps per rollout (>= 0).
        seed: the seed passed to ``init``.
        controller: for a World only: ``f(world, state) -> (cmd_vel, cmd_yaw_rate)`` passed to
            :meth:`~finkensim.world.World.rollout`; None = the config's open-loop ``behaviour.kind``
            (:func:`~finkensim.behaviours.open_loop.open_loop_controller`).
    """
    # local imports: world and swarm import the kernels, keep this module light to import
    from .behaviours.open_loop import open_loop_controller
    from .swarm import SwarmSim
    from .world import World

    if int(n_envs) < 1:
        raise ValueError(f"n_envs = {n_envs!r}: expected >= 1")
    n_envs, n_steps = int(n_envs), int(n_steps)
    sim = sim_or_cfg
    if not isinstance(sim, (World, SwarmSim)):
        cfg = sim if isinstance(sim, Config) else load_config(sim)
        sim = World(cfg) if controller is not None else SwarmSim(cfg)
    if isinstance(sim, SwarmSim):
        if controller is not None:
            raise ValueError("controller: only for a World (a SwarmSim runs its own behaviour)")
        run = lambda state: sim.rollout(state, n_steps, record=True)  # noqa: E731
    else:
        controller = open_loop_controller(sim.cfg) if controller is None else controller
        run = lambda state: sim.rollout(state, n_steps, controller=controller)  # noqa: E731

    init = sim.init(n_envs=n_envs, seed=seed)
    init_copy = init.copy()
    final_a, traj_a = run(init)
    _compare("initial state after rollout", init, init_copy, "after", "before")
    final_b, traj_b = run(sim.init(n_envs=n_envs, seed=seed))
    _compare("repeat: init", init, sim.init(n_envs=n_envs, seed=seed), "run 1", "run 2")
    # trajectories first: their first difference is the earliest step that differs
    _compare("repeat: traj", traj_a, traj_b, "run 1", "run 2")
    _compare("repeat: final", final_a, final_b, "run 1", "run 2")

    for k in range(n_envs):
        lone_init = sim.init(env_ids=[k], seed=seed)
        _compare(f"lone env {k} vs batch: init", lone_init, init.select([k]), "lone", "batch")
        lone_final, lone_traj = run(lone_init)
        _compare(f"lone env {k} vs batch: traj", lone_traj, _select_run(traj_a, k), "lone", "batch")
        _compare(f"lone env {k} vs batch: final", lone_final, final_a.select([k]), "lone", "batch")

    if n_envs > 1:
        rev = np.arange(n_envs)[::-1].copy()
        rev_final, rev_traj = run(sim.init(env_ids=rev, seed=seed))
        for j, k in enumerate(rev):
            _compare(f"reversed env_ids: traj of env {k}", _select_run(rev_traj, j), _select_run(traj_a, k),
                     "reversed", "batch")
        _compare("reversed env_ids: final", rev_final, final_a.select(rev), "reversed", "batch")
