"""The default scenario: its embedded TOML text, the shipped file, and :func:`load_scenario`.

    from finkensim.default_scenario import load_scenario
    cfg = load_scenario()                 # 6 copters, random walk, 60 s in the 3 m x 4 m arena
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from .config import Config, load_config

__all__ = ["DEFAULT_SCENARIO_TOML", "default_scenario_path", "load_scenario"]

DEFAULT_SCENARIO_TOML = """\
# finkensim default scenario: 6 FINken copters on a bounded random walk for 60 s
# in the 3 m x 4 m SwarmLab arena, with Bernoulli curtain walls (16 plates per wall).
# Every key not given here takes its default; see finkensim.config for all keys.
profile = "default"

[arena]
width = 3.0       # m, x extent
length = 4.0      # m, y extent
altitude = 0.6    # m, flight height

[walls]
bending = true
n_segments = 16
threshold = 1.0           # m, copters closer than this pull a plate
max_amplitude_deg = 30.0  # deg, target = max_amplitude * f(x)

[copters]
n = 6
radius = 0.15     # m
max_speed = 1.0   # m/s

[behaviour]
kind = "random_walk"
speed = 0.3           # m/s cruise speed
redraw_steps = 20     # new random heading every 20 steps (1 s)
wall_margin = 0.4     # m, steer inward when closer to a wall
yaw_rate_deg = 20.0   # deg/s, largest random yaw-rate command

[simulation]
dt = 0.05         # s
duration = 60.0   # s
seed = 0
"""
"""The embedded default scenario (same text as ``finkensim/data/default_scenario.toml``)."""


def default_scenario_path() -> Path:
    """Path of the shipped copy of :data:`DEFAULT_SCENARIO_TOML` (``finkensim/data/default_scenario.toml``)."""
    return Path(str(resources.files("finkensim") / "data" / "default_scenario.toml"))


def load_scenario(source: str | Path | Mapping[str, Any] | Config | None = None) -> Config:
    """A scenario :class:`~finkensim.config.Config`, by default the embedded default scenario.

    Parameters
    ----------
    source : str, Path, Mapping, Config or None
        A TOML path, TOML text, a dict, a Config (returned as it is), or None for the embedded default scenario
        (:data:`DEFAULT_SCENARIO_TOML`).

    Returns
    -------
    Config
        The validated scenario.

    Raises
    ------
    ConfigError
        As :func:`~finkensim.config.load_config`.
    """
    if source is None:
        return load_config(DEFAULT_SCENARIO_TOML)
    if isinstance(source, Config):
        return source
    return load_config(source)
