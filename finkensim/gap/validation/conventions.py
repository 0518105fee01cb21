"""How other tools and arenas record the same flight: the conventions axis of ``finkensim gap-validate``.

A real log differs from finkensim's own in ways that say nothing about the physics: the altitude flown,
where the sonars sit, how a lost echo is written down, the shape of the sonar noise, the logging rate,
the swarm size, the tracking system's noise. :class:`Conventions` describes one such combination;
:func:`draw_conventions` samples the axis; :meth:`Conventions.sim_updates` and :meth:`Conventions.record`
produce a log in those conventions from a simulated flight. This module is written apart from the
diagnosis on purpose: it uses the simulator and plain NumPy only, never the diagnosis's own models, so a
validation cannot pass because both sides share a mistake.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ...flightlog import FlightLog
from ...sensors.sonar_hold import held_steps

__all__ = ["Conventions", "draw_conventions", "DEFAULT_CONVENTIONS", "NO_ECHO", "NOISE"]

# max_range exactly; max_range + noise clipped; the value 0; NaN ("no reading", as docs/formats/flightlog.md allows)
NO_ECHO = ("exact", "noisy_clipped", "zero", "nan")
"""How a lost sonar echo may be logged: ``max_range`` exactly, ``max_range`` plus noise clipped, 0, or NaN."""
# the random axis of gap-validate (the three; "nan" is validated by tests and explicit runs, since adding it
# to the draw would change the conventions of every random trial of the matrices already measured)
NO_ECHO_DRAWN = NO_ECHO[:3]
"""The lost-echo conventions ``gap-validate`` draws from (NaN is tested but not drawn)."""
NOISE = ("rayleigh", "gaussian", "laplace")  # base sonar noise of the "real" readings (same σ)
"""Base sonar noise laws of the simulated "real" readings (same σ)."""


@dataclass(frozen=True)
class Conventions:
    """One way of recording a flight.

    altitude m; sonar_offset m (sonar distance from the copter centre); no_echo: one of :data:`NO_ECHO`;
    noise: one of :data:`NOISE` (Rayleigh and Gaussian as the simulator draws them; Laplace added here to
    the error-free readings with the same standard deviation as the Gaussian); rate_hz: logging rate (the
    simulation steps at it; the diagnosed config keeps its own dt); n_copters; tracking_sigma_xy m (declared in the log's meta; yaw noise
    2.5 × that in rad).
    """

    altitude: float = 0.6
    sonar_offset: float = 0.0
    no_echo: str = "exact"
    noise: str = "rayleigh"
    rate_hz: float = 20.0
    n_copters: int = 6
    tracking_sigma_xy: float = 0.002

    def __post_init__(self):
        if self.no_echo not in NO_ECHO:
            raise ValueError(f"no_echo = {self.no_echo!r}: expected one of {NO_ECHO}")
        if self.noise not in NOISE:
            raise ValueError(f"noise = {self.noise!r}: expected one of {NOISE}")

    @property
    def tracking_sigma_yaw(self) -> float:
        return 2.5 * self.tracking_sigma_xy

    def to_dict(self) -> dict:
        return asdict(self)

    def sim_updates(self) -> dict:
        """Simulator config updates that fly the flight this way (altitude, mounting, swarm, noise model)."""
        return {"arena.altitude": self.altitude, "sonar.offset": self.sonar_offset, "copters.n": self.n_copters,
                "simulation.dt": 1.0 / self.rate_hz,
                "sonar.error": {"rayleigh": "rayleigh", "gaussian": "gaussian", "laplace": "none"}[self.noise]}

    def diag_updates(self) -> dict:
        """What a user would configure for the diagnosis: the closest noise model finkensim has (Laplace →
        Gaussian of the same σ). Altitude, mounting and swarm size come from the log itself."""
        return {"sonar.error": "rayleigh" if self.noise == "rayleigh" else "gaussian"}

    def record(self, log: FlightLog, cfg, rng: np.random.Generator) -> None:
        """Write the sonar readings of ``log`` (simulated with :meth:`sim_updates`, with ideal extras) as a
        tool with these conventions would: Laplace noise on echoes, then the no-echo convention."""
        if log.ultrasonic is None:
            return
        sc = cfg.sonar
        echo = log.extras["ultrasonic_hit_type"] > 0
        y = log.ultrasonic
        # a sample-and-hold sonar holds its noise with its measurement: draws are indexed by the measuring sample
        held = (held_steps(np.arange(y.shape[0]), cfg.simulation.dt, sc.update_hz, 0.0)  # the simulator: from t = 0
                if sc.update_hz > 0 else slice(None))
        if self.noise == "laplace":
            b = sc.sigma / math.sqrt(2.0)  # Laplace(0, b) has standard deviation σ
            echo = echo[held]
            y = np.where(echo, np.clip(y + rng.laplace(0.0, b, y.shape)[held], sc.min_range, sc.max_range), y)
        lost = y >= sc.max_range  # the simulator's no-echo value (and echoes clipped to it, as a driver would)
        if self.no_echo == "noisy_clipped":
            y = np.where(lost, np.clip(sc.max_range + rng.normal(0.0, sc.sigma, y.shape)[held], sc.min_range,
                                       sc.max_range), y)
        elif self.no_echo == "zero":
            y = np.where(lost, 0.0, y)
        elif self.no_echo == "nan":
            y = np.where(lost, np.nan, y)
        log.ultrasonic = y


DEFAULT_CONVENTIONS = Conventions()
"""finkensim's own recording conventions (:class:`Conventions` with its defaults)."""


def draw_conventions(rng: np.random.Generator) -> Conventions:
    """A random point of the axis: altitude U(0.3, 1.2) m, sonar offset U(0, 0.12) m, no-echo convention (of
    :data:`NO_ECHO_DRAWN`),
    noise shape, rate U{10, 20, 25, 50} Hz, 3–10 copters, tracking noise U(0, 0.01) m."""
    return Conventions(altitude=round(float(rng.uniform(0.3, 1.2)), 3), sonar_offset=round(float(rng.uniform(0.0, 0.12)), 3),
                       no_echo=str(rng.choice(NO_ECHO_DRAWN)), noise=str(rng.choice(NOISE)),
                       rate_hz=float(rng.choice([10.0, 20.0, 25.0, 50.0])), n_copters=int(rng.integers(3, 11)),
                       tracking_sigma_xy=round(float(rng.uniform(0.0, 0.01)), 4))
