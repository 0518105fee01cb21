"""Matplotlib figures and animations of the arena, its Bernoulli walls and the copters.

Everything here only draws: no state is changed and nothing is shown (no ``plt.show``), so it
works under the Agg backend, in scripts, notebooks and the CLI alike. Functions that create a
figure return it (and its axes) for the caller to save or display.

    fig, ax = plot_arena(world, state.pos[0], state.yaw[0], state.theta[0], trails=traj.pose[:, 0])
    fig, ax = plot_wall_response(world, traj)           # amplitude law + simulated plate angles
    animate(world, traj, path="flight.gif")              # small animated GIF (PillowWriter)
    fig, axes = plot_sensors(log, copter=0)              # sonar, ranging, IMU vs ideal values

``arena`` arguments accept an :class:`~finkensim.arena.Arena` or a :class:`~finkensim.world.World`;
with a World the copter radius comes from its config, with an Arena pass ``radius`` (default
0.15 m). ``traj`` arguments accept a :class:`~finkensim.world.Trajectory` (shapes (T, B, ...)) or a
:class:`~finkensim.flightlog.FlightLog` carrying the ``wall_theta`` extra written by
:func:`finkensim.scenario.simulate_flight`.

Modules: :mod:`.inputs` (argument handling, plate names), :mod:`.arena` (top view),
:mod:`.walls` (wall response, plate angles over time), :mod:`.animation` (GIF),
:mod:`.sensors` (sensor panels), :mod:`.png` (palette PNG). The numbers behind the figures
(cross-talk events, plate distances, binned statistics) are in :mod:`finkensim.analysis`;
:func:`peak_deflection_index` and :func:`sonar_crosstalk_events` are re-exported here.
"""
from __future__ import annotations

from ..analysis import peak_deflection_index, sonar_crosstalk_events
from .animation import animate
from .arena import plot_arena
from .inputs import WALL_NAMES, plate_label
from .png import save_png
from .sensors import SONAR_NAMES, plot_sensors
from .walls import plot_plate_timeseries, plot_wall_response

__all__ = [
    "WALL_NAMES",
    "plot_arena",
    "plot_wall_response",
    "plot_plate_timeseries",
    "animate",
    "peak_deflection_index",
    "plate_label",
    "plot_sensors",
    "save_png",
    "sonar_crosstalk_events",
    "SONAR_NAMES",
]
