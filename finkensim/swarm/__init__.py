"""The closed swarm loop: sense → behave → step, compiled, for B environments at once.

    from finkensim.swarm import SwarmSim
    sim = SwarmSim(cfg)                                   # behaviour.kind from the config
    state = sim.init(n_envs=1024, seed=1)                 # world + IMU bias + behaviour memory
    final, rec = sim.rollout(state, n_steps=200, record=("pose", "wall"))
    rec.pose            # (T, B, N, 3) state before each step
    rec.counters        # per-episode counters (B, N): collisions, wall_contacts, wall_onsets, wall_readings

Each step k (the state after k steps, ``WorldState.step``), for every environment:

1. **sense** — horizontal sonars (:func:`~finkensim.sensors.sonar.sonar_env` on the plates
   displaced by their current angles), the down sonar, virtual ranging to every other copter and beacon,
   and the IMU (reading the acceleration of the step that ended at k; its bias state advances). Every
   sensor uses exactly the random numbers of its batched function at step k (same keys, same indices),
   and only runs when its ``enabled`` key is true;
2. **behave** — IMU dead reckoning, the wall plausibility check (``behaviour.wall_check``), then the
   controller: ``attraction_repulsion`` (body-frame command from the sonar readings, rotated to the
   world frame by the flight controller), ``random_walk`` (the open-loop bounded walk of
   :mod:`finkensim.behaviours.random_walk`, identical to ``World.rollout`` with
   :class:`~finkensim.behaviours.open_loop.RandomWalk`), ``hover``, or any behaviour registered with
   :func:`~finkensim.behaviours.register_behaviour` (its compiled ``commands`` kernel);
3. **step** — :func:`~finkensim.world.step_env` (copters, contacts, Bernoulli plates).

:meth:`SwarmSim.rollout` runs T steps of B environments in compiled code
(:func:`finkensim.swarm.kernel.swarm_rollout`: B split over numba's threads, the T loop inside, buffers allocated once
per environment, no Python per step). Besides the sensor readings and commands it can record the state
before each step (pose, velocity, acceleration, yaw rate, plate angles) and the sonars' error-free
distances and hit types (:data:`RECORDABLE`), so a flight log needs nothing else.
:meth:`SwarmSim.step` is the same step through the batched Python-facing functions
(``sonar_readings``, ``down_readings``, ``ranging_readings``, ``imu_step``,
:func:`~finkensim.behaviours.wall_check.wall_check`, :func:`~finkensim.behaviours.attraction.attraction_repulsion`,
``World.step``); both give identical results bit for bit (tested; ``rollout(..., python=True)`` runs the
per-step path), and a result depends only on (seed, environment index, step, copter).

**Your own behaviour.** Pass a Python function ``f(readings, memory, params) -> (cmd_vel, cmd_yaw_rate)``
as ``SwarmSim(cfg, behaviour=f)``. It sees only the copters' own sensors, a :class:`SensorReadings`
(sonar (B, N, 4) m, sonar_down (B, N) m, ranging (B, N, N + M) m, imu_acc (B, N, 2) m/s² body frame,
imu_gyro (B, N) rad/s, wall (B, N, 4) bool from the configured wall check, plus step, dt, seed and
env_ids for reproducible randomness; a disabled sensor is None). ``memory`` is the object in
``state.memory`` (from ``memory=`` of :meth:`SwarmSim.init`, or the ``memory_factory(B, N)`` given to
the constructor, else a new empty dict) — mutate it in place to remember things across steps.
``params`` is ``SwarmSim(..., params=...)`` (default: ``cfg.behaviour``). Return the velocity
command (B, N, 2) m/s — body frame (x forward, y left) by default, or world frame with
``command_frame="world"`` — and the yaw-rate command (B, N) rad/s (or None for 0). Such a behaviour
runs through the per-step Python path (``rollout`` loops over :meth:`SwarmSim.step`). Example — fly
toward the farthest echo, stop when something is closer than 0.5 m::

    import numpy as np
    from finkensim.swarm import SwarmSim

    def explorer(readings, memory, params):
        r = readings.sonar                                  # (B, N, 4): front, left, back, right
        heading = np.radians([0.0, 90.0, 180.0, -90.0])[r.argmax(-1)]
        speed = np.where(r.min(-1) < 0.5, 0.0, 0.3)
        v = speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], -1)
        memory["steps"] = memory.get("steps", 0) + 1
        return v, None                                      # body frame, no turning

    sim = SwarmSim(cfg, behaviour=explorer)
    final, rec = sim.rollout(sim.init(n_envs=4, seed=0), 100)

Modules: :mod:`.state` (the records: :class:`SwarmState`, :class:`Models`, ``RunSpec``, :class:`SwarmRecord`),
:mod:`.sense` (the one sense step of both engines), :mod:`.kernel` (the compiled loop, one per registered behaviour:
:mod:`finkensim.behaviours.registry`), :mod:`.sim` (:class:`SwarmSim`), :mod:`.control` (the RL step). The :class:`SwarmState` carries the world state, the IMU bias (B, N, 3) and the behaviour memory
(:class:`~finkensim.behaviours.wall_check.BehaviourState`: fail counters, wall flags, dead reckoning).
"""
from __future__ import annotations

from ..sensors.ranging_kernels import ranging_batch, ranging_env
from .kernel import swarm_rollout
from .sim import SwarmSim, check_behaviour_sensors, needs_sensors
from .state import RECORDABLE, Models, SensorReadings, SwarmRecord, SwarmState

__all__ = ["SwarmSim", "SwarmState", "SwarmRecord", "SensorReadings", "RECORDABLE", "Models", "needs_sensors",
           "check_behaviour_sensors", "ranging_env", "ranging_batch", "swarm_rollout"]
