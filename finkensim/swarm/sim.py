"""The Python API of the closed swarm loop: :class:`SwarmSim` (see :mod:`finkensim.swarm` for the contract)."""
from __future__ import annotations

import threading
from typing import Any, Callable, Iterable

import numpy as np

from ..behaviours.attraction import AttractionParams, body_to_world
from ..behaviours.open_loop import OPEN_LOOP_BEHAVIOURS
from ..behaviours.random_walk import RandomWalkParams
from ..behaviours.registry import BEHAVIOURS, Behaviour, BehaviourInput, get_behaviour
from ..behaviours.wall_check import WALL_CHECK_NONE, WALL_CHECK_SEQUENCE, BehaviourState, WallCheckParams, \
    dead_reckon, wall_check
from ..config import Config, ConfigError, load_config
from ..sensors.imu import ImuModel, imu_step
from ..sensors.latency import LAG_IMU, LAG_RANGING, LAG_SONAR, delay_batch, delay_buffer, sensor_lags
from ..sensors.ranging import RangingModel, ranging_readings
from ..sensors.sonar_hold import hold_env
from ..sensors.sonar import N_SONARS, SonarModel, down_readings, sonar_readings
from ..world import World
from ..kernels.cellgrid import engine_grid
from .kernel import swarm_rollout
from .state import NO_RANGING_ROWS, RECORDABLE, SENSOR_OF, Models, SensorReadings, SwarmRecord, \
    SwarmState, concat_records, kernel_record, run_spec

__all__ = ["SwarmSim", "needs_sensors", "check_behaviour_sensors"]


def needs_sensors(kind) -> bool:
    """True when ``behaviour.kind`` (a registered behaviour's name, a :class:`~finkensim.behaviours.Behaviour` or a
    Python behaviour function) is a closed-loop controller that reads sensors; False for open-loop ones such as
    ``"random_walk"`` and ``"hover"``.

    Parameters
    ----------
    kind : str, Behaviour or callable
        The behaviour.

    Returns
    -------
    bool
        Whether it reads sensors.
    """
    if isinstance(kind, Behaviour) or (isinstance(kind, str) and kind in BEHAVIOURS):
        return bool(get_behaviour(kind).sensors)
    return callable(kind) or kind not in OPEN_LOOP_BEHAVIOURS


_SENSOR_KEYS = {"sonar": "sonar.enabled", "down": "sonar.down_enabled", "ranging": "ranging.enabled",
                "imu": "imu.enabled"}


def _require_sensors(behaviour, wall_check_mode: int, enabled: dict, wall_check: str) -> None:
    """Raise ConfigError if the behaviour (a :class:`~finkensim.behaviours.Behaviour` or None for a Python function)
    or its wall check needs a sensor that is not ``enabled`` (sensor name -> bool)."""
    for sensor in (behaviour.sensors if behaviour is not None else ()):
        if not enabled[sensor]:
            raise ConfigError(f"behaviour.kind = {behaviour.name!r} needs {_SENSOR_KEYS[sensor]} = true")
    if wall_check_mode != WALL_CHECK_NONE:
        need = [("sonar.enabled", enabled["sonar"]), ("ranging.enabled", enabled["ranging"])]
        if wall_check_mode == WALL_CHECK_SEQUENCE:
            need.append(("imu.enabled", enabled["imu"]))
        for key, ok in need:
            if not ok:
                raise ConfigError(f"behaviour.wall_check = {wall_check!r} needs {key} = true")


def check_behaviour_sensors(cfg: Config, sensors: bool = True) -> None:
    """Raise ConfigError if ``behaviour.kind`` or ``behaviour.wall_check`` of ``cfg`` needs a sensor that ``cfg``
    disables: the check ``SwarmSim(cfg, sensors=sensors)`` makes, without building the models (cheap, for study
    and sweep files)."""
    enabled = {"sonar": bool(cfg.sonar.enabled), "ranging": bool(cfg.ranging.enabled), "imu": bool(cfg.imu.enabled)}
    mode = WallCheckParams.from_config(cfg).mode if sensors else WALL_CHECK_NONE
    enabled["down"] = bool(cfg.sonar.enabled and cfg.sonar.down_enabled)
    kind = cfg.behaviour.kind
    _require_sensors(BEHAVIOURS.get(kind), mode, enabled, cfg.behaviour.wall_check)


class SwarmSim:
    """A configured swarm: world, sensor models and behaviour, with compiled and per-step stepping.

    Parameters
    ----------
    cfg : Config, str, dict or None
        A :class:`~finkensim.config.Config`, a TOML path or text, a dict, or None for the defaults.
    behaviour : str, Behaviour, callable or None
        None (``behaviour.kind`` from the config), the name of a registered behaviour (``"hover"``,
        ``"random_walk"``, ``"attraction_repulsion"`` or one added with
        :func:`~finkensim.behaviours.register_behaviour`), a :class:`~finkensim.behaviours.Behaviour` (flown in the
        compiled engine), or a Python function ``f(readings, memory, params) -> (cmd_vel, cmd_yaw_rate)`` with
        cmd_vel (B, N, 2) m/s and cmd_yaw_rate (B, N) rad/s or None (module doc).
    params : object, optional
        The ``params`` passed to a Python behaviour (default ``cfg.behaviour``), or a registered behaviour's
        parameter record (default ``behaviour.params(cfg)``).
    command_frame : str
        ``"body"`` (default) or ``"world"``: the frame of a Python behaviour's velocity commands.
    memory_factory : callable, optional
        ``(n_envs, n_copters) -> object``, a Python behaviour's initial memory.
    sensors : bool
        False runs no sensor at all (only for the open-loop ``"random_walk"`` and ``"hover"``, which read
        none): faster when only the flight matters; the IMU bias and behaviour memory of the state then stay
        as they are.

    Attributes
    ----------
    world : World
        The physics (:class:`~finkensim.world.World`).
    sonar, ranging, imu
        The sensor records (``SonarModel``, ``RangingModel``, ``ImuModel``).
    attraction, wall_check, random_walk
        The behaviour records (``AttractionParams``, ``WallCheckParams``, ``RandomWalkParams``).
    beacons : ndarray, shape (M, 2)
        Fixed ranging beacons, m.
    kind : str or callable
        The behaviour (its name, or the Python function).
    behaviour : Behaviour or None
        The registered behaviour flown in the compiled engine (None for a Python function).
    enabled : dict
        Sensor name → whether it runs.
    """

    def __init__(self, cfg: Config | str | dict | None = None, behaviour: str | Callable | None = None,
                 params: Any = None, command_frame: str = "body", memory_factory: Callable | None = None,
                 sensors: bool = True):
        self.cfg = cfg if isinstance(cfg, Config) else load_config(cfg)
        c = self.cfg
        self.world = World(c)
        self.dt = self.world.dt
        self.sonar = SonarModel.from_config(c)
        self.ranging = RangingModel.from_config(c.ranging)
        self.imu = ImuModel.from_config(c.imu, self.dt)
        self.attraction = AttractionParams.from_config(c)
        self.wall_check = WallCheckParams.from_config(c)
        self.random_walk = RandomWalkParams.from_config(c.behaviour, c.arena.width, c.arena.length)
        self.beacons = np.ascontiguousarray(np.asarray(c.ranging.beacons, dtype=np.float64).reshape(-1, 2))
        kind = c.behaviour.kind if behaviour is None else behaviour
        self.behaviour = None if callable(kind) and not isinstance(kind, Behaviour) else get_behaviour(kind)
        self.kind = self.behaviour.name if self.behaviour is not None else kind
        if command_frame not in ("body", "world"):
            raise ConfigError(f"command_frame = {command_frame!r}: expected 'body' or 'world'")
        self.command_frame = command_frame
        if self.behaviour is None:
            self.params = c.behaviour if params is None else params
        else:
            self.params = self.behaviour.params(c) if params is None else params
        self.memory_factory = memory_factory
        self.enabled = {"sonar": bool(c.sonar.enabled), "down": bool(c.sonar.enabled and c.sonar.down_enabled),
                        "ranging": bool(c.ranging.enabled), "imu": bool(c.imu.enabled)}
        if not sensors:
            if needs_sensors(kind):
                raise ConfigError(f"sensors = False: behaviour {getattr(kind, '__name__', kind)!r} reads sensors; "
                                  f"expected one of {', '.join(map(repr, OPEN_LOOP_BEHAVIOURS))}")
            self.enabled = dict.fromkeys(self.enabled, False)
        _require_sensors(self.behaviour, self.wall_check.mode if sensors else WALL_CHECK_NONE, self.enabled,
                         c.behaviour.wall_check)
        #: sonar, ranging, IMU latency in steps (:mod:`finkensim.sensors.latency`; 0 for a sensor that is off)
        self.lags = sensor_lags(*(getattr(c, s).latency if self.enabled[s] else 0.0 for s in ("sonar", "ranging", "imu")),
                                self.dt)
        self._work = threading.local()  # per thread: the compiled rollout's ranging rows, kept between calls

    def __getstate__(self):
        # the kept ranging rows are a per-thread cache: a copy (pickle, deepcopy) starts without them
        return {k: v for k, v in self.__dict__.items() if k != "_work"}

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._work = threading.local()

    @property
    def n_copters(self) -> int:
        """Copters per environment, N (``copters.n``)."""
        return self.cfg.copters.n

    def _rollout_parts(self, state, n_steps, record, python, label):
        import sys

        from tqdm import tqdm

        from ..compiletime import compiling_notice

        part = max(1, n_steps // 100)
        records = []
        with tqdm(total=n_steps, desc=label, unit="step", file=sys.stderr) as bar, compiling_notice(bar):
            for k0 in range(0, n_steps, part):
                k = min(part, n_steps - k0)
                state, rec = self.rollout(state, k, record, python)
                records.append(rec)
                bar.update(k)
        return state, concat_records(records)

    def recordable(self) -> tuple[str, ...]:
        """Names :meth:`rollout` can record with this config.

        Returns
        -------
        tuple of str
            The names of :data:`RECORDABLE` whose sensor is enabled.
        """
        return tuple(name for name in RECORDABLE if name not in SENSOR_OF or self.enabled[SENSOR_OF[name]])

    def init(self, n_envs: int | None = None, seed: int | None = None, env_ids=None, positions=None, yaw=None,
             memory: Any = None) -> SwarmState:
        """Initial state: the world's, zero IMU bias, empty behaviour memory (dead reckoning at 0, no flags).

        Parameters
        ----------
        n_envs, seed, env_ids, positions, yaw
            As :meth:`World.init <finkensim.world.World.init>`: number of environments B, random seed, global
            environment indices (B,), copter centres (B, N, 2) m, headings (B, N) rad.
        memory : object, optional
            A Python behaviour's initial memory (default: ``memory_factory(B, N)``, or an empty dict).

        Returns
        -------
        SwarmState
            The state at step 0.
        """
        ws = self.world.init(n_envs=n_envs, seed=seed, env_ids=env_ids, positions=positions, yaw=yaw)
        B, N = ws.n_envs, ws.n_copters
        if memory is None:
            memory = self.memory_factory(B, N) if self.memory_factory is not None else {}
        width = self.behaviour.memory if self.behaviour is not None else 0
        behaviour = BehaviourState.zeros(B, N, N_SONARS, memory=width)._replace(
            sensor_delay=delay_buffer(self.lags, B, N, N + self.beacons.shape[0]))
        return SwarmState(world=ws, imu_bias=np.zeros((B, N, 3)), behaviour=behaviour, memory=memory)

    def models(self) -> Models:
        """Every model the compiled engine reads, as one record.

        Returns
        -------
        Models
            The copter, hinge, wall geometry, sonar, ranging (+ beacons), IMU and wall-check records.
        """
        w = self.world
        return Models(w.copter_params, w.hinge_params, w.geometry, self.sonar, self.ranging.params, self.beacons,
                      self.imu, self.wall_check)

    # -- one step through the batched functions (the reference path; also runs Python behaviours) --

    def sense(self, state: SwarmState) -> tuple[SensorReadings, np.ndarray, BehaviourState]:
        """Sensor readings of ``state`` (at its step); ``state`` is unchanged.

        Parameters
        ----------
        state : SwarmState
            The current state.

        Returns
        -------
        readings : SensorReadings
            Every enabled sensor's readings (sonar (B, N, 4) m, ranging (B, N, R) m, IMU, wall flags).
        imu_bias : ndarray, shape (B, N, 3)
            The advanced IMU bias (new array).
        behaviour : BehaviourState
            The advanced behaviour memory (new arrays).
        """
        return self._sense(state)[:3]

    def _sense(self, state: SwarmState):
        """:meth:`sense` plus the sonars' ideal distances and hit types ((B, N, 4) each; None, None when off)."""
        ws = state.world
        k, seed, env_ids = ws.step, ws.seed, ws.env_ids
        B, N = ws.n_envs, ws.n_copters
        on = self.enabled
        sonar = ideal = hit = None
        if on["sonar"]:
            sonar, ideal, hit, _ = sonar_readings(ws.pos, ws.yaw, ws.theta, self.world.arena, self.sonar, seed,
                                                       env_ids, k, return_ideal=True, bulge=ws.bulge)
        down = down_readings(ws.pos, self.sonar, seed, env_ids, k) if on["down"] else None
        ranging = ranging_readings(ws.pos, self.beacons, seed, env_ids, k, self.ranging, yaw=ws.yaw) if on["ranging"] else None
        bias = state.imu_bias.copy()
        mem = state.behaviour.copy()
        if on["sonar"] and self.sonar.update_hz > 0.0:
            for b in range(B):
                hold_env(sonar[b], mem.sonar_held[b], k, self.dt, self.sonar.update_hz, self.sonar.update_phase)
        R = N + self.beacons.shape[0]
        self._check_delay(mem.sensor_delay, B, N)
        if on["sonar"]:
            delay_batch(sonar, mem.sensor_delay, self.lags, LAG_SONAR, k, R)
        if on["ranging"]:
            delay_batch(ranging, mem.sensor_delay, self.lags, LAG_RANGING, k, R)
        imu_acc = imu_gyro = None
        if on["imu"]:
            imu_acc, imu_gyro = imu_step(ws.acc, ws.yaw, ws.yaw_rate, bias, self.imu, seed, env_ids, k)
            delay_batch(imu_acc, mem.sensor_delay, self.lags, LAG_IMU, k, R)
            delay_batch(imu_gyro, mem.sensor_delay, self.lags, LAG_IMU, k, R, offset=2)
            dead_reckon(imu_acc, imu_gyro, mem, self.wall_check)
        if on["sonar"]:
            ranging_in = ranging if ranging is not None else np.zeros((B, N, N + self.beacons.shape[0]))
            wall = wall_check(sonar, ranging_in, self.wall_check, mem)
        else:
            wall = mem.wall.copy()
        readings = SensorReadings(sonar=sonar, sonar_down=down, ranging=ranging, imu_acc=imu_acc, imu_gyro=imu_gyro,
                                  wall=wall, step=k, dt=self.dt, seed=seed, env_ids=env_ids.copy())
        return readings, bias, mem, ideal, hit

    def _check_delay(self, buf: np.ndarray, B: int, N: int) -> None:
        """Raise ConfigError unless ``buf`` is the latency ring buffer this sim's :meth:`init` makes for B × N."""
        want = delay_buffer(self.lags, 1, N, N + self.beacons.shape[0]).shape[1:]
        if buf.shape != (B,) + want:
            raise ConfigError(f"state.behaviour.sensor_delay has shape {buf.shape}: expected {(B,) + want}, the "
                              "latency buffer of this SwarmSim's init (sonar/ranging/imu.latency = "
                              f"{tuple(int(x) for x in self.lags)} steps)")

    def commands(self, state: SwarmState, readings: SensorReadings) -> tuple[np.ndarray, np.ndarray]:
        """The behaviour's commands for ``state`` given its readings.

        Parameters
        ----------
        state : SwarmState
            The current state.
        readings : SensorReadings
            The readings of ``state`` (from :meth:`sense`).

        Returns
        -------
        cmd_vel : ndarray, shape (B, N, 2)
            Velocity commands in the world frame, m/s.
        cmd_yaw_rate : ndarray, shape (B, N)
            Yaw-rate commands, rad/s.
        """
        return self._commands(state, readings, state.behaviour.copy())

    def _commands(self, state: SwarmState, readings: SensorReadings, memory: BehaviourState):
        """:meth:`commands` with the behaviour's memory ``memory.commands`` (B, N, W) advanced in place."""
        ws = state.world
        B, N = ws.n_envs, ws.n_copters
        beh = self.behaviour
        if beh is not None:  # a registered behaviour: its compiled commands, environment by environment
            v = np.zeros((B, N, 2))
            w = np.zeros((B, N))
            R = N + self.beacons.shape[0] if self.enabled["sonar"] and self.wall_check.mode != WALL_CHECK_NONE else 0
            absent = {"sonar": np.full((B, N, N_SONARS), self.sonar.max_range), "sonar_down": np.zeros((B, N)),
                      "ranging": np.zeros((B, N, R)), "imu_acc": np.zeros((B, N, 2)), "imu_gyro": np.zeros((B, N))}
            seen = {k: getattr(readings, k) if getattr(readings, k) is not None else a for k, a in absent.items()}
            for b in range(B):
                inputs = BehaviourInput(ws.pos[b], ws.yaw[b], seen["sonar"][b], readings.wall[b],
                                        seen["sonar_down"][b], seen["ranging"][b], seen["imu_acc"][b],
                                        seen["imu_gyro"][b], int(ws.seed), int(ws.env_ids[b]), int(ws.step),
                                        float(self.dt))
                beh.commands(inputs, self.params, memory.commands[b], v[b], w[b])
            return (body_to_world(ws.yaw, v) if beh.frame == "body" else v), w
        out = self.kind(readings, state.memory, self.params)
        if not isinstance(out, tuple) or len(out) != 2:
            raise ConfigError(f"behaviour {getattr(self.kind, '__name__', self.kind)!r} returned "
                              f"{type(out).__name__}: expected a tuple (cmd_vel (B, N, 2) m/s, cmd_yaw_rate (B, N) "
                              "rad/s or None)")
        v, w = out
        v, w = self.world.check_commands(ws, v, w)
        if self.command_frame == "body":
            v = body_to_world(ws.yaw, v)
        return v, w

    def step(self, state: SwarmState) -> tuple[SwarmState, SensorReadings, tuple[np.ndarray, np.ndarray]]:
        """One closed-loop step through the batched functions.

        Pure for the arrays (``state`` is left unchanged); a Python behaviour may mutate ``state.memory``,
        which the new state shares.

        Parameters
        ----------
        state : SwarmState
            The current state.

        Returns
        -------
        new_state : SwarmState
            The state one step later.
        readings : SensorReadings
            The readings the behaviour acted on.
        commands : tuple of ndarray
            ``(cmd_vel (B, N, 2) m/s, cmd_yaw_rate (B, N) rad/s)``, world frame.
        """
        return self._step(state)[:3]

    def _step(self, state: SwarmState):
        """:meth:`step` plus the sonars' ideal distances and hit types of :meth:`_sense`."""
        readings, bias, mem, ideal, hit = self._sense(state)
        cmd_v, cmd_w = self._commands(state, readings, mem)
        ws = self.world.step(state.world, cmd_v, cmd_w)
        new = SwarmState(world=ws, imu_bias=bias, behaviour=mem, memory=state.memory)
        return new, readings, (cmd_v, cmd_w), ideal, hit

    # -- many steps --

    def _record_names(self, record) -> tuple[str, ...]:
        avail = self.recordable()
        if record is True:
            return avail
        if record is False or record is None:
            return ()
        names = (record,) if isinstance(record, str) else tuple(record)
        for name in names:
            if name not in RECORDABLE:
                raise ConfigError(f"record: unknown name {name!r}; expected True, False or names from "
                                  f"{', '.join(RECORDABLE)}")
            if name not in avail:
                raise ConfigError(f"record: {name!r} is not available because its sensor is disabled "
                                  f"({SENSOR_OF[name]})")
        return names

    def rollout(self, state: SwarmState, n_steps: int, record: bool | str | Iterable[str] = True,
                python: bool = False, progress: bool | str = False) -> tuple[SwarmState, SwarmRecord]:
        """Run ``n_steps`` closed-loop steps; ``state`` is unchanged.

        Built-in behaviours run in one compiled kernel; a Python behaviour (or ``python=True``) loops over
        :meth:`step`.

        Parameters
        ----------
        state : SwarmState
            The initial state (from :meth:`init`).
        n_steps : int
            Number of steps T (≥ 0).
        record : bool, str or iterable of str
            True (everything available), False (only the per-episode counters), or names from
            :data:`RECORDABLE` (``"pose"``, ``"sonar"``, …).
        python : bool
            Loop over :meth:`step` in Python even for a built-in behaviour (the reference path).
        progress : bool or str
            A progress bar on stderr (a string: its label); the rollout then runs in about 100 consecutive
            parts, with results identical to one part.

        Returns
        -------
        final : SwarmState
            The state after ``n_steps`` steps.
        record : SwarmRecord
            The recorded arrays, each shaped (T, B, N, ...) (e.g. ``pose`` (T, B, N, 3): x m, y m, yaw rad),
            recorded before each step, and the per-episode counters.
        """
        if not isinstance(n_steps, (int, np.integer)) or isinstance(n_steps, bool) or n_steps < 0:
            raise ConfigError(f"n_steps = {n_steps!r}: expected a non-negative integer")
        if progress and n_steps > 1:
            return self._rollout_parts(state, int(n_steps), record, python,
                                       progress if isinstance(progress, str) else "rollout")
        names = self._record_names(record)
        T = int(n_steps)
        ws0 = state.world
        B, N, S, R = ws0.n_envs, ws0.n_copters, self.world.arena.n_plates, ws0.n_copters + self.beacons.shape[0]
        shapes = {"pose": (B, N, 3), "vel": (B, N, 2), "acc": (B, N, 2), "yaw_rate": (B, N), "theta": (B, S),
                  "sonar": (B, N, N_SONARS), "sonar_ideal": (B, N, N_SONARS), "sonar_hit": (B, N, N_SONARS),
                  "sonar_down": (B, N), "ranging": (B, N, R), "imu_acc": (B, N, 2), "imu_gyro": (B, N),
                  "wall": (B, N, N_SONARS), "cmd_vel": (B, N, 2), "cmd_yaw_rate": (B, N)}
        dtypes = {"wall": np.bool_, "sonar_hit": np.int64}
        rec = {name: np.zeros(((T if name in names else 0),) + shapes[name], dtype=dtypes.get(name, np.float64))
               for name in RECORDABLE}
        if self.behaviour is None or python:
            new = self._python_rollout(state, T, names, rec)
        else:
            new = state.copy()
            w = new.world
            run = run_spec(w, T, self.dt, tuple(self.enabled[s] for s in ("sonar", "down", "ranging", "imu")),
                           self._ranging_rows(B, N, R) if self.enabled["ranging"] else NO_RANGING_ROWS, self.lags, R)
            self._check_delay(new.behaviour.sensor_delay, B, N)
            swarm_rollout(new.for_kernels(), run, kernel_record(rec), self.models(),
                          engine_grid(self.world.grid, w.n_envs, w.n_copters), self.behaviour, self.params)
            new = new._replace(world=w._replace(step=w.step + T))
        counters = {
            "collisions": new.world.collisions - ws0.collisions,
            "wall_contacts": new.world.wall_contacts - ws0.wall_contacts,
            "wall_onsets": new.behaviour.wall_onsets - state.behaviour.wall_onsets,
            "wall_readings": new.behaviour.wall_readings - state.behaviour.wall_readings,
        }
        out = {name: rec[name] for name in names}
        return new, SwarmRecord(t=(ws0.step + np.arange(T)) * self.dt, counters=counters, **out)

    def _ranging_rows(self, B: int, N: int, R: int) -> np.ndarray:
        """The (B, N, R) work buffer of the compiled rollout's ranging rows, kept for the next rollout of the same
        shape on this thread (a progress bar's parts, Monte-Carlo chunks): fresh pages would be zeroed by the
        operating system on first touch, ≈ 0.2 s per call for the 800 MB of one environment of 10 000 copters. Its
        contents are never read before the rollout writes them, so reuse changes no result."""
        rows = getattr(self._work, "ranging_rows", None)
        if rows is None or rows.shape != (B, N, R):
            self._work.ranging_rows = None  # the old buffer goes before the new one is allocated
            rows = self._work.ranging_rows = np.empty((B, N, R))
        return rows

    def _python_rollout(self, state: SwarmState, T: int, names, rec: dict) -> SwarmState:
        """T steps through :meth:`step`, filling ``rec[name][t]`` for the recorded ``names``."""
        new = state
        for t in range(T):
            ws = new.world
            before = (("pose", ws.pose), ("vel", ws.vel), ("acc", ws.acc), ("yaw_rate", ws.yaw_rate),
                      ("theta", ws.theta))
            new, readings, (cmd_v, cmd_w), ideal, hit = self._step(new)
            for name, value in before + (
                    ("sonar", readings.sonar), ("sonar_ideal", ideal), ("sonar_hit", hit),
                    ("sonar_down", readings.sonar_down), ("ranging", readings.ranging),
                    ("imu_acc", readings.imu_acc), ("imu_gyro", readings.imu_gyro), ("wall", readings.wall),
                    ("cmd_vel", cmd_v), ("cmd_yaw_rate", cmd_w)):
                if name in names:
                    rec[name][t] = value
        return state.copy() if T == 0 else new
