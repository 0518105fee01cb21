"""Plug-ins: every registered behaviour and task passes its public checker, a toy behaviour added exactly as
docs/architecture.md's recipe says flies in the compiled engine, and the checkers catch broken plug-ins."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
from numba import njit

from finkensim.behaviours import BEHAVIOURS, Behaviour, register_behaviour
from finkensim.config import ConfigError
from finkensim.default_scenario import load_scenario
from finkensim.envs.tasks import TASKS
from finkensim.testing import PluginError, check_behaviour, check_task


@pytest.mark.parametrize("name", list(BEHAVIOURS))
def test_every_registered_behaviour_passes_its_checker(name):
    check_behaviour(BEHAVIOURS[name])


@pytest.mark.parametrize("name", list(TASKS))
def test_every_registered_task_passes_its_checker(name):
    check_task(TASKS[name]())


# --- docs/architecture.md, "Add a behaviour", literally ---------------------------------------------------------

class DriftParams(NamedTuple):
    speed: float  # m/s


def drift_params(cfg):
    return DriftParams(0.5 * cfg.copters.max_speed)


@njit
def drift_commands(inputs, params, memory, cmd_v, cmd_w):
    for n in range(cmd_v.shape[0]):
        blocked = inputs.sonar[n, 0] < 0.5           # front echo closer than 0.5 m
        cmd_v[n, 0] = 0.0 if blocked else params.speed
        cmd_v[n, 1] = 0.0
        cmd_w[n] = 0.0
        memory[n, 0] += 1.0                          # steps flown, kept across steps


DRIFT = Behaviour("drift", drift_commands, drift_params, frame="body", sensors=("sonar",), memory=1,
                  doc="fly forward at half the top speed, stop in front of an echo")


def test_a_toy_behaviour_added_as_the_recipe_says_flies_in_the_compiled_engine():
    from finkensim.swarm import SwarmSim

    register_behaviour(DRIFT, replace=True)
    try:
        check_behaviour(DRIFT)
        cfg = load_scenario(None).replace({"sonar.enabled": True})
        sim = SwarmSim(cfg, behaviour="drift")
        state = sim.init(n_envs=2, seed=0)
        final, rec = sim.rollout(state, 20, record=("pose", "cmd_vel"))
        np.testing.assert_array_equal(final.behaviour.commands[..., 0], 20.0)  # its memory, every step
        speed = np.hypot(rec.cmd_vel[..., 0], rec.cmd_vel[..., 1])
        assert np.isin(np.round(speed, 12), [0.0, 0.5 * cfg.copters.max_speed]).all()
        # the per-step Python path flies the same kernel: bit-identical
        final_py, rec_py = sim.rollout(state, 20, record=("pose", "cmd_vel"), python=True)
        np.testing.assert_array_equal(rec.pose, rec_py.pose)
        np.testing.assert_array_equal(final.behaviour.commands, final_py.behaviour.commands)
    finally:
        BEHAVIOURS.pop("drift", None)


def test_a_registered_behaviour_is_selectable_from_a_toml_config(tmp_path):
    """docs/architecture.md: once registered, the recipe's name is a valid behaviour.kind in a TOML file; unknown
    names are refused with the registered ones listed and a did-you-mean."""
    from finkensim.config import load_config
    from finkensim.swarm import SwarmSim

    toml = tmp_path / "drift.toml"
    toml.write_text('[behaviour]\nkind = "drift"      # SwarmSim(load_config("drift.toml")) flies DRIFT\n'
                    '[sonar]\nenabled = true      # the sensors it declares\n')
    with pytest.raises(ConfigError, match="behaviour.kind = 'drift': expected one of 'random_walk', 'hover', "
                                          "'attraction_repulsion'.*register_behaviour"):
        load_config(toml)  # not registered yet
    register_behaviour(DRIFT, replace=True)
    try:
        cfg = load_config(toml)
        assert cfg.behaviour.kind == "drift"
        sim = SwarmSim(cfg)
        assert sim.behaviour is DRIFT
        final, _ = sim.rollout(sim.init(n_envs=1, seed=0), 5, record=("pose",))
        np.testing.assert_array_equal(final.behaviour.commands[..., 0], 5.0)  # DRIFT's memory: it flew
        with pytest.raises(ConfigError, match=r"expected one of .*'drift'.*did you mean 'drift'\?"):
            load_config({"behaviour": {"kind": "drfit"}})
    finally:
        BEHAVIOURS.pop("drift", None)
    with pytest.raises(ConfigError, match="behaviour.kind = 'drift'"):
        load_config(toml)  # gone with it from the table


# --- the checkers catch broken plug-ins ---------------------------------------------------------------------------

@njit
def _too_fast(inputs, params, memory, cmd_v, cmd_w):
    for n in range(cmd_v.shape[0]):
        cmd_v[n, 0] = 1e3
        cmd_v[n, 1] = 0.0
        cmd_w[n] = 0.0


@njit
def _forgets_yaw(inputs, params, memory, cmd_v, cmd_w):
    for n in range(cmd_v.shape[0]):
        cmd_v[n, 0] = 0.0
        cmd_v[n, 1] = 0.0


@njit
def _undeclared_memory(inputs, params, memory, cmd_v, cmd_w):
    for n in range(cmd_v.shape[0]):
        memory[n, 0] += 1.0
        cmd_v[n, 0] = 0.0
        cmd_v[n, 1] = 0.0
        cmd_w[n] = 0.0


@pytest.mark.parametrize("kernel, message", [(_too_fast, "max_speed"), (_forgets_yaw, "unwritten"),
                                             (_undeclared_memory, "memory = 0")])
def test_check_behaviour_names_the_broken_contract(kernel, message):
    with pytest.raises(PluginError, match=message):
        check_behaviour(Behaviour("broken", kernel), fly=False)


def test_a_behaviour_is_refused_clearly():
    with pytest.raises(ConfigError, match="frame = 'up'"):
        Behaviour("x", drift_commands, frame="up")
    with pytest.raises(ConfigError, match="sensors = 'sonar'"):
        Behaviour("x", drift_commands, sensors="sonar")
    with pytest.raises(ConfigError, match="registered already"):
        register_behaviour(Behaviour("hover", drift_commands))


class _Unpicklable:
    def __init__(self):
        self.f = lambda: None

    def reset(self, ctx, pos):
        pass

    def reward(self, ctx, world):
        return np.zeros(world.pos.shape[0])


class _WrongShape:
    def reset(self, ctx, pos):
        pass

    def reward(self, ctx, world):
        return np.zeros(world.pos.shape[:2])


@pytest.mark.parametrize("task, message", [(_Unpicklable(), "pickle"), (_WrongShape(), "shape"),
                                           (object(), "reset")])
def test_check_task_names_the_broken_contract(task, message):
    with pytest.raises(PluginError, match=message):
        check_task(task)
