"""The effect contract's public checker (finkensim.testing.check_effect): every catalogued effect of the gap
diagnosis through it, and broken effects caught with a named error. docs/architecture.md's "add an effect" recipe,
literally."""
from __future__ import annotations

import dataclasses

import pytest

import finkensim.gap  # noqa: F401  (registers the whole catalogue, radio effects included)
from finkensim.gap.attribute import effects as fx
from finkensim.config import load_config
from finkensim.testing import PluginError, check_effect

@pytest.mark.parametrize("name", sorted(fx.REGISTRY))
def test_every_catalogued_effect_passes_its_checker(name):
    check_effect(fx.REGISTRY[name])


@pytest.mark.parametrize("crosstalk", ["off", "constant"])
@pytest.mark.parametrize("name", sorted(fx.REGISTRY))
def test_every_catalogued_effect_passes_its_checker_on_a_base_without_geometric_crosstalk(name, crosstalk):
    """Neutral start values stay neutral on another base model too (crosstalk_geometric at probability 0 once set
    the firing schedule of a base without geometric cross-talk to simultaneous)."""
    check_effect(fx.REGISTRY[name], load_config().replace({"sonar.crosstalk": crosstalk}))


# --- docs/architecture.md, "Add an effect", literally ------------------------------------------------------------

from finkensim.gap.attribute.effects import Effect, Param, register  # noqa: E402

def best_of_a_grid(objective, effect, current, values):   # optional: the effect's own fit
    sensors = [s for s in effect.sensors if s in objective.tables]
    grid = [{"bias": b} for b in (-0.2, -0.1, 0.0, 0.1, 0.2)]
    return min(grid, key=lambda v: objective.objective(effect, current, sensors, v))

SONAR_OFFSET = Effect(
    name="sonar_offset_demo", sensors=("ultrasonic",),
    params=(Param("bias", -0.3, 0.3, unit="m"),),
    apply=lambda base, v: base.with_sonar(bias=base.sonar.bias + v["bias"]),
    doc="a constant offset on every sonar echo",
    fit=best_of_a_grid)                 # leave it out for the generic fit


def test_the_recipe_effect_passes_and_registers():
    check_effect(SONAR_OFFSET)              # raises PluginError naming a broken contract
    try:
        register(SONAR_OFFSET)
        assert fx.REGISTRY["sonar_offset_demo"] is SONAR_OFFSET
    finally:
        fx.REGISTRY.pop("sonar_offset_demo", None)


class _Objective:
    """The diagnosis as a fit sees it (FitObjective), with a training score that is least at a 0.1 m bias."""
    tables = {"ultrasonic": None}

    def objective(self, effect, current, sensors, values):
        assert sensors == ["ultrasonic"]
        return abs(values["bias"] - 0.1)


def test_the_diagnosis_fits_an_effect_with_its_own_fit():
    from finkensim.default_scenario import load_scenario
    from finkensim.gap.diagnosis import Diagnosis
    from finkensim.gap.model.params import ModelParams

    res = Diagnosis.fit(_Objective(), SONAR_OFFSET, ModelParams.from_config(load_scenario()))
    assert res.values == {"bias": 0.1} and res.score_train == 0.0


@pytest.mark.parametrize("fit, message", [
    (lambda objective, effect: {}, "four positional parameters"),
    ("grid", "expected None or a callable"),
])
def test_an_own_fit_that_cannot_be_called_as_documented_is_caught(fit, message):
    with pytest.raises(PluginError, match=message):
        check_effect(dataclasses.replace(SONAR_OFFSET, fit=fit))


def test_a_profiled_effect_without_an_own_fit_is_caught():
    check_effect(dataclasses.replace(SONAR_OFFSET, profiled=True))  # its own fit: profiled in joint searches
    with pytest.raises(PluginError, match="profiled = True without an own fit"):
        check_effect(dataclasses.replace(SONAR_OFFSET, fit=None, profiled=True))


def test_an_effect_that_changes_a_sensor_it_does_not_name_is_caught():
    sneaky = Effect("sneaky", ("ultrasonic",), (Param("bias", 0.0, 0.3),),
                    lambda base, v: base.with_(sigma_xy=v["bias"]) if v["bias"] else base)
    with pytest.raises(PluginError, match="does not name"):
        check_effect(sneaky)


def test_an_effect_that_is_not_neutral_at_its_start_is_caught():
    shifted = Effect("shifted", ("ultrasonic",), (Param("bias", 0.1, 0.3),),
                     lambda base, v: base.with_sonar(bias=base.sonar.bias + v["bias"]))
    with pytest.raises(PluginError, match="start values"):
        check_effect(shifted)


def test_bad_bounds_and_sensors_are_named():
    with pytest.raises(PluginError, match="finite lo < hi"):
        check_effect(Effect("bounds", ("ultrasonic",), (Param("x", 1.0, 0.0),), lambda b, v: b))
    with pytest.raises(PluginError, match="sensors"):
        check_effect(Effect("sonarz", ("sonar",), (Param("x", 0.0, 1.0),), lambda b, v: b))
    with pytest.raises(PluginError, match="expected a finkensim.gap.attribute.effects.Effect"):
        check_effect("wall_bulge")


def test_a_log_parameter_needs_a_positive_lower_bound_and_gets_a_geometric_grid():
    with pytest.raises(PluginError, match=r"log=True\) from lo = 0.0: expected lo > 0"):
        check_effect(Effect("logz", ("ranging",), (Param("x", 0.0, 1.0, log=True),), lambda b, v: b))
    assert Param("mean", 0.02, 1.5, log=True).grid(5) == pytest.approx([0.02, 0.0589, 0.1732, 0.5097, 1.5], rel=1e-3)
    assert Param("p", 0.0, 0.5).grid(5) == pytest.approx([0.0, 0.125, 0.25, 0.375, 0.5])
