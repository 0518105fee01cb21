"""Swarm controllers: functions from a copter's own state/sensor readings to velocity commands.

Built in (``behaviour.kind`` in the config), all compiled into the closed loop of
:class:`finkensim.swarm.SwarmSim`:

- ``attraction_repulsion`` (:mod:`.attraction`): the original FINken controller on the four sonar
  readings, Δ = w_c · Σ p_j (a − b exp(−|p_j|²/c)) + w_t · a · target;
- ``random_walk`` (:mod:`.random_walk`) and ``hover``: open-loop references (also as
  :meth:`World.rollout <finkensim.world.World.rollout>` controllers in :mod:`.open_loop`);
- the wall plausibility checks ``behaviour.wall_check = "per_reading" | "sequence"`` (:mod:`.wall_check`)
  that drop readings judged to be walls from attraction.

**A compiled behaviour of your own** is a plug-in: an ``@njit`` ``commands(inputs, params, memory, cmd_v, cmd_w)``
kernel and its parameter record, registered with one :func:`register_behaviour` call (:mod:`.registry`; the recipe
is in ``docs/architecture.md``, "Add a behaviour"); it flies in the compiled engine like the built-ins, which are
registered the same way (:mod:`.builtin`). Check it with :func:`finkensim.testing.check_behaviour`.

**Your own behaviour in plain Python** is a function ``f(readings, memory, params) -> (cmd_vel, cmd_yaw_rate)``
passed as ``SwarmSim(cfg, behaviour=f)``; the full contract (what ``readings`` holds, body or world
frame, memory) is in the docstring of :mod:`finkensim.swarm`. It sees only the copters' own sensors.
Example — back away from every echo closer than 1 m, otherwise drift forward::

    import numpy as np
    from finkensim.metrics import episode_metrics
    from finkensim.scenario import load_scenario
    from finkensim.swarm import SwarmSim

    MOUNT = np.radians([0.0, 90.0, 180.0, -90.0])        # sonar.yaw_deg: front, left, back, right

    def shy(readings, memory, params):
        r = readings.sonar                                 # (B, N, 4) m, this step's readings
        push = np.where(r < 1.0, r - 1.0, 0.0)             # < 0 for echoes inside 1 m
        v = np.stack([(push * np.cos(MOUNT)).sum(-1), (push * np.sin(MOUNT)).sum(-1)], -1)
        v[..., 0] += 0.2                                   # body frame: x forward, y left (m/s)
        return v, None                                     # no turning

    cfg = load_scenario()
    sim = SwarmSim(cfg, behaviour=shy)
    final, rec = sim.rollout(sim.init(n_envs=8, seed=0), n_steps=400, record=("pose",))
    m = episode_metrics(rec.pose, (cfg.arena.width, cfg.arena.length), cfg.copters.radius,
                        final_pos=final.world.pos)    # {"cohesion": (8,) m, "wall_sticking": ..., ...}

A Python behaviour runs through the per-step path (each step calls the batched sensor kernels),
slower than the built-in ones but fine for a few environments. To run it in a Monte-Carlo sweep, give
:func:`finkensim.sweep.run_sweep` a ``runner(cfg, seed, env_id) -> {metric: value}`` built like
``m`` above (``sim.init(seed=seed, env_ids=[env_id])``); for the process pool or Dask the runner must
live in an importable module, in a notebook use ``executor="serial"``
(``notebooks/03_swarm_and_sweeps.ipynb`` does exactly that).
"""
from .registry import BEHAVIOURS, Behaviour, BehaviourInput, NoParams, get_behaviour, register_behaviour
from . import builtin  # noqa: F401 — importing it registers the built-ins

__all__ = ["BEHAVIOURS", "Behaviour", "BehaviourInput", "NoParams", "get_behaviour", "register_behaviour"]
