"""Public checkers of plug-ins, in the style of ``gymnasium.utils.env_checker.check_env`` and scikit-learn's
``check_estimator``: :func:`check_behaviour` for a behaviour (:mod:`finkensim.behaviours.registry`),
:func:`check_task` for an RL reward task (:mod:`finkensim.envs.tasks`) and :func:`check_effect` for an effect of the
gap diagnosis (:mod:`finkensim.gap.attribute.effects`). Each raises :class:`PluginError` naming
what failed, the value and what was expected, and returns None when the plug-in passes. The tests run every
registered plug-in through them; run them on your own before registering it::

    from finkensim.testing import check_behaviour, check_task
    check_behaviour(my_behaviour)          # a Behaviour
    check_task(MyTask())                   # an object with reset(ctx, pos) and reward(ctx, world)
    check_effect(my_effect)                # a finkensim.gap.attribute.effects.Effect
"""
from __future__ import annotations

import inspect
import pickle

import numpy as np

from .behaviours.registry import Behaviour, BehaviourInput
from .config import Config
from .default_scenario import load_scenario
from .kernels.outline import python_function

__all__ = ["PluginError", "check_behaviour", "check_effect", "check_task", "random_inputs"]


class PluginError(AssertionError):
    """A plug-in broke its contract (the message names the check, the value and what was expected)."""


def random_inputs(cfg: Config, seed: int = 0, env_id: int = 0, step: int = 0) -> BehaviourInput:
    """A random scene of one environment as a behaviour sees it: copters inside the arena, sonar readings in
    [min_range, max_range] m with some walls flagged, down-sonar, ranging, IMU readings.

    Parameters
    ----------
    cfg : Config
        The configuration (arena, copters, sensors, beacons).
    seed : int
        Seed of the scene (and of the behaviour's randomness).
    env_id : int
        Environment index passed to the behaviour.
    step : int
        Step passed to the behaviour.

    Returns
    -------
    BehaviourInput
        One environment's inputs (N = ``copters.n``).
    """
    rng = np.random.default_rng(seed)
    N = cfg.copters.n
    R = N + len(cfg.ranging.beacons)
    r = cfg.copters.radius
    pos = np.stack([rng.uniform(r, cfg.arena.width - r, N), rng.uniform(r, cfg.arena.length - r, N)], -1)
    return BehaviourInput(pos, rng.uniform(-np.pi, np.pi, N),
                          rng.uniform(cfg.sonar.min_range, cfg.sonar.max_range, (N, 4)), rng.random((N, 4)) < 0.2,
                          rng.uniform(0.0, 2.0, N), rng.uniform(0.0, max(cfg.arena.width, cfg.arena.length), (N, R)),
                          rng.normal(0.0, 1.0, (N, 2)), rng.normal(0.0, 0.5, N), int(seed), int(env_id), int(step),
                          float(cfg.simulation.dt))


def _fail(name: str, what: str) -> None:
    raise PluginError(f"{name}: {what}")


def _run(commands, inputs, params, memory):
    v = np.full((inputs.pos.shape[0], 2), np.nan)
    w = np.full(inputs.pos.shape[0], np.nan)
    commands(inputs, params, memory, v, w)
    return v, w


def _check_params(b: Behaviour, params) -> None:
    if not (isinstance(params, tuple) and hasattr(params, "_fields")):
        _fail(b.name, f"params(cfg) returned {type(params).__name__}: expected a NamedTuple record")
    for field, value in zip(params._fields, params):
        ok = isinstance(value, (bool, int, float, np.integer, np.floating)) or (
            isinstance(value, np.ndarray) and value.dtype.kind in "biuf")
        if not ok:
            _fail(b.name, f"parameter {field} = {value!r}: expected a number or a numeric array (numba reads it)")
    again = pickle.loads(pickle.dumps(params))
    same = all(np.array_equal(x, y) for x, y in zip(params, again))
    if type(again) is not type(params) or not same:
        _fail(b.name, f"params {params!r} do not survive pickling unchanged (sweeps send them to other processes)")


def _check_commands(b: Behaviour, cfg: Config, params, seed: int) -> None:
    N = cfg.copters.n
    for k in range(3):
        inputs = random_inputs(cfg, seed + k, env_id=k, step=17 * k)
        before = [np.copy(a) if isinstance(a, np.ndarray) else a for a in inputs]
        memory = np.zeros((N, b.memory))
        # first the plain Python function on arrays of exactly the declared memory: an access beyond it raises
        # here (compiled code would write past the array unseen)
        try:
            vp, wp = _run(python_function(b.commands), inputs, params, memory.copy())
        except IndexError as e:
            _fail(b.name, f"commands indexed outside its arrays ({e}); it declares memory = {b.memory} floats "
                          "per copter")
        v, w = _run(b.commands, inputs, params, memory.copy())
        if not (np.isfinite(v).all() and np.isfinite(w).all()):
            _fail(b.name, f"commands left non-finite or unwritten entries: cmd_v {v.tolist()}, cmd_w {w.tolist()} "
                          "(expected every entry written, finite)")
        speed = np.hypot(v[:, 0], v[:, 1]).max()
        yaw = np.abs(w).max()
        if speed > cfg.copters.max_speed * (1 + 1e-9):
            _fail(b.name, f"a speed command of {speed:.6g} m/s: expected at most copters.max_speed = "
                          f"{cfg.copters.max_speed} m/s")
        if yaw > np.deg2rad(cfg.copters.max_yaw_rate_deg) * (1 + 1e-9):
            _fail(b.name, f"a yaw-rate command of {np.rad2deg(yaw):.6g} deg/s: expected at most "
                          f"copters.max_yaw_rate_deg = {cfg.copters.max_yaw_rate_deg} deg/s")
        v2, w2 = _run(b.commands, inputs, params, memory.copy())
        if not (np.array_equal(v, v2) and np.array_equal(w, w2)):
            _fail(b.name, "two calls on the same inputs, memory and seed gave different commands (expected "
                          "deterministic commands: draw randomness from finkensim.kernels.rng with inputs.seed, "
                          "env_id, step)")
        for field, old, new in zip(inputs._fields, before, inputs):
            if isinstance(old, np.ndarray) and not np.array_equal(old, new):
                _fail(b.name, f"commands changed its input {field} (expected read-only inputs; keep state in "
                              "memory)")
        if not (np.allclose(v, vp, rtol=1e-9, atol=1e-12) and np.allclose(w, wp, rtol=1e-9, atol=1e-12)):
            _fail(b.name, "the compiled commands differ from its plain Python function on the same inputs")


def _check_flight(b: Behaviour, cfg: Config, seed: int) -> None:
    from .swarm import SwarmSim

    sim = SwarmSim(cfg, behaviour=b)
    state = sim.init(n_envs=2, seed=seed)
    runs = [sim.rollout(state, 3, record=("pose", "cmd_vel")) for _ in range(2)]
    (f1, r1), (f2, r2) = runs
    if not np.isfinite(r1.pose).all() or not np.isfinite(r1.cmd_vel).all():
        _fail(b.name, "a compiled flight of 3 steps gave non-finite poses or commands")
    if not (np.array_equal(r1.pose, r2.pose) and np.array_equal(f1.behaviour.commands, f2.behaviour.commands)):
        _fail(b.name, "two compiled flights from the same state differ (expected deterministic flight)")


def check_behaviour(behaviour: Behaviour, cfg: Config | None = None, seed: int = 0, fly: bool = True) -> None:
    """Check a behaviour plug-in against its contract (:mod:`finkensim.behaviours.registry`).

    Its default parameters (``params(cfg)``) are a NamedTuple of numbers and numeric arrays that pickle; over three
    random scenes (:func:`random_inputs`) its commands are finite, every entry written, within ``copters.max_speed``
    and ``copters.max_yaw_rate_deg``, deterministic for the same inputs, leave the inputs unchanged, stay within
    the declared memory (the plain Python function runs on arrays of exactly that size) and equal the plain
    Python function's; with ``fly``, two short compiled flights (2 environments, 3 steps) are finite and identical.

    Parameters
    ----------
    behaviour : Behaviour
        The plug-in (registered or not).
    cfg : Config or None
        The configuration of the scenes (default: the built-in scenario with sonar, ranging and IMU on).
    seed : int
        Seed of the random scenes.
    fly : bool
        Also fly it in the compiled engine (compiles its closed loop: tens of seconds when not cached).

    Raises
    ------
    PluginError
        Naming the failed check.
    """
    if not isinstance(behaviour, Behaviour):
        raise PluginError(f"check_behaviour({behaviour!r}): expected a finkensim.behaviours.Behaviour")
    cfg = cfg if cfg is not None else load_scenario(None).replace(
        {"sonar.enabled": True, "ranging.enabled": True, "imu.enabled": True})
    params = behaviour.params(cfg)
    _check_params(behaviour, params)
    _check_commands(behaviour, cfg, params, seed)
    if fly:
        _check_flight(behaviour, cfg, seed)


def check_task(task, cfg: Config | None = None, seed: int = 0, n_envs: int = 3) -> None:
    """Check an RL reward task (:class:`~finkensim.envs.tasks.Task`) against its contract.

    On random worlds of ``n_envs`` environments stepped with random commands: ``reset`` returns None, ``reward``
    gives a finite float array of shape (B,) at every step, the same rewards for a second run of a fresh copy
    (deterministic), and the task pickles (vector environments may be sent to other processes).

    Parameters
    ----------
    task : Task
        An object with ``reset(ctx, pos)`` and ``reward(ctx, world)``.
    cfg : Config or None
        The scenario (default: the built-in one).
    seed : int
        Seed of the worlds and commands.
    n_envs : int
        Environments B per call.

    Raises
    ------
    PluginError
        Naming the failed check.
    """
    from .envs.tasks import Task, TaskContext
    from .world import World

    name = type(task).__name__
    if not isinstance(task, Task):
        raise PluginError(f"check_task({task!r}): expected an object with reset(ctx, pos) and reward(ctx, world)")
    try:
        fresh = pickle.dumps(task)
    except Exception as e:  # noqa: BLE001 — any pickling failure is the finding
        raise PluginError(f"{name}: does not pickle ({type(e).__name__}: {e})") from None
    cfg = cfg if cfg is not None else load_scenario(None)
    world = World(cfg)
    ctx = TaskContext((cfg.arena.width, cfg.arena.length), cfg.copters.radius, world.dt, cfg.copters.n)
    runs = []
    for t in (task, pickle.loads(fresh)):
        rng = np.random.default_rng(seed)
        state = world.init(n_envs=n_envs, seed=seed)
        if t.reset(ctx, state.pos.copy()) is not None:
            raise PluginError(f"{name}: reset returned a value (expected None)")
        rewards = []
        for _ in range(3):
            state = world.step(state, rng.uniform(-cfg.copters.max_speed, cfg.copters.max_speed,
                                                  (n_envs, cfg.copters.n, 2)))
            r = np.asarray(t.reward(ctx, state))
            if r.shape != (n_envs,) or r.dtype.kind != "f" or not np.isfinite(r).all():
                raise PluginError(f"{name}: reward gave {r!r}: expected finite floats of shape ({n_envs},)")
            rewards.append(r)
        runs.append(np.array(rewards))
    if not np.array_equal(*runs):
        raise PluginError(f"{name}: two runs from the same seed gave rewards {runs[0].tolist()} and "
                          f"{runs[1].tolist()} (expected deterministic rewards)")


def _effect_values(effect, fraction: float) -> dict:
    """Each parameter of ``effect`` at ``fraction`` of its range (integers rounded)."""
    return {p.name: (round(p.lo + fraction * (p.hi - p.lo)) if p.integer else p.lo + fraction * (p.hi - p.lo))
            for p in effect.params}


def _keys(model) -> dict:
    from .gap.model.params import SENSORS  # the sensors an effect may name

    return {sensor: model.sensor_key(sensor) for sensor in SENSORS}


def _check_effect_fit(name: str, fit) -> None:
    """An effect's own fit takes (objective, effect, current, values) positionally."""
    if not callable(fit):
        _fail(name, f"fit = {fit!r}: expected None or a callable fit(objective, effect, current, values) -> values")
    try:
        signature = inspect.signature(fit)
    except (TypeError, ValueError):
        return  # a builtin without a signature: nothing to judge
    try:
        signature.bind(None, None, None, None)
    except TypeError as e:
        _fail(name, f"fit{signature} cannot be called as fit(objective, effect, current, values) ({e}): expected "
                    "four positional parameters")


def check_effect(effect, cfg: Config | None = None) -> None:
    """Check an effect of the gap diagnosis against its contract (:class:`~finkensim.gap.attribute.effects.Effect`).

    Checked: a name, known sensors and parameters with finite bounds lo < hi; the starting values lie within the
    bounds (or at the neutral 0, or None where the base model leaves the quantity to the logs); at the starting values the model is the base model (neutral parameters change
    nothing); at the bounds and inside them ``apply`` returns a :class:`~finkensim.gap.model.params.ModelParams`, changes no
    sensor the effect does not name, leaves the base model as it was and gives the same model twice (pure); with a
    ``calibrate`` mapping, the config it writes flies the same model ``apply`` gives, for every named sensor; an own
    ``fit`` is callable as ``fit(objective, effect, current, values)``
    (:data:`~finkensim.gap.attribute.objective.EffectFit`), and a ``profiled`` effect has one.

    Parameters
    ----------
    effect : Effect
        The effect (registered or not).
    cfg : Config, optional
        The configuration whose model is the base (default: the default scenario's).

    Raises
    ------
    PluginError
        Naming the check that failed, the value and what was expected.
    """
    from .gap.attribute.effects import Effect
    from .gap.model.params import SENSORS, ModelParams

    if not isinstance(effect, Effect):
        raise PluginError(f"check_effect({effect!r}): expected a finkensim.gap.attribute.effects.Effect")
    name = f"effect {effect.name!r}"
    if not isinstance(effect.name, str) or not effect.name:
        _fail(name, "expected a non-empty name")
    unknown = [s for s in effect.sensors if s not in SENSORS]
    if not effect.sensors or unknown:
        _fail(name, f"sensors = {effect.sensors!r}: expected one or more of {SENSORS}")
    for prm in effect.params:
        if not (np.isfinite(prm.lo) and np.isfinite(prm.hi) and prm.lo < prm.hi):
            _fail(name, f"parameter {prm.name!r} has bounds [{prm.lo}, {prm.hi}]: expected finite lo < hi")
        if prm.log and not prm.lo > 0:
            _fail(name, f"parameter {prm.name!r} is searched on a geometric grid (log=True) from lo = {prm.lo}: "
                        "expected lo > 0")
    cfg = load_scenario() if cfg is None else cfg
    base = ModelParams.from_config(cfg)
    before = _keys(base)
    start = effect.start(base)
    for prm in effect.params:
        v = start.get(prm.name)
        # None: the base model leaves the quantity to the logs (pose_noise: each flight's stated tracking noise)
        if v is not None and not (prm.lo <= v <= prm.hi or v == 0.0):
            _fail(name, f"start value of {prm.name!r} is {v!r}: expected a value in [{prm.lo}, {prm.hi}] (or 0, "
                        "or None where the base model leaves it to the logs)")
    neutral = _keys(effect.apply(base, start))
    for sensor in SENSORS:
        if neutral[sensor] != before[sensor]:
            _fail(name, f"at its start values {start} the {sensor} model differs from the base model: expected "
                        "neutral start values to change nothing")
    for fraction in (0.0, 0.3, 0.75, 1.0):
        values = _effect_values(effect, fraction)
        try:
            model = effect.apply(base, values)
        except Exception as e:  # noqa: BLE001 - any failure of a user's apply is the contract broken
            _fail(name, f"apply at {values} raised {type(e).__name__}: {e}")
        if not isinstance(model, ModelParams):
            _fail(name, f"apply at {values} returned {type(model).__name__}: expected a ModelParams")
        if _keys(base) != before:
            _fail(name, f"apply at {values} changed the base model in place: expected a pure function")
        got = _keys(model)
        for sensor in SENSORS:
            if sensor not in effect.sensors and got[sensor] != before[sensor]:
                _fail(name, f"apply at {values} changed the {sensor} model, which the effect does not name "
                            f"(sensors = {effect.sensors})")
        if _keys(effect.apply(base, values)) != got:
            _fail(name, f"apply at {values} gave two different models: expected a pure function")
    if effect.fit is not None:
        _check_effect_fit(name, effect.fit)
    elif effect.profiled:
        _fail(name, "profiled = True without an own fit: expected a closed-form fit(objective, effect, current, "
                    "values) that joint searches can solve at each step")
    if effect.calibrate is not None:
        values = _effect_values(effect, 0.75)
        want = effect.apply(base, values)
        flown = ModelParams.from_config(cfg.replace(effect.calibrate(values, cfg)))
        for sensor in effect.sensors:
            if flown.sensor_key(sensor) != want.sensor_key(sensor):
                _fail(name, f"the config calibrate({values}) writes flies a different {sensor} model than apply "
                            "gives: expected the simulator to fly the fitted effect")
