"""finkensim: fast simulator of FINken quadcopter swarms with realistic walls and sensors.

The public API, for notebooks (``import finkensim as fs``):

========================  ==================================================================================
``fs.load_config(src)``   a validated :class:`~finkensim.config.Config` from TOML (path or text), a dict, or
                          None for the defaults; ``fs.load_scenario()`` the embedded default scenario
``fs.World``              the arena and copter physics: pure ``step`` of a batched state (B environments)
``fs.SwarmSim``           the compiled closed loop: world + sensors + behaviour over B environments
``fs.simulate_flight``    one flight of the configured scenario as a :class:`FlightLog`
``fs.fly_recorded_poses`` a config's ranging flown along a log's recorded poses (e.g. a real flight's mocap)
``fs.run_episode``        one Monte-Carlo episode's metrics
``fs.FlightLog``          the flight-log record (``docs/formats/flightlog.md``); ``fs.load_log(path)`` reads one
``fs.run_sweep``          a Monte-Carlo sweep over a design (TOML), stored as Parquet, resumable
``fs.diagnose``           the sim-to-real gap of real logs: a :class:`~finkensim.gap.GapReport`
``fs.metrics``            swarm metrics (cohesion, wall contact, coverage …)
========================  ==================================================================================

Names are imported on first use, so ``import finkensim`` stays fast (it does not import numba). It chooses
numba's on-disk cache of compiled kernels, shared by every entry point (:mod:`finkensim.numba_cache`).
"""
from __future__ import annotations

from . import numba_cache as _numba_cache
from .lazy import lazy_exports as _lazy_exports

_numba_cache.configure()  # before any kernel module is imported

__version__ = "0.1.0"

_API = {
    "Config": "finkensim.config",
    "ConfigError": "finkensim.config",
    "load_config": "finkensim.config",
    "World": "finkensim.world",
    "SwarmSim": "finkensim.swarm",
    "load_scenario": "finkensim.scenario",
    "simulate_flight": "finkensim.scenario",
    "fly_recorded_poses": "finkensim.scenario",
    "run_episode": "finkensim.episode",
    "FlightLog": "finkensim.flightlog",
    "FlightLogError": "finkensim.flightlog",
    "load_log": ("finkensim.flightlog", "load"),
    "run_sweep": "finkensim.sweep",
    "diagnose": "finkensim.gap",
    "GapReport": "finkensim.gap",
}
_MODULES = ("metrics", "viz", "gap", "sweep", "flightlog", "config", "determinism")

__all__ = ["__version__", *_API, *_MODULES]


__getattr__, __dir__ = _lazy_exports(__name__, _API, _MODULES)
