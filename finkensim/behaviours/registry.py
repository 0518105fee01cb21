"""Behaviours as registered plug-ins: the contract (:class:`Behaviour`), what a behaviour sees
(:class:`BehaviourInput`) and the one table of them (:data:`BEHAVIOURS`).

A behaviour is a compiled ``commands`` kernel plus its parameter record. The engine
(:mod:`finkensim.swarm.kernel`) compiles one closed loop per behaviour with that kernel called at every step, for
every environment::

    commands(inputs, params, memory, cmd_v, cmd_w) -> None

- ``inputs``: a :class:`BehaviourInput` of one environment (its N copters' readings of this step, after the wall
  check; the pose is privileged information, for open-loop references);
- ``params``: the behaviour's parameter record (a NamedTuple of numbers and arrays, from ``params(cfg)``);
- ``memory``: (N, W) float64, the behaviour's own per-copter memory (W = ``Behaviour.memory``), kept across
  steps in :class:`~finkensim.behaviours.wall_check.BehaviourState` ``.commands``; change it in place;
- ``cmd_v`` (N, 2) m/s in the behaviour's ``frame`` (``"body"``: x forward, y left; ``"world"``) and ``cmd_w``
  (N,) rad/s: the outputs; write every entry at every call.

The built-ins (:mod:`.builtin`) are registered through :func:`register_behaviour` like a user's; the recipe is in
``docs/architecture.md`` ("Add a behaviour") and :func:`finkensim.plugin_checkers.check_behaviour` checks one.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np

from ..config import ConfigError
from ..configfields import BEHAVIOUR_KINDS
from ..usertext import suggest

__all__ = ["Behaviour", "BehaviourInput", "NoParams", "BEHAVIOURS", "SENSORS", "register_behaviour",
           "get_behaviour", "no_params"]

#: the sensors a behaviour may declare it reads (keys of ``SwarmSim.enabled``)
SENSORS = ("sonar", "down", "ranging", "imu")


class BehaviourInput(NamedTuple):
    """What one environment's behaviour sees at one step (N copters, M beacons).

    pos (N, 2) m and yaw (N,) rad: the true pose (privileged; open-loop references only); sonar (N, 4) m (front,
    left, back, right; ``sonar.max_range`` when the sonars are off); wall (N, 4) bool: readings the wall check
    judged to be walls; sonar_down (N,) m (0 when off); ranging (N, N + M) m (or (N, 0) when nothing ranges);
    imu_acc (N, 2) m/s² body frame and imu_gyro (N,) rad/s (0 when off); seed, env_id, step: the keys of
    reproducible randomness (:mod:`finkensim.kernels.rng`); dt s."""

    pos: np.ndarray
    yaw: np.ndarray
    sonar: np.ndarray
    wall: np.ndarray
    sonar_down: np.ndarray
    ranging: np.ndarray
    imu_acc: np.ndarray
    imu_gyro: np.ndarray
    seed: int
    env_id: int
    step: int
    dt: float


class NoParams(NamedTuple):
    """The parameter record of a behaviour without parameters."""


def no_params(cfg) -> NoParams:
    """The empty parameter record, whatever ``cfg``.

    Parameters
    ----------
    cfg : Config
        Ignored.

    Returns
    -------
    NoParams
        An empty record.
    """
    return NoParams()


@dataclass(frozen=True)
class Behaviour:
    """A behaviour plug-in (module doc: the ``commands`` contract).

    Parameters
    ----------
    name : str
        Its name (``behaviour.kind`` of a built-in; ``SwarmSim(cfg, behaviour=name)``).
    commands : numba dispatcher
        ``commands(inputs, params, memory, cmd_v, cmd_w)``, an ``@njit`` function.
    params : callable
        ``params(cfg) -> record``: the parameter record from a :class:`~finkensim.config.Config` (numbers and
        arrays only; it must pickle). Default: :func:`no_params`.
    frame : str
        ``"body"`` or ``"world"``: the frame of ``cmd_v``.
    sensors : tuple of str
        The sensors (:data:`SENSORS`) it reads: a flight with one of them disabled is refused.
    memory : int
        W, floats of per-copter memory it keeps (``memory`` (N, W) in ``commands``).
    cached : bool
        Keep its compiled closed loop in numba's on-disk cache. Only for behaviours defined in an importable
        module whose source does not change unseen (the built-ins): the cache notices edits to the engine's file
        only. A notebook's behaviour compiles anew in each process.
    doc : str
        One line for listings.
    """

    name: str
    commands: Callable
    params: Callable = no_params
    frame: str = "body"
    sensors: tuple = ()
    memory: int = 0
    cached: bool = False
    doc: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ConfigError(f"Behaviour name = {self.name!r}: expected a Python identifier (it names the "
                              "compiled loop)")
        if self.frame not in ("body", "world"):
            raise ConfigError(f"Behaviour {self.name!r} frame = {self.frame!r}: expected 'body' or 'world'")
        bad = [s for s in self.sensors if s not in SENSORS]
        if bad or isinstance(self.sensors, str):
            raise ConfigError(f"Behaviour {self.name!r} sensors = {self.sensors!r}: expected a tuple of names "
                              f"from {', '.join(map(repr, SENSORS))}")
        if not isinstance(self.memory, int) or isinstance(self.memory, bool) or self.memory < 0:
            raise ConfigError(f"Behaviour {self.name!r} memory = {self.memory!r}: expected a non-negative integer "
                              "(floats per copter)")
        if not callable(self.commands) or not callable(self.params):
            raise ConfigError(f"Behaviour {self.name!r}: commands and params must be callables (an @njit "
                              "kernel and a function of the config)")


#: name → :class:`Behaviour`: every behaviour the engine can fly (built-ins first, then registered ones)
BEHAVIOURS: dict[str, Behaviour] = {}
BEHAVIOUR_KINDS.follow(BEHAVIOURS)  # the config's behaviour.kind accepts every name in it (TOML or Python)


def register_behaviour(behaviour: Behaviour, replace: bool = False) -> Behaviour:
    """Add ``behaviour`` to :data:`BEHAVIOURS` (the one table the engine and the checkers read).

    Parameters
    ----------
    behaviour : Behaviour
        The plug-in.
    replace : bool
        Allow replacing a registered behaviour of the same name.

    Returns
    -------
    Behaviour
        ``behaviour`` (so that registering can be one line).
    """
    if not isinstance(behaviour, Behaviour):
        raise ConfigError(f"register_behaviour({behaviour!r}): expected a finkensim.behaviours.Behaviour")
    if behaviour.name in BEHAVIOURS and not replace and BEHAVIOURS[behaviour.name] is not behaviour:
        raise ConfigError(f"behaviour {behaviour.name!r} is registered already: pass replace=True to replace it")
    BEHAVIOURS[behaviour.name] = behaviour  # now valid as behaviour.kind in a config too (BEHAVIOUR_KINDS follows it)
    return behaviour


def get_behaviour(name) -> Behaviour:
    """The registered behaviour called ``name`` (a :class:`Behaviour` is returned as it is).

    Parameters
    ----------
    name : str or Behaviour
        A key of :data:`BEHAVIOURS`.

    Returns
    -------
    Behaviour
        The plug-in.
    """
    if isinstance(name, Behaviour):
        return name
    if name not in BEHAVIOURS:
        raise ConfigError(f"behaviour = {name!r}{suggest(str(name), BEHAVIOURS)}: expected one of "
                          f"{', '.join(map(repr, BEHAVIOURS))}, a registered Behaviour or a function "
                          "f(readings, memory, params)")
    return BEHAVIOURS[name]
