"""Batched Monte-Carlo evaluation of a scenario and the held-out comparison of two parameter sets.

:func:`evaluate` flies B environments of a config in ONE compiled call
(:meth:`SwarmSim.rollout <finkensim.swarm.SwarmSim.rollout>`) and returns each environment's metrics;
:func:`compare` evaluates the defaults and the tuned values on the same held-out environments and
reports each mean with a 95 % confidence interval and the paired difference (tuned − default) with its
interval (the same environments for both: common random numbers make the difference precise).
"""
from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np

from ..config import Config
from ..metrics import episode_metrics

__all__ = ["evaluate", "mean_ci", "compare", "CI_LEVEL"]

CI_LEVEL = 0.95


def evaluate(cfg: Config, n_envs: int, seed: int, duration: float, metrics: Iterable[str]) -> dict[str, np.ndarray]:
    """Metrics (name -> (B,) float64) of ``n_envs`` episodes of ``duration`` s of ``cfg``, environments
    0 … B − 1 of ``seed``: one compiled batched rollout."""
    from ..swarm import SwarmSim, needs_sensors  # the engine loads when a trial runs, not with the CLI

    sim = SwarmSim(cfg, sensors=needs_sensors(cfg.behaviour.kind))
    n_steps = max(1, int(round(duration / cfg.simulation.dt)))
    final, rec = sim.rollout(sim.init(n_envs=int(n_envs), seed=int(seed)), n_steps, record=("pose",))
    return episode_metrics(rec.pose, (cfg.arena.width, cfg.arena.length), cfg.copters.radius,
                           final_pos=final.world.pos, names=list(metrics))


def mean_ci(x, level: float = CI_LEVEL) -> tuple[float, float, float]:
    """(mean, low, high): Student-t confidence interval of the mean of the finite values of ``x``."""
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return (float("nan"),) * 3
    m = float(x.mean())
    if x.size < 2:
        return m, float("nan"), float("nan")
    from scipy import stats

    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size))
    return m, m - half, m + half


def compare(spec, best: Mapping, n_envs: int | None = None, seed: int | None = None) -> list[dict]:
    """Rows comparing the defaults and ``best`` on held-out environments, for the base settings and every
    ``[compare.<name>]`` of the study: variant, metric, direction, default / tuned mean with CI, the paired
    difference tuned − default with CI, and ``better`` (the difference's CI lies entirely on the side of
    the objective's direction)."""
    n_envs = spec.heldout_envs if n_envs is None else int(n_envs)
    seed = spec.heldout_seed if seed is None else int(seed)
    metrics = [m for m, _ in spec.objectives]
    rows = []
    for variant, extra in {"base": {}, **spec.compare}.items():
        d = evaluate(spec.config(spec.defaults(), extra), n_envs, seed, spec.duration, metrics)
        t = evaluate(spec.config(best, extra), n_envs, seed, spec.duration, metrics)
        for metric, direction in spec.objectives:
            dm, dlo, dhi = mean_ci(d[metric])
            tm, tlo, thi = mean_ci(t[metric])
            diff, lo, hi = mean_ci(t[metric] - d[metric])
            better = hi < 0 if direction == "minimize" else lo > 0
            worse = lo > 0 if direction == "minimize" else hi < 0
            rows.append(dict(variant=variant, metric=metric, direction=direction, n_envs=n_envs, seed=seed,
                             default=dm, default_lo=dlo, default_hi=dhi, tuned=tm, tuned_lo=tlo, tuned_hi=thi,
                             diff=diff, diff_lo=lo, diff_hi=hi,
                             verdict="better" if better else ("worse" if worse else "no significant change")))
    return rows
