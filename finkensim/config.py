"""Configuration: frozen dataclasses with defaults for everything, loaded from TOML.

Every field carries metadata (unit, allowed range or choices, one line of doc). The same validator runs when a
dataclass is built in Python and when a TOML file is loaded, so a wrong key, type or range is always a
:class:`ConfigError` naming the key, the value and what is allowed. Unknown keys are errors with a "did you mean"
suggestion. Units are SI (m, s, rad, kg) except fields whose name ends in ``_deg`` (degrees, converted by the
models). ``profile = "seed"`` switches every model to the behaviour described in the original V-REP report (see
``docs/user-guide/``); keys given explicitly still override the profile.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from .configfields import BEHAVIOUR_KINDS, ConfigError, Section as _Section, describe_range, field_spec as _f
from .usertext import loads_toml, suggest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True)
class ArenaConfig(_Section):
    """The flight arena: a rectangle with its origin at one corner."""

    _section = "arena"
    width: float = _f(3.0, "m", 0.5, 1000.0, doc="x extent")
    length: float = _f(4.0, "m", 0.5, 1000.0, doc="y extent")
    altitude: float = _f(0.6, "m", 0.05, 5.0, doc="fixed flight height of every copter")


@dataclass(frozen=True)
class WallConfig(_Section):
    """Curtain walls as hinged plates pulled toward passing copters (Bernoulli)."""

    _section = "walls"
    bending: bool = _f(True, doc="false = rigid walls (plates never move)")
    n_segments: int = _f(16, "", 1, 1000, doc="hinged plates per wall")
    threshold: float = _f(1.0, "m", 0.0, 10.0, lo_open=True, doc="copter distance below which the plate is pulled")
    max_amplitude_deg: float = _f(30.0, "deg", 0.0, 80.0, doc="target angle scale; target = max_amplitude * f(x)")
    pid_p: float = _f(1.0, "N m/rad", 0.0, 1e6)
    pid_i: float = _f(2.0, "N m/(rad s)", 0.0, 1e6)
    pid_d: float = _f(1.0, "N m s/rad", 0.0, 1e6)
    joint_force: float = _f(15.0, "N m", 0.0, 1e6, doc="hinge motor torque limit")
    friction: float = _f(3.0, "N m s/rad", 0.0, 1e6, doc="viscous hinge friction while the motor is off")
    plate_mass: float = _f(0.3, "kg", 0.0, 1e4, lo_open=True, doc="light curtain strip; the report's 40 kg cannot reach 30 deg")
    plate_length: float = _f(1.0, "m", 0.0, 10.0, lo_open=True, doc="hinge to lower edge")
    plate_thickness: float = _f(0.05, "m", 0.0, 1.0)
    plate_width_fraction: float = _f(0.9, "", 0.0, 1.0, lo_open=True, doc="plate width as a fraction of the segment pitch")
    hinge_height: float = _f(1.0, "m", 0.0, 20.0, lo_open=True, doc="height of the horizontal hinge above the floor")
    substeps: int = _f(10, "", 1, 1000, doc="hinge integration substeps per world step")
    model: str = _f("hinge", choices=("hinge", "bulge", "hinge+bulge"),
                    doc="what moves the plates: the hinge (plates pulled toward passing copters), the curtain bulge "
                        "(each plate displaced toward the arena by bulge_amplitude * exp(-(d/bulge_reach)^bulge_shape), d "
                        "its distance to the nearest copter body, followed with time constant bulge_response; the gap "
                        "effect wall_bulge fits it), or both")
    bulge_amplitude: float = _f(0.0, "m", -0.5, 1.0, doc="curtain bulge: displacement of a plate touching a copter")
    bulge_reach: float = _f(0.3, "m", 0.01, 5.0, doc="curtain bulge: distance scale of the displacement")
    bulge_shape: float = _f(2.0, "", 0.2, 50.0, doc="curtain bulge: 2 a Gaussian, larger a flat bulge ending sharply "
                            "near bulge_reach")
    bulge_response: float = _f(0.0, "s", 0.0, 10.0, doc="curtain bulge: first-order time constant of the plates "
                               "following it (0: at once)")
    bulge_hinge: float = _f(0.0, "", 0.0, 1.0, doc="curtain bulge: weight of the hinge's amplitude law f(1 - d/bulge_reach)/f(1) blended into its target (0: the exponential law alone)")

    def _check(self):
        if self.plate_length > self.hinge_height:
            raise ConfigError(
                f"walls.plate_length = {self.plate_length!r}: expected <= walls.hinge_height = {self.hinge_height!r} m "
                "(the plate would reach below the floor)"
            )


@dataclass(frozen=True)
class CopterConfig(_Section):
    """Kinematic copters at fixed altitude."""

    _section = "copters"
    n: int = _f(6, "", 1, 100000, doc="copters per environment")
    radius: float = _f(0.15, "m", 0.0, 2.0, lo_open=True, doc="body radius for contacts and sonar echoes")
    max_speed: float = _f(1.0, "m/s", 0.0, 50.0, lo_open=True)
    max_accel: float = _f(2.0, "m/s^2", 0.0, 1000.0, lo_open=True)
    velocity_tau: float = _f(0.3, "s", 0.0, 100.0, doc="first-order lag of velocity toward the command (0 = none)")
    max_yaw_rate_deg: float = _f(90.0, "deg/s", 0.0, 3600.0, lo_open=True)
    yaw_tau: float = _f(0.2, "s", 0.0, 100.0, doc="first-order lag of yaw rate toward the command (0 = none)")
    min_separation: float = _f(0.5, "m", 0.0, 100.0, doc="minimum centre distance when placing copters at start")


@dataclass(frozen=True)
class SimulationConfig(_Section):
    """Time stepping, run length, seed and batch size: world step ``dt`` s, ``duration`` s, ``seed``, ``n_envs`` (B)."""
    _section = "simulation"
    dt: float = _f(0.05, "s", 0.0, 1.0, lo_open=True, doc="world step")
    duration: float = _f(60.0, "s", 0.0, 1e6, lo_open=True, doc="length of a `finkensim run` flight")
    seed: int = _f(0, "", 0, 2**63 - 1)
    n_envs: int = _f(1, "", 1, 10_000_000, doc="parallel environments (leading array axis)")
    grid_min_copters: int = _f(64, "", 0, 2**62, doc="copters per environment from which copter-copter queries "
                               "use a cell grid instead of the brute force (identical results; 0 = always; "
                               "the break-even measured by `python -m benchmarks.grid_threshold`)")


@dataclass(frozen=True)
class BehaviourConfig(_Section):
    """Controller driving the copters (issue: swarm behaviours). Each uses the copter's own sensors only,
    except ``random_walk``/``hover``, which are open-loop."""

    _section = "behaviour"
    kind: str = _f("random_walk", choices=BEHAVIOUR_KINDS)  # the built-ins and every registered behaviour
    speed: float = _f(0.3, "m/s", 0.0, 50.0, doc="random walk: cruise speed")
    redraw_steps: int = _f(20, "", 1, 10**9, doc="steps between new random headings / random targets")
    wall_margin: float = _f(0.4, "m", 0.0, 100.0, doc="random walk: steer inward when closer than this to a wall")
    yaw_rate_deg: float = _f(20.0, "deg/s", 0.0, 3600.0, doc="random walk: largest random yaw rate command")
    ar_a: float = _f(1.0, "", 0.0, 1e6, doc="attraction-repulsion: attraction a in p (a - b exp(-|p|^2/c))")
    ar_b: float = _f(4.0, "", 0.0, 1e6, doc="attraction-repulsion: repulsion b")
    ar_c: float = _f(1.5, "m^2", 0.0, 1e6, lo_open=True, doc="attraction-repulsion: repulsion range c")
    w_c: float = _f(0.8, "", 0.0, 1e6, doc="weight of the swarm term")
    w_t: float = _f(0.2, "", 0.0, 1e6, doc="weight of the random target term")
    target_distance: float = _f(1.0, "m", 0.0, 1e6, doc="length of the random target offset, redrawn every redraw_steps")
    gain: float = _f(1.0, "1/s", 0.0, 1e6, doc="velocity command = gain * displacement, then speed-limited")
    wall_check: str = _f("none", choices=("none", "per_reading", "sequence"),
                         doc="virtual-ranging plausibility check of sonar readings")
    wall_check_epsilon: float = _f(0.286, "m", 0.0, 100.0, doc="a sonar reading matching no ranging reading within this is a wall")
    sequence_fail_count: int = _f(5, "", 1, 10**6, doc="sequence check: consecutive failures before a sonar is judged to see a wall")
    sequence_release_distance: float = _f(0.3, "m", 0.0, 100.0, doc="sequence check: release after moving this far (IMU dead reckoning)")
    sequence_release_angle_deg: float = _f(30.0, "deg", 0.0, 360.0, doc="sequence check: release after turning this much (gyro)")


@dataclass(frozen=True)
class SonarConfig(_Section):
    """Sonars: four horizontal ones plus the down-facing one (issue: sensor models)."""

    _section = "sonar"
    enabled: bool = _f(True)
    yaw_deg: tuple[float, ...] = _f((0.0, 90.0, 180.0, -90.0), "deg", -360.0, 360.0, length=4,
                                    doc="mounting yaw of front, left, back, right relative to the heading")
    offset: float = _f(0.0, "m", 0.0, 1.0, doc="sonar distance from the copter centre (original scene: 0)")
    min_range: float = _f(0.2, "m", 0.0, 10.0, doc="readings are clamped to [min_range, max_range]")
    max_range: float = _f(3.0, "m", 0.0, 50.0, lo_open=True, doc="no echo within this distance reads max_range")
    error: str = _f("rayleigh", choices=("rayleigh", "seed", "gaussian", "none"),
                    doc="error model: Rayleigh term, the report's rule, Gaussian(sigma), or ideal")
    sigma: float = _f(0.05, "m", 0.0, 10.0, doc="Rayleigh scale (rayleigh, seed) or standard deviation (gaussian)")
    rayleigh_sign: float = _f(-1.0, "", -1.0, 1.0, doc="+1: reading = true + (R - s); -1: true - (R - s) (readings run short)")
    crosstalk: str = _f("geometric", choices=("geometric", "constant", "geometric+constant", "off"),
                        doc="cross-talk model: another copter's ping heard by geometry, a constant fraction of "
                            "halved readings (the report's rule), both, or none")
    crosstalk_probability: float = _f(0.68, "", 0.0, 1.0, doc="constant cross-talk: probability per reading (report: 0.68)")
    cone_half_angle_deg: float = _f(45.0, "deg", 0.0, 90.0, lo_open=True, doc="sonar cone (original scene: 45 deg)")
    schedule: str = _f("round_robin", choices=("simultaneous", "round_robin", "random_offset"),
                       doc="firing schedule: which copters ping in the same slot")
    n_slots: int = _f(4, "", 1, 1000, doc="time slots of the round-robin / random-offset schedules")
    crosstalk_jitter: float = _f(0.02, "m", 0.0, 10.0, doc="std of the jitter added to a cross-talk reading")
    beam: str = _f("ray", choices=("ray", "cone"), doc="ray: one ray; cone: nearest echo of several rays inside the cone")
    beam_rays: int = _f(7, "", 1, 1001, doc="rays across the cone when beam = 'cone'")
    beam_half_angle_deg: float = _f(-1.0, "deg", -1.0, 90.0, doc="half-width of the rays of beam = 'cone'; -1 = "
                                    "cone_half_angle_deg (the beam_width effect fits it apart from the cross-talk cone)")
    down_enabled: bool = _f(True, doc="down-facing sonar reading the altitude")
    range_scale: float = _f(1.0, "", 0.5, 2.0, doc="factor on every echo distance and its error (speed of "
                            "sound relative to the assumed one; the gap effect sound_speed fits it)")
    bias: float = _f(0.0, "m", -1.0, 1.0, doc="constant offset added to every echo (the gap effect sonar_bias fits it)")
    crosstalk_hear_probability: float = _f(1.0, "", 0.0, 1.0, doc="geometric cross-talk: probability that a "
                                           "receiver in cross-talk position hears the emitter (crosstalk_geometric)")
    update_hz: float = _f(0.0, "Hz", 0.0, 1000.0,
                          doc="horizontal-sonar measurements per second, each held until the next (sample-and-hold); 0 = a new "
                              "measurement at every simulation step (the FINken's 2015 log shows no hold at its 36 Hz "
                              "telemetry while airborne: docs/real-finken.md)")
    update_phase: float = _f(0.0, "s", 0.0, None, doc="time of the first horizontal-sonar measurement after t = 0 "
                             "with update_hz > 0 (the sonar_update_rate effect fits it; a slow rate's may lie far "
                             "beyond the flight)")
    latency: float = _f(0.0, "s", 0.0, 2.0, doc="horizontal-sonar latency: each reading describes the world this long "
                        "earlier, in whole simulation steps (the gap effect latency fits it; 0 = none)")
    correction_file: str = _f("", doc="a learned correction of the horizontal sonars (JSON table written by finkensim "
                              "gap --out beside calibrated.toml: docs/calibration.md); empty = none")


@dataclass(frozen=True)
class RangingConfig(_Section):
    """Virtual ranging: radio distances between tags, with a Gaussian-mixture error."""

    _section = "ranging"
    enabled: bool = _f(True)
    max_range: float = _f(2.5, "m", 0.01, 1000.0, doc="beyond this, reads exactly max_range without error")
    error: str = _f("mixture", choices=("mixture", "seed", "gaussian", "none"),
                    doc="mixture: correct conditional GMM draw; seed: the script's weighted sum")
    sigma: float = _f(0.1, "m", 0.0, 10.0, doc="standard deviation for error = 'gaussian'")
    mixture_file: str = _f("", doc="JSON/NPZ mixture in metres; empty = Parlow's K=100 model shipped with finkensim")
    seed_variance_factor: float = _f(10.0, "", 0.0, 1e6, lo_open=True, doc="seed mode: the script's variance fudge")
    beacons: tuple[tuple[float, float], ...] = _f((), "m", -1e6, 1e6, doc="fixed ranging tags [[x, y], ...]")
    # radio effects (finkensim.sensors.ranging_radio; each the simulator side of the gap effect of the same name); defaults: none
    bias: float = _f(0.0, "m", -5.0, 5.0, doc="constant offset added to every reading (the gap effect ranging_bias)")
    scale: float = _f(1.0, "", 0.5, 2.0, doc="factor on every reading: a clock-rate error (ranging_scale)")
    node_delay: tuple[float, ...] = _f((), "m", -5.0, 5.0, doc="constant delay per node, copters 0..N-1 then "
                                       "beacons; a pair reads the sum; nodes beyond the list have none "
                                       "(ranging_node_delay)")
    antenna_offset: tuple[float, ...] = _f((0.0, 0.0, 0.0), "m", -2.0, 2.0, length=3,
                                           doc="the radio tag's position (x, y, z) in every copter's body frame: "
                                               "readings are tag to tag (ranging_antenna_offset)")
    antenna_offset_per_copter: tuple[tuple[float, float], ...] = _f(
        (), "m", -2.0, 2.0, doc="copter k's own extra tag offset [x, y] in its body frame, [[x, y], ...]; copters "
                                "beyond the list have none")
    nlos_bias: float = _f(0.0, "m", -1.0, 2.0, doc="reading longer by nlos_bias*exp(-(c/nlos_width)^2), c the line of "
                          "sight's clearance from a third copter's centre (ranging_nlos)")
    nlos_width: float = _f(0.2, "m", 0.0, 10.0, lo_open=True, doc="clearance scale of the NLOS near a third copter")
    nlos_tail_probability: float = _f(0.0, "", 0.0, 1.0, doc="probability of a positive exponential extra length, "
                                      "independent of other copters: obstacles, people (ranging_nlos_tail)")
    nlos_tail_mean: float = _f(0.3, "m", 0.0, 10.0, lo_open=True, doc="mean of that exponential extra length")
    dropout_a: float = _f(-100.0, "", -100.0, 100.0, doc="a reading is lost (NaN) with probability "
                          "sigmoid(dropout_a + dropout_b*distance); -100 = never (ranging_dropout)")
    dropout_b: float = _f(0.0, "1/m", -100.0, 100.0, doc="distance slope of the dropout probability")
    latency: float = _f(0.0, "s", 0.0, 2.0, doc="ranging latency: each reading describes the world this long earlier, in whole simulation steps (the gap effect latency fits it; 0 = none)")
    correction_file: str = _f("", doc="a learned correction of the ranging readings (JSON table with a 'ranging' table, written by finkensim gap --out beside calibrated.toml: docs/calibration.md); empty = none")


@dataclass(frozen=True)
class ImuConfig(_Section):
    """Body-frame 2-axis accelerometer and yaw-rate gyro with white noise and bias random walk."""

    _section = "imu"
    enabled: bool = _f(True)
    acc_noise_density: float = _f(0.004, "m/s^2/sqrt(Hz)", 0.0, 100.0, doc="MPU-6000 class: 400 ug/sqrt(Hz)")
    acc_bias_walk: float = _f(0.0005, "m/s^3/sqrt(Hz)", 0.0, 100.0, doc="accelerometer bias random walk density")
    gyro_noise_density: float = _f(0.00009, "rad/s/sqrt(Hz)", 0.0, 100.0, doc="MPU-6000 class: 0.005 deg/s/sqrt(Hz)")
    gyro_bias_walk: float = _f(0.00002, "rad/s^2/sqrt(Hz)", 0.0, 100.0, doc="gyro bias random walk density")
    acc_bias: tuple[float, ...] = _f((0.0, 0.0), "m/s^2", -20.0, 20.0, length=2,
                                     doc="constant body-frame accelerometer bias (x, y) (the gap effect imu_bias fits it)")
    gyro_bias: float = _f(0.0, "rad/s", -10.0, 10.0, doc="constant gyro bias (the gap effect imu_bias fits it)")
    latency: float = _f(0.0, "s", 0.0, 2.0, doc="IMU latency: each sample describes the motion this long earlier, in whole simulation steps (the gap effect latency fits it; 0 = none)")
    correction_file: str = _f("", doc="a learned correction of the IMU (JSON table with an 'imu' table per channel, written by finkensim gap --out beside calibrated.toml: docs/calibration.md); empty = none")


@dataclass(frozen=True)
class GapConfig(_Section):
    """Sim-to-real gap diagnosis (``finkensim gap``): predictive draws, statistics, effect search."""

    _section = "gap"
    tracking_sigma_xy: float = _f(-1.0, "m", -1.0, 1.0, doc="pose tracking noise; -1 = from the log's meta, else 0")
    tracking_sigma_yaw: float = _f(-1.0, "rad", -1.0, 3.2, doc="yaw tracking noise; -1 = from the log's meta, else 0")
    draws: int = _f(24, "", 4, 1000, doc="predictive draws per reading (ensemble size M)")
    max_samples_per_flight: int = _f(3000, "", 10, 10**7, doc="time samples used per flight (evenly strided)")
    fit_max_readings: int = _f(20000, "", 100, 10**8, doc="training readings per sensor used when fitting effects (a random subset; held-out scores use every reading)")
    n_boot: int = _f(300, "", 50, 100000, doc="block-bootstrap replicates")
    block_seconds: float = _f(10.0, "s", 0.0, 1e6, lo_open=True, doc="length of a bootstrap block (contiguous time)")
    n_bins: int = _f(5, "", 2, 100, doc="quantile bins per continuous feature")
    alpha: float = _f(0.05, "", 0.0, 0.5, lo_open=True, doc="false-discovery rate for locations and significance level")
    margin: float = _f(0.02, "", 0.0, 10.0, doc="practical-significance margin on the normalised gap")
    accept_gain: float = _f(0.1, "", 0.0, 1.0, doc="an effect is added when it removes at least this fraction of the configured model's gap")
    accept_improvement: float = _f(0.003, "", 0.0, 1.0, doc="a further effect (after the first) is also added when its held-out score improvement is at least this (in units of the current model's typical error: each sensor's configured-model error times the current held-out score over the configured one's) and significant after Bonferroni over the candidates")
    unexplained_shrink: float = _f(0.7, "", 0.0, 1.0, doc="below this held-out shrink a significant gap is 'unexplained' (if what the selected effects leave is itself significant)")
    tie_tolerance: float = _f(0.1, "", 0.0, 1.0, doc="effects whose held-out improvement is within this fraction of the best are near ties")
    imu_window: float = _f(1.0, "s", 0.0, 60.0, lo_open=True, doc="IMU readings are compared integrated over this window")
    imu_velocity_baseline: float = _f(0.2, "s", 0.0, 60.0, doc="velocities compared with the IMU are mean velocities over this baseline (divides tracking noise; at most gap.imu_window)")
    effects: tuple[str, ...] = _f((), "", doc="catalogued effects to try; empty = all registered")
    param_intervals: bool = _f(True, doc="bootstrap each selected effect's fitted parameters (an interval and a "
                               "distribution per parameter, written into calibrated.toml: docs/calibration.md)")


@dataclass(frozen=True)
class LogConfig(_Section):
    """What the flight-log writer records beyond the simulated world (``simulate_flight``, ``finkensim run``)."""

    _section = "log"
    tracking_sigma_xy: float = _f(0.0, "m", 0.0, 0.1, doc="tracking noise added to the logged x, y (a camera "
                                  "tracker's; 0 = ground truth; kept inside the arena); written to "
                                  "meta.tracking_sigma_xy")
    tracking_sigma_yaw: float = _f(0.0, "rad", 0.0, 3.2, doc="tracking noise added to the logged yaw; written to "
                                   "meta.tracking_sigma_yaw")


#: Config section name → its dataclass (``register_section`` adds more).
SECTIONS: dict[str, type] = {
    "arena": ArenaConfig,
    "walls": WallConfig,
    "copters": CopterConfig,
    "simulation": SimulationConfig,
    "behaviour": BehaviourConfig,
    "sonar": SonarConfig,
    "ranging": RangingConfig,
    "imu": ImuConfig,
    "gap": GapConfig,
    "log": LogConfig,
}

#: Profile name → section → the values that differ from the defaults.
PROFILES: dict[str, dict[str, dict[str, Any]]] = {
    "default": {},
    # The original V-REP report, as described (DESIGN.md): 40 kg plates saturate the hinge motor.
    "seed": {
        "walls": {"plate_mass": 40.0},
        "sonar": {"error": "seed", "crosstalk": "constant", "rayleigh_sign": 1.0},
        "ranging": {"error": "seed"},
    },
}


def register_section(name: str, cls: type, seed_overrides: Mapping[str, Any] | None = None) -> None:
    """Add a config section (used by sensor and behaviour modules). ``seed_overrides`` are its seed-profile values."""
    SECTIONS[name] = cls
    if seed_overrides:
        PROFILES["seed"].setdefault(name, {}).update(seed_overrides)


class Config:
    """The whole configuration: one frozen section object per name in ``SECTIONS`` (section name → class).

    Sections are attributes (``cfg.walls.n_segments``). Build with :func:`load_config`, :func:`config_from_dict`,
    or ``Config()`` for all defaults; derive variants with :meth:`replace` (``cfg.replace({"walls.bending": False})``).

    Parameters
    ----------
    profile, **sections : ``"default"`` or ``"seed"`` (the V-REP report's models); sections by TOML table name
    """

    __slots__ = ("profile", "_sections")

    def __init__(self, profile: str = "default", **sections):
        if profile not in PROFILES:
            raise ConfigError(f"profile = {profile!r}: expected one of {', '.join(map(repr, PROFILES))}"
                              f"{suggest(profile, PROFILES)}")
        object.__setattr__(self, "profile", profile)
        built = {}
        for name, cls in SECTIONS.items():
            sec = sections.pop(name, None)
            built[name] = sec if sec is not None else cls(**PROFILES[profile].get(name, {}))
        if sections:
            raise ConfigError(f"unknown config sections: {', '.join(sections)}")
        _check_room(built["copters"], built["arena"])
        _check_imu_noise(built["imu"], built["simulation"])
        object.__setattr__(self, "_sections", built)

    def __getattr__(self, name):
        try:
            return object.__getattribute__(self, "_sections")[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name, value):
        raise dataclasses.FrozenInstanceError(f"Config is frozen; use cfg.replace({{'{name}...': ...}})")

    def __eq__(self, other):
        return isinstance(other, Config) and self.profile == other.profile and self._sections == other._sections

    def __hash__(self):
        return hash((self.profile, tuple(self._sections.items())))

    def __reduce__(self):
        # Frozen slots block pickle's default path; rebuild through __init__, which re-checks the values.
        return functools.partial(Config, self.profile, **self._sections), ()

    def __repr__(self):
        inner = ", ".join(f"{k}={v!r}" for k, v in self._sections.items())
        return f"Config(profile={self.profile!r}, {inner})"

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (TOML-shaped) of every value, including defaults."""
        out: dict[str, Any] = {"profile": self.profile}
        for name, sec in self._sections.items():
            out[name] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(sec).items()}
        return out

    def replace(self, updates: Mapping[str, Any]) -> "Config":
        """A new Config with dotted keys replaced, e.g. ``{"walls.bending": False, "copters.n": 10}``.

        ``{"profile": "seed"}`` switches profile: values that were at the old profile's defaults take the new
        profile's; values set away from them are kept.

        Parameters
        ----------
        updates : Mapping[str, Any]
            Dotted keys ``"section.key"`` (or ``"profile"``) → new values, in the config's units.
        """
        profile = updates.get("profile", self.profile)
        base = Config(profile).to_dict() if profile != self.profile else None
        data = self.to_dict()
        if base is not None:
            old = Config(self.profile).to_dict()
            for name in SECTIONS:
                for key, value in data[name].items():
                    if value == old[name][key]:
                        data[name][key] = base[name][key]
            data["profile"] = profile
        for dotted, value in updates.items():
            if dotted == "profile":
                continue
            section, _, key = dotted.partition(".")
            if not key:
                raise ConfigError(f"{dotted!r}: expected a dotted key 'section.key'")
            check_key(section, key)
            data[section][key] = value
        return config_from_dict(data, _explicit=True)


PACKING_DENSITY = math.pi / (2 * math.sqrt(3))  # densest packing of equal discs in the plane (hexagonal)


def _check_room(copters, arena) -> None:
    """Raise if ``copters.n`` bodies of ``copters.radius`` cannot fit in the arena at any arrangement."""
    body, room = math.pi * copters.radius ** 2, PACKING_DENSITY * arena.width * arena.length
    if copters.n * body > room:
        raise ConfigError(
            f"copters.n = {copters.n}: {copters.n} copters of copters.radius = {copters.radius} m cover "
            f"{copters.n * body:.3g} m^2, more than the {arena.width} x {arena.length} m arena holds even packed "
            f"hexagonally ({room:.3g} m^2); expected copters.n <= {int(room / body)}, a larger arena or a smaller radius")


#: largest white-noise std of one accelerometer sample (m/s^2): a flight-log loader reads a median |imu_acc| above
#: 50 as cm/s^2 (finkensim.flightlog.validation), and no accelerometer is that noisy
MAX_ACC_SAMPLE_NOISE = 20.0


def _check_imu_noise(imu, simulation) -> None:
    """Raise if the accelerometer's white noise per sample (``acc_noise_density`` / √dt) exceeds
    :data:`MAX_ACC_SAMPLE_NOISE`: the flight's own log would then look like cm/s^2 to every loader."""
    per_sample = imu.acc_noise_density / math.sqrt(simulation.dt)
    if imu.acc_noise_density > MAX_ACC_SAMPLE_NOISE * math.sqrt(simulation.dt):  # the cap itself passes, unrounded
        raise ConfigError(
            f"imu.acc_noise_density = {imu.acc_noise_density} m/s^2/sqrt(Hz) at simulation.dt = {simulation.dt} s is "
            f"{per_sample:.3g} m/s^2 of white noise per sample: expected at most {MAX_ACC_SAMPLE_NOISE} m/s^2, i.e. "
            f"imu.acc_noise_density <= {MAX_ACC_SAMPLE_NOISE * math.sqrt(simulation.dt):.3g} (larger readings look "
            "like cm/s^2 to every flight-log loader)")


def check_key(section: str, key: str | None = None) -> None:
    """Check that ``[section]`` (and, when given, ``section.key``) names a config setting; a :class:`ConfigError`
    for an unknown section or key, with a close-match suggestion and the allowed names."""
    if section not in SECTIONS:
        extra = suggest(section, [*SECTIONS, "profile"])
        raise ConfigError(f"unknown section [{section}]: expected one of {', '.join(SECTIONS)}{extra}")
    if key is not None:
        names = [f.name for f in dataclasses.fields(SECTIONS[section])]
        if key not in names:
            extra = suggest(key, names, show=lambda name: f"{section}.{name}")
            raise ConfigError(f"unknown key {section}.{key}{extra}; allowed: {', '.join(names)}")


def config_from_dict(data: Mapping[str, Any], _explicit: bool = False) -> Config:
    """Build a :class:`Config` from a TOML-shaped nested dict; missing keys take (profile) defaults."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"config: expected a table of sections, got {type(data).__name__}")
    profile = data.get("profile", "default")
    if not isinstance(profile, str):
        raise ConfigError(f"profile = {profile!r}: expected a string")
    Config(profile)  # validates the profile name
    sections = {}
    for name, values in data.items():
        if name == "profile":
            continue
        check_key(name)
        if not isinstance(values, Mapping):
            raise ConfigError(f"[{name}] = {values!r}: expected a table of keys")
        for key in values:
            check_key(name, key)
        merged = {**PROFILES[profile].get(name, {}), **values} if not _explicit else dict(values)
        sections[name] = SECTIONS[name](**merged)
    return Config(profile, **sections)


def load_config(source: str | Path | Mapping[str, Any] | None = None) -> Config:
    """Load a config from a TOML file path, a TOML string, a dict, or None (all defaults).

    Parameters
    ----------
    source : str, Path, Mapping or None (errors: :class:`ConfigError` naming the key, the value and the range)
    """
    if source is None:
        return Config()
    if isinstance(source, Mapping):
        return config_from_dict(source)
    path = Path(source)
    try:
        is_file = path.is_file()
    except OSError:  # e.g. a long TOML text is not a valid file name
        is_file = False
    looks_like_toml = isinstance(source, str) and ("\n" in source or "=" in source or source.lstrip().startswith("["))
    if looks_like_toml and not is_file:
        path, text = None, str(source)
    else:
        if not is_file:
            raise ConfigError(f"config file {str(path)!r} does not exist" if not path.exists()
                              else f"config file {str(path)!r} is not a file")
        text = path.read_text()
    try:
        data = loads_toml(text)
    except tomllib.TOMLDecodeError as exc:
        where = f" in {path}" if path else ""
        raise ConfigError(f"invalid TOML{where}: {exc}") from None
    return config_from_dict(data)


def describe(cfg_cls: type) -> list[tuple[str, Any, str, str, str]]:
    """Rows (key, default, unit, allowed, doc) for documenting a section."""
    rows = []
    for f in dataclasses.fields(cfg_cls):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        rows.append((f.name, default, f.metadata["unit"], describe_range(f.metadata), f.metadata["doc"]))
    return rows
