"""The effect contract's public checker (finkensim.testing.check_effect): every catalogued effect of the gap
diagnosis through it, and broken effects caught with a named error. docs/architecture.md's "add an effect" recipe,
literally."""
from __future__ import annotations

import pytest

import finkensim.gap  # noqa: F401  (registers the whole catalogue, radio effects included)
from finkensim.gap import effects as fx
from finkensim.testing import PluginError, check_effect

@pytest.mark.parametrize("name", sorted(fx.REGISTRY))
def test_every_catalogued_effect_passes_its_checker(name):
    check_effect(fx.REGISTRY[name])


# --- docs/architecture.md, "Add an effect", literally ------------------------------------------------------------

from finkensim.gap.effects import Effect, Param, register  # noqa: E402

SONAR_OFFSET = Effect(
    name="sonar_offset_demo", sensors=("ultrasonic",),
    params=(Param("bias", -0.3, 0.3, unit="m"),),
    apply=lambda base, v: base.with_sonar(bias=base.sonar.bias + v["bias"]),
    doc="a constant offset on every sonar echo")


def test_the_recipe_effect_passes_and_registers():
    check_effect(SONAR_OFFSET)              # raises PluginError naming a broken contract
    try:
        register(SONAR_OFFSET)
        assert fx.REGISTRY["sonar_offset_demo"] is SONAR_OFFSET
    finally:
        fx.REGISTRY.pop("sonar_offset_demo", None)


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
    with pytest.raises(PluginError, match="expected a finkensim.gap.effects.Effect"):
        check_effect("wall_bulge")
