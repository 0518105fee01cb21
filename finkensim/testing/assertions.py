"""Invariant checks for property tests, with failure messages that say where and by how much.

Each raises ``AssertionError`` (so pytest and Hypothesis treat it as a failed property) naming the copter, the
environment and step (or sample), the values and what was expected. They accept what the simulator and the loader
produce: a :class:`~finkensim.world.WorldState` or :class:`~finkensim.swarm.SwarmState` (B, N), a
:class:`~finkensim.world.Trajectory` or :class:`~finkensim.swarm.SwarmRecord` (T, B, N), a
:class:`~finkensim.flightlog.FlightLog` (T, N), or a plain array of positions (..., N, 2) m (more trailing
columns, such as yaw, are ignored).
"""
from __future__ import annotations

import os
from typing import Any, Iterable

import numpy as np

__all__ = ["assert_inside_arena", "assert_no_overlap", "assert_reproducible", "assert_flightlog_valid"]


def _positions(obj: Any) -> tuple[np.ndarray, tuple[str, ...], list[str] | None]:
    """(positions (*lead, N, 2) m, names of the lead axes, copter names or None) of anything with poses."""
    from ..flightlog import FlightLog

    if isinstance(obj, FlightLog):
        return np.asarray(obj.pose)[..., :2], ("sample",), [str(c) for c in obj.copter_ids]
    world = getattr(obj, "world", None)  # a SwarmState
    if world is not None and hasattr(world, "pos"):
        obj = world
    if hasattr(obj, "pos") and hasattr(obj, "env_ids"):  # a WorldState
        return np.asarray(obj.pos), ("env",), None
    pose = getattr(obj, "pose", None)  # a Trajectory or SwarmRecord
    if pose is not None and np.ndim(pose) == 4:
        return np.asarray(pose)[..., :2], ("step", "env"), None
    a = np.asarray(obj, dtype=float)
    if a.ndim < 2 or a.shape[-1] < 2:
        raise TypeError(f"expected a world state, trajectory, flight log or positions (..., N, 2) m, got "
                        f"{type(obj).__name__} of shape {np.shape(obj)}")
    return a[..., :2], ("index",) * (a.ndim - 2), None


def _where(lead_axes: tuple[str, ...], index: tuple[int, ...]) -> str:
    return ", ".join(f"{name} {i}" for name, i in zip(lead_axes, index))


def _copter(names, i: int) -> str:
    return f"copter {i}" + (f" ({names[i]!r})" if names else "")


def _arena_and_radius(obj: Any, arena: Any, radius: float | None) -> tuple[float, float, float]:
    from ..config import Config
    from ..flightlog import DEFAULT_COPTER_RADIUS, FlightLog

    cfg = getattr(arena, "cfg", arena)  # a World or SwarmSim has .cfg
    if isinstance(cfg, Config):
        width, length = cfg.arena.width, cfg.arena.length
        radius = cfg.copters.radius if radius is None else radius
    elif arena is not None:
        width, length = (float(v) for v in arena)
    elif isinstance(obj, FlightLog):
        width, length = float(obj.arena[0]), float(obj.arena[1])
        radius = float(obj.meta.get("copter_radius", DEFAULT_COPTER_RADIUS)) if radius is None else radius
    else:
        raise TypeError("arena: expected a Config, World, SwarmSim or (width, length) m (only a flight log "
                        "carries its own)")
    return width, length, 0.0 if radius is None else float(radius)


def assert_inside_arena(obj: Any, arena: Any = None, radius: float | None = None, *, tol: float = 1e-9) -> None:
    """Assert every copter body lies inside the arena: centre in [r, width − r] × [r, length − r] (m), within ``tol``.

    Args:
        obj: states, trajectories, a flight log or positions (module doc).
        arena: a Config, World or SwarmSim (arena and ``copters.radius``), or (width, length) m; a flight log's
            own ``arena`` and ``meta['copter_radius']`` when omitted.
        radius: copter body radius r (m); default from ``arena``'s config or the log, else 0 (centres only).
        tol: slack (m) for rounding.
    """
    pos, axes, names = _positions(obj)
    width, length, r = _arena_and_radius(obj, arena, radius)
    x, y = pos[..., 0], pos[..., 1]
    out = np.maximum.reduce([r - x, x - (width - r), r - y, y - (length - r)])  # m outside the allowed box
    bad = ~(out <= tol)  # NaN positions are outside too
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        lead, c = idx[:-1], idx[-1]
        where = _where(axes, lead)
        raise AssertionError(
            f"{_copter(names, c)}{f' ({where})' if where else ''} is at ({x[idx]:.6g}, {y[idx]:.6g}) m, "
            f"{out[idx]:.3g} m outside [{r:g}, {width - r:g}] x [{r:g}, {length - r:g}] m (the {width:g} x {length:g} m "
            f"arena less the radius {r:g} m); {int(bad.sum())} of {bad.size} copter positions are outside")


def assert_no_overlap(obj: Any, radius: Any = None, *, tol: float = 1e-9) -> None:
    """Assert no two copter bodies overlap: every pair of centres at least 2 r apart (m), within ``tol``.

    ``radius`` is r in m, or a Config / World / SwarmSim (its ``copters.radius``); a flight log's
    ``meta['copter_radius']`` when omitted. Pairs are compared within each environment, step or sample.
    """
    from ..config import Config
    from ..flightlog import DEFAULT_COPTER_RADIUS, FlightLog

    pos, axes, names = _positions(obj)
    cfg = getattr(radius, "cfg", radius)
    if isinstance(cfg, Config):
        r = cfg.copters.radius
    elif radius is not None:
        r = float(radius)
    elif isinstance(obj, FlightLog):
        r = float(obj.meta.get("copter_radius", DEFAULT_COPTER_RADIUS))
    else:
        raise TypeError("radius: expected a number (m) or a Config, World or SwarmSim")
    N = pos.shape[-2]
    if N < 2:
        return
    flat = pos.reshape(-1, N, 2)
    limit = 2.0 * r - tol
    iu, ju = np.triu_indices(N, k=1)
    count, first = 0, None
    for k in range(flat.shape[0]):
        d = np.sqrt(((flat[k, iu] - flat[k, ju]) ** 2).sum(-1))
        close = d < limit
        if close.any():
            count += int(close.sum())
            if first is None:
                p = int(np.argmax(close))
                first = (k, int(iu[p]), int(ju[p]), float(d[p]))
    if first is not None:
        k, i, j, d = first
        lead = tuple(int(v) for v in np.unravel_index(k, pos.shape[:-2])) if pos.ndim > 2 else ()
        where = _where(axes, lead)
        raise AssertionError(
            f"{_copter(names, i)} and {_copter(names, j)}{f' ({where})' if where else ''} overlap: centres "
            f"{d:.6g} m apart, expected at least 2 x radius = {2 * r:g} m; {count} overlapping pair(s) in all")


def assert_flightlog_valid(log_or_path: Any, *, check_units: bool = True) -> None:
    """Assert a :class:`~finkensim.flightlog.FlightLog` (or an ``.npz`` / ``.csv`` file, read as ``finkensim
    check`` reads it) follows ``spec/flightlog.md``; the message is the loader's, naming the array and the problem."""
    from ..config import ConfigError
    from ..flightlog import FlightLog, FlightLogError, validate

    try:
        if isinstance(log_or_path, FlightLog):
            validate(log_or_path, check_units=check_units)
        else:
            from ..checkfiles import check_file

            check_file(log_or_path)
    except (FlightLogError, ConfigError) as exc:
        raise AssertionError(f"not a valid flight log: {exc}") from None


def assert_reproducible(target: Any, *, seed: int = 0, n_envs: int = 3, n_steps: int = 20,
                        executors: Iterable[str] = ("serial", "process"), controller=None) -> None:
    """Assert that results depend on the seed only: bit-identical across repeats, batch sizes, environment
    order and executors.

    1. :func:`finkensim.determinism.check_determinism` (repeat, purity, each environment of a batch of ``n_envs`` equal
       to a lone run, reversed environment order) for ``n_steps`` steps.
    2. With more than one of ``executors`` (from :data:`finkensim.sweep.executors.EXECUTORS`) and a configuration
       as ``target``: the same episodes (seeds ``seed``, ``seed + 1``; ``n_steps`` steps) run by each executor, as a
       sweep runs them, give bit-identical metrics. Serial episodes run on this process's numba threads, pool
       workers on one thread each, so this also compares thread counts.

    Args:
        target: a Config (or anything :func:`~finkensim.config.load_config` takes), a SwarmSim, or a World (with
            ``controller``); executors need a configuration (a Python behaviour lives in this process only).
    """
    from ..determinism import check_determinism, first_difference
    from ..config import Config, load_config

    try:
        check_determinism(target, n_envs=n_envs, n_steps=n_steps, seed=seed, controller=controller)
    except AssertionError as exc:
        raise AssertionError(f"not reproducible across repeats and batch sizes (seed {seed}, {n_envs} "
                             f"environments, {n_steps} steps): {exc}") from None
    executors = list(executors)
    if len(executors) < 2 or not (target is None or isinstance(target, (Config, str, dict, os.PathLike))):
        return
    from ..metrics import METRICS
    from ..sweep import executors as ex

    for name in executors:
        ex.check_executor(name, None)
    cfg = target if isinstance(target, Config) else load_config(target)
    cfg = cfg.replace({"simulation.duration": cfg.simulation.dt * max(1, n_steps)})
    names = list(METRICS)
    results = {}
    for name in executors:
        # workers run one numba thread each (as a sweep's do); this process keeps its own thread count
        tasks = [dict(run_id=k, config=cfg.to_dict(), seed=seed + k, metrics=names, runner=None,
                      single_thread=name != "serial") for k in range(2)]
        if name == "serial":
            rows = list(ex.run_serial(tasks))
        elif name == "process":
            rows = list(ex.run_process(tasks, workers=2))
        else:
            client, cluster = ex.dask_client(2, None)
            try:
                rows = list(ex.run_dask(tasks, 2, client))
            finally:
                client.close()
                cluster.close()
        by_run = {row["run_id"]: row for row in rows}
        for k, row in by_run.items():
            if row.get("status") != "ok":
                raise AssertionError(f"executor {name!r}: run {k} (seed {seed + k}) failed: {row.get('error')}")
        results[name] = by_run
    ref_name = executors[0]
    for name in executors[1:]:
        for k in range(2):
            for m in names:
                a, b = results[ref_name][k][m], results[name][k][m]
                if first_difference(np.array(a), np.array(b)) is not None:
                    raise AssertionError(f"executor {name!r} differs from {ref_name!r}: run {k} (seed {seed + k}) "
                                         f"metric {m!r} = {b!r} vs {a!r}; expected bit-identical results")
