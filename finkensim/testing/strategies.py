"""Hypothesis strategies that generate only valid finkensim objects, each with parameters to narrow it.

    from finkensim.testing import strategies as fst

    @given(fst.scenarios(max_copters=4), st.data())
    def test_my_behaviour(cfg, data):
        state = data.draw(fst.world_states(cfg))
        ...

=====================  ==========================================================================================
:func:`configs`        any :class:`~finkensim.config.Config` (keys in their declared ranges, combinations
                       ``finkensim run`` accepts)
:func:`scenarios`      small configs that fly in milliseconds
:func:`world_states`   a batched :class:`~finkensim.world.WorldState` for a config
:func:`sensor_models`  SonarModel / RangingModel / ImuModel built from a config
:func:`flight_logs`    ``spec/flightlog.md`` flights (missing readings, imported conventions)
:func:`recordings`     asynchronous recordings for the importer (:class:`RecordingCase`)
:func:`effects`        a catalogued gap effect with parameter values in its bounds
=====================  ==========================================================================================

Every range is read from the package's own declarations (config field metadata, effect bounds, the flight-log
validator's limits), never copied. The modules: :mod:`.configs`, :mod:`.models`, :mod:`.logs`.
"""
from __future__ import annotations

from .configs import SCENARIO_BOUNDS, SCENARIO_SECTIONS, config_toml, configs, field_values, scenarios, toml_value
from .logs import LOG_SENSORS, NO_ECHO, RecordingCase, flight_logs, recordings
from .models import SENSOR_KINDS, effects, sensor_models, world_states

__all__ = ["configs", "scenarios", "field_values", "config_toml", "toml_value", "world_states", "sensor_models", "effects", "flight_logs",
           "recordings", "RecordingCase", "SCENARIO_BOUNDS", "SCENARIO_SECTIONS", "SENSOR_KINDS", "LOG_SENSORS",
           "NO_ECHO"]
