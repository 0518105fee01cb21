"""The catalogue of candidate unmodelled effects, each a small plug-in.

An :class:`Effect` names the sensors it changes, its parameters (bounds, integer or not), and
how a set of parameter values modifies a :class:`~finkensim.gap.model.params.ModelParams`. The
diagnosis fits each effect's parameters on the training flights (minimising the mean CRPS of
the sensors it touches) and measures it on held-out flights.

Add your own in a notebook::

    from finkensim.gap.attribute.effects import Effect, Param, register

    register(Effect(
        name="sonar_offset_bias", sensors=("ultrasonic",),
        params=(Param("bias", -0.3, 0.3),),
        apply=lambda base, v: base.with_sonar(bias=base.sonar.bias + v["bias"]),
        doc="a constant offset on every sonar echo"))

``apply(base, values)`` must be pure. ``expected_features`` (optional) lists the location
features where the effect is expected to show up; only ``finkensim gap-validate`` uses it.
``calibrate(values, cfg)`` (optional) returns the config updates (dotted keys) under which the simulator flies the
fitted effect: ``ModelParams.from_config(cfg.replace(calibrate(v, cfg)))`` must equal ``apply(from_config(cfg), v)``
(``tests/test_calibrate.py`` checks it for every catalogued effect that has one). An effect without it is not flown
by the simulator yet; a calibrated config says so (:mod:`finkensim.gap.quantify.calibrate`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...config import Config

from ...sensors.sonar_model import (CROSSTALK_CONSTANT, CROSSTALK_GEOMETRIC, ERROR_NONE, ERROR_RAYLEIGH,
                                   SCHEDULE_SIMULTANEOUS)
from ..model.bulge import HINGE_KEYS, as_hinge_walls
from ..model.params import ModelParams
from . import fits
from .objective import EffectFit, FitObjective


@dataclass(frozen=True)
class Param:
    """One parameter of an :class:`Effect`, fitted within its bounds.

    Parameters
    ----------
    name : str
        The key of the parameter in the values dict ``apply`` receives.
    lo, hi : float
        Bounds of the fit, in ``unit``.
    integer : bool
        An integer parameter (a step count): fitted over every integer in [lo, hi].
    unit : str
        Unit of the parameter (``"m"``, ``"s"``, ``""`` for a factor), shown in the report.
    log : bool
        A positive scale whose plausible values span decades (a mean length from centimetres to a metre): the
        generic search's coarse grid is geometric in it, so that small values are tried as densely as large ones.
        Needs ``lo > 0``.
    """

    name: str
    lo: float
    hi: float
    integer: bool = False
    unit: str = ""
    log: bool = False

    def grid(self, n: int) -> np.ndarray:
        """n points from lo to hi: geometric when :attr:`log`, else evenly spaced."""
        return np.geomspace(self.lo, self.hi, n) if self.log else np.linspace(self.lo, self.hi, n)


@dataclass(frozen=True)
class Effect:
    """A candidate unmodelled effect: how a set of parameter values changes the simulator's sensor model.

    Register one with :func:`register`; the diagnosis fits its parameters on the training flights
    (minimising the mean CRPS of the sensors it changes) and scores it on the held-out flights.

    Parameters
    ----------
    name : str
        Unique name (the report's ``effects[].name``).
    sensors : tuple of str
        The sensors it changes: ``"ultrasonic"``, ``"ranging"``, ``"imu"``.
    params : tuple of Param
        Its parameters, with bounds and units.
    apply : callable
        ``apply(base, values) -> ModelParams``: the base :class:`~finkensim.gap.model.params.ModelParams` with the
        effect added at ``values`` (parameter name → value); must be pure.
    doc : str
        One sentence for the report: what the effect is.
    initial : callable, optional
        ``initial(base) -> values``: the starting point of the fit (default: each parameter at ``lo``, or 0
        when ``lo`` < 0).
    expected_features : tuple of str
        Location features where the effect is expected to show up (only ``finkensim gap-validate`` uses it).
    catch_all : bool
        An effect that absorbs part of any gap (a scale, a bias, pose noise): it is named only when no
        structured effect comes within the tie tolerance of it.
    separable : bool
        Its parameters act on different sensors and are fitted one at a time.
    calibrate : callable, optional
        ``calibrate(values, cfg) -> updates``: the config updates (dotted keys) under which the simulator flies
        the effect at ``values`` on top of ``cfg`` (:mod:`finkensim.gap.quantify.calibrate`); None = not flown yet.
    fit : callable, optional
        The effect's own fit, replacing the generic one (a grid, a bounded scalar search or Nelder–Mead per
        parameter group): ``fit(objective, effect, current, values) -> values``
        (:data:`~finkensim.gap.attribute.objective.EffectFit`; ``objective`` is the diagnosis as a fit sees it,
        :class:`~finkensim.gap.attribute.objective.FitObjective`); None = the generic fit.
    informed : callable, optional
        ``informed(objective) -> names``: the parameters the diagnosis's logs can inform (a per-node delay of a node
        no reading involves cannot be); the others stay at their start values in the joint searches and get no
        interval. None = every parameter.
    profiled : bool
        Its own ``fit`` is a cheap closed-form solve (least squares, not a search): a joint search with other
        effects solves it anew at each of their trial values instead of searching its parameters (a search over
        eight per-node delays and a range scale cannot move within a joint search's budget).
    """

    name: str
    sensors: tuple[str, ...]
    params: tuple[Param, ...]
    apply: Callable[[ModelParams, dict], ModelParams]
    doc: str = ""
    initial: Callable[[ModelParams], dict] | None = None
    expected_features: tuple[str, ...] = ()
    catch_all: bool = False
    separable: bool = False  # parameters act on different sensors and are fitted one at a time
    calibrate: Callable[[dict, Config], dict] | None = None
    fit: EffectFit | None = None
    informed: Callable[[FitObjective], tuple[str, ...]] | None = None
    profiled: bool = False

    def free(self, objective: FitObjective) -> tuple[Param, ...]:
        """The parameters the logs of ``objective`` can inform (:attr:`informed`; default all).

        Parameters
        ----------
        objective : FitObjective
            The diagnosis as a fit sees it.

        Returns
        -------
        tuple of Param
            The informed parameters, in the effect's order.
        """
        if self.informed is None:
            return self.params
        names = set(self.informed(objective))
        return tuple(p for p in self.params if p.name in names)

    def start(self, base: ModelParams) -> dict:
        """Parameter values that reproduce the base model (or the effect's neutral values).

        Parameters
        ----------
        base : ModelParams
            The model the effect is added to.

        Returns
        -------
        dict
            Parameter name → starting value, in the parameters' units.
        """
        if self.initial is not None:
            return self.initial(base)
        return {p.name: (p.lo if p.lo >= 0 else 0.0) for p in self.params}


#: The catalogue: effect name → :class:`Effect` (:func:`register` adds or replaces one).
REGISTRY: dict[str, Effect] = {}

#: a fitted value within this share of its range from a bound sits at the bound
AT_BOUND_SHARE = 0.01


def at_bound(effect: Effect, values: dict, base: ModelParams) -> list[str]:
    """Names of the parameters of ``effect`` whose fitted ``values`` sit at a bound of their range (within
    :data:`AT_BOUND_SHARE` of it), leaving out a bound that is the effect's neutral value (no dropout, no delay):
    the fit wanted to go further, so the range is too narrow or another effect is at work."""
    neutral = effect.start(base)
    out = []
    for prm in effect.params:
        v = values.get(prm.name)
        if v is None or not math.isfinite(float(v)):
            continue
        tol = AT_BOUND_SHARE * (prm.hi - prm.lo)
        for bound in (prm.lo, prm.hi):
            n = neutral.get(prm.name)
            if abs(float(v) - bound) <= tol and not abs(float(math.nan if n is None else n) - bound) <= tol:
                out.append(prm.name)
                break
    return out


def register(effect: Effect) -> Effect:
    """Add (or replace) an effect in the catalogue.

    Parameters
    ----------
    effect : Effect
        The effect; an effect of the same name is replaced.

    Returns
    -------
    Effect
        ``effect`` itself (so that ``register`` can wrap a definition).
    """
    REGISTRY[effect.name] = effect
    return effect


def _rayleigh_scale(base: ModelParams, v: dict) -> ModelParams:
    sigma0 = base.sonar.sigma if base.sonar.sigma > 0 else 0.05
    err = base.sonar.error if base.sonar.error != ERROR_NONE else ERROR_RAYLEIGH
    return base.with_sonar(error=err, sigma=sigma0 * v["scale"])


def _cal_rayleigh_scale(v: dict, cfg: Config) -> dict:
    out = {"sonar.sigma": (cfg.sonar.sigma if cfg.sonar.sigma > 0 else 0.05) * v["scale"]}
    if cfg.sonar.error == "none":
        out["sonar.error"] = "rayleigh"
    return out


def _cal_crosstalk(kind: str, probability_key: str):
    """The calibration of one cross-talk model: switch it on beside the configured one (geometric without a
    configured schedule fires every copter at once, as the effect assumes)."""
    def cal(v: dict, cfg: Config) -> dict:
        now = cfg.sonar.crosstalk
        if v["probability"] == 0.0 and kind not in now.split("+"):
            return {}  # probability 0 is no cross-talk: nothing to switch on (_crosstalk_constant, _geometric)
        out = {probability_key: v["probability"]}
        if kind not in now.split("+"):
            out["sonar.crosstalk"] = kind if now == "off" else "geometric+constant"
            if kind == "geometric":
                out["sonar.schedule"] = "simultaneous"
        if kind == "geometric" and "cone_half_angle_deg" in v:
            out.update(_cal_cone(float(v["cone_half_angle_deg"]), cfg))
        return out
    return cal


def _same_cone(deg: float, half_angle: float) -> bool:
    """Whether a cone of ``deg`` degrees is the sonar record's ``half_angle`` (rad), to rounding."""
    return abs(math.radians(deg) - half_angle) <= 1e-12


def _cal_cone(deg: float, cfg: Config) -> dict:
    """The geometric cross-talk cone the simulator flies: ``sonar.cone_half_angle_deg`` (the config's own value when
    the fit kept it). A cone beam that follows that key (``sonar.beam_half_angle_deg = -1``) is pinned at the angle it
    flew: the beam's width is the ``beam_width`` effect's, not the cross-talk cone's."""
    if _same_cone(deg, math.radians(cfg.sonar.cone_half_angle_deg)):
        return {"sonar.cone_half_angle_deg": cfg.sonar.cone_half_angle_deg}
    out = {"sonar.cone_half_angle_deg": deg}
    if cfg.sonar.beam == "cone" and cfg.sonar.beam_half_angle_deg < 0.0:
        out["sonar.beam_half_angle_deg"] = cfg.sonar.cone_half_angle_deg
    return out


def _cal_beam(v: dict, cfg: Config) -> dict:
    return {"sonar.beam": "cone", "sonar.beam_half_angle_deg": v["half_angle_deg"],
            "sonar.beam_rays": cfg.sonar.beam_rays}


def _crosstalk_geometric(base: ModelParams, v: dict) -> ModelParams:
    # without geometric cross-talk in the base model the schedule is unknown: every copter fires at once
    geometric = bool(base.sonar.crosstalk & CROSSTALK_GEOMETRIC)
    if v["probability"] == 0.0 and not geometric:
        return base  # probability 0 is no cross-talk: the base model as it is, its schedule and cone unchanged
    cone = {}
    deg = v.get("cone_half_angle_deg")
    if deg is not None and not _same_cone(float(deg), base.sonar.half_angle):
        # the cross-talk cone only (cos_half_angle: sonar_kernels.crosstalk_path); the beam's rays stay as they are
        h = math.radians(float(deg))
        cone = {"half_angle": h, "cos_half_angle": math.cos(h)}
    return base.with_sonar(crosstalk=base.sonar.crosstalk | CROSSTALK_GEOMETRIC,
                           crosstalk_hear_probability=v["probability"],
                           schedule=base.sonar.schedule if geometric else SCHEDULE_SIMULTANEOUS, **cone)


def _crosstalk_constant(base: ModelParams, v: dict) -> ModelParams:
    if v["probability"] == 0.0 and not base.sonar.crosstalk & CROSSTALK_CONSTANT:
        return base  # probability 0 is no cross-talk: the base model as it is, its cross-talk mode unchanged
    return base.with_sonar(crosstalk=base.sonar.crosstalk | CROSSTALK_CONSTANT, crosstalk_probability=v["probability"])


def _geometric_probability(base: ModelParams) -> float:
    return base.sonar.crosstalk_hear_probability if base.sonar.crosstalk & CROSSTALK_GEOMETRIC else 0.0


def _constant_probability(base: ModelParams) -> float:
    return base.sonar.crosstalk_probability if base.sonar.crosstalk & CROSSTALK_CONSTANT else 0.0


def _beam(base: ModelParams, v: dict) -> ModelParams:
    rays = base.sonar.n_rays if base.sonar.n_rays > 1 else base.beam_rays
    return base.with_(sonar=base.sonar.with_beam(math.radians(v["half_angle_deg"]), rays))


def _cal_hinge_walls(v: dict) -> dict:
    """The ``wall_bulge`` effect's hinge version (:mod:`.hinge`) flown: the simulator's hinge walls at the fitted
    keys, no bulge on top."""
    return {"walls.bending": True, "walls.model": "hinge", **{f"walls.{k}": float(v[k]) for k in HINGE_KEYS}}


register(Effect(
    "wall_bulge", ("ultrasonic",), (Param("amplitude", -0.1, 0.5, unit="m"), Param("reach", 0.05, 1.5, unit="m"),
                                    Param("response", 0.0, 3.0, unit="s"), Param("shape", 1.0, 12.0)),
    lambda b, v: as_hinge_walls(b, v) if HINGE_KEYS[0] in v else b.with_(
        bulge_amplitude=v["amplitude"], bulge_reach=v["reach"], bulge_response=v["response"], bulge_shape=v["shape"]),
    fit=fits.fit_bulge,
    doc="curtain plates bend toward nearby copters (Bernoulli) beyond the configured wall model: each plate "
        "moves toward the arena by amplitude·exp(−(d/reach)^shape), d its distance to the nearest copter body "
        "(shape 2 a Gaussian, larger a flat bulge that ends sharply near reach), following it with a first-order "
        "response time (fitted from the readings, so it works at any altitude, hinge height, or with rigid "
        "configured walls)",
    initial=lambda b: {"amplitude": b.bulge_amplitude, "reach": b.bulge_reach, "response": b.bulge_response,
                       "shape": b.bulge_shape},
    expected_features=("wall_distance", "hit_type", "hit_to_copter", "true_range", "incidence"),
    calibrate=lambda v, cfg: _cal_hinge_walls(v) if HINGE_KEYS[0] in v else {
        "walls.bending": True, "walls.bulge_amplitude": float(v["amplitude"]), "walls.bulge_reach": float(v["reach"]),
        "walls.bulge_response": float(v["response"]), "walls.bulge_shape": float(v["shape"]),
        # the hinge-law weight of the flexible refit (gap/attribute/parsimony.py); the catalogue's fit keeps the config's
        "walls.bulge_hinge": float(v.get("hinge", cfg.walls.bulge_hinge)),
        # the hinge stays as the config flew it (rigid walls: the bulge alone)
        "walls.model": "hinge+bulge" if cfg.walls.bending and "hinge" in cfg.walls.model else "bulge"}))
register(Effect(
    "crosstalk_geometric", ("ultrasonic",),
    (Param("probability", 0.0, 1.0), Param("cone_half_angle_deg", 5.0, 80.0, unit="deg")),
    _crosstalk_geometric,
    fit=fits.fit_crosstalk_cone,
    doc="a sonar hears another copter's ping (with a probability) when the emitter is inside its cone (half-angle "
        "cone_half_angle_deg) and points at it",
    initial=lambda b: {"probability": _geometric_probability(b),
                       "cone_half_angle_deg": math.degrees(b.sonar.half_angle)},
    calibrate=_cal_crosstalk("geometric", "sonar.crosstalk_hear_probability"),
    expected_features=("neighbor_in_beam", "neighbor_distance", "hit_type")))
register(Effect(
    "crosstalk_constant", ("ultrasonic",), (Param("probability", 0.0, 0.95),),
    _crosstalk_constant,
    doc="a constant fraction of readings is halved (the report's 68 % rule)",
    initial=lambda b: {"probability": _constant_probability(b)},
    calibrate=_cal_crosstalk("constant", "sonar.crosstalk_probability"),
    expected_features=("true_range",), catch_all=True))
register(Effect(
    "sonar_rayleigh_scale", ("ultrasonic",), (Param("scale", 0.1, 10.0),),
    _rayleigh_scale,
    doc="the sonar noise scale sigma is off by a factor",
    calibrate=_cal_rayleigh_scale,
    initial=lambda b: {"scale": 1.0}, catch_all=True))
register(Effect(
    "sonar_bias", ("ultrasonic",), (Param("bias", -0.5, 0.5, unit="m"),),
    lambda b, v: b.with_sonar(bias=b.sonar.bias + v["bias"]),
    doc="a constant offset on every echo", initial=lambda b: {"bias": 0.0}, catch_all=True,
    calibrate=lambda v, cfg: {"sonar.bias": cfg.sonar.bias + v["bias"]}))
register(Effect(
    "beam_width", ("ultrasonic",), (Param("half_angle_deg", 0.0, 60.0, unit="deg"),),
    _beam,
    doc="the sonar reports the nearest echo inside a cone, not along one ray",
    calibrate=_cal_beam,
    initial=lambda b: {"half_angle_deg": math.degrees(float(abs(b.sonar.ray_angles).max()))},
    expected_features=("neighbor_in_beam", "neighbor_distance", "hit_to_copter", "incidence", "true_range",
                       "hit_type")))
register(Effect(
    "sound_speed", ("ultrasonic",), (Param("factor", 0.8, 1.25),),
    lambda b, v: b.with_sonar(range_scale=b.sonar.range_scale * v["factor"]),
    doc="speed of sound differs from the assumed one (temperature): readings scale by a factor",
    initial=lambda b: {"factor": 1.0}, expected_features=("true_range",),
    calibrate=lambda v, cfg: {"sonar.range_scale": cfg.sonar.range_scale * v["factor"]}))


def _update_phase_seconds(v: dict) -> float:
    """The first measurement instant (s) of ``sonar_update_rate``'s values: ``phase`` periods (0 where a rate so
    slow that its period overflows makes it infinite)."""
    hz = float(v["rate_hz"])
    seconds = float(v["phase"]) / hz if hz > 0 else 0.0
    return seconds if math.isfinite(seconds) else 0.0


def _update_rate(base: ModelParams, v: dict) -> ModelParams:
    return base.with_sonar(update_hz=float(v["rate_hz"]), update_phase=_update_phase_seconds(v))


register(Effect(
    "sonar_update_rate", ("ultrasonic",), (Param("rate_hz", 0.0, 50.0, unit="Hz"), Param("phase", 0.0, 1.0)),
    _update_rate,
    fit=fits.fit_update_rate,
    doc="the sonars measure rate_hz times a second and hold each reading until the next (sample-and-hold; phase: "
        "the first measurement, in periods from the log's first sample; rate 0 = every sample): readings describe "
        "the world up to one period earlier, in a sawtooth",
    initial=lambda b: {"rate_hz": b.sonar.update_hz, "phase": b.sonar.update_phase * b.sonar.update_hz},
    expected_features=("range_rate", "speed"),
    calibrate=lambda v, cfg: {"sonar.update_hz": float(v["rate_hz"]), "sonar.update_phase": _update_phase_seconds(v)}))
register(Effect(
    "latency", ("ultrasonic", "ranging", "imu"),
    (Param("ultrasonic", -0.5, 1.0, unit="s"), Param("ranging", -0.5, 1.0, unit="s"),
     Param("imu", -0.5, 1.0, unit="s")),
    lambda b, v: b.with_(latency_sonar=float(v["ultrasonic"]), latency_ranging=float(v["ranging"]),
                         latency_imu=float(v["imu"])),
    fit=fits.fit_latency,
    doc="readings describe the world some time earlier (per sensor, s; negative: later, a clock offset set too "
        "early); searched in whole samples of the log",
    initial=lambda b: {"ultrasonic": b.latency_sonar, "ranging": b.latency_ranging, "imu": b.latency_imu},
    expected_features=("range_rate", "speed", "acc_magnitude"), separable=True,
    # the simulator flies latencies >= 0 (a simulated reading cannot describe a later world): a negative fit (a log
    # stamped early) flies as 0, and the calibrated file's comment at the key shows the fitted value
    calibrate=lambda v, cfg: {"sonar.latency": max(0.0, float(v["ultrasonic"])),
                              "ranging.latency": max(0.0, float(v["ranging"])),
                              "imu.latency": max(0.0, float(v["imu"]))}))
register(Effect(
    "ranging_nlos", ("ranging",), (Param("bias", -0.5, 1.0, unit="m"), Param("width", 0.03, 0.35, unit="m")),
    lambda b, v: b.with_ranging(nlos_bias=v["bias"], nlos_width=v["width"]),
    doc="ranging reads long when a third copter's body is near the line of sight: bias·exp(−(clearance/width)²)",
    initial=lambda b: {"bias": b.ranging.radio["nlos_bias"], "width": b.ranging.radio["nlos_width"]},
    calibrate=lambda v, cfg: {"ranging.nlos_bias": v["bias"], "ranging.nlos_width": v["width"]},
    expected_features=("los_clearance", "neighbor_distance")))
register(Effect(
    # a = -100 is the config's "never" (sigmoid(-100) ~ 4e-44): the range includes the base model's value
    "ranging_dropout", ("ranging",), (Param("a", -100.0, 8.0), Param("b", -6.0, 6.0, unit="1/m")),
    lambda b, v: b.with_ranging(dropout_a=v["a"], dropout_b=v["b"]),
    calibrate=lambda v, cfg: {"ranging.dropout_a": v["a"], "ranging.dropout_b": v["b"]},
    fit=fits.fit_dropout,
    doc="readings go missing with probability sigmoid(a + b·distance)",
    initial=lambda b: {"a": b.ranging.radio["dropout_a"], "b": b.ranging.radio["dropout_b"]},
    expected_features=("true_range",)))
register(Effect(
    "pose_noise", ("ultrasonic", "ranging", "imu"),
    (Param("sigma_xy", 0.0, 0.05, unit="m"), Param("sigma_yaw", 0.0, 0.2, unit="rad")),
    lambda b, v: b.with_(sigma_xy=v["sigma_xy"], sigma_yaw=v["sigma_yaw"]),
    fit=fits.fit_pose_noise,
    doc="tracking noise in the logged poses", catch_all=True,
    # None: each flight's stated noise, as the base model (a fitted σ is one value for every flight)
    initial=lambda b: {"sigma_xy": b.sigma_xy, "sigma_yaw": b.sigma_yaw},
    # the flight-log writer records simulated poses with it, and a diagnosis of new logs under the calibrated config
    # takes it instead of the logs' declared noise
    calibrate=lambda v, cfg: {"log.tracking_sigma_xy": v["sigma_xy"], "log.tracking_sigma_yaw": v["sigma_yaw"],
                              "gap.tracking_sigma_xy": v["sigma_xy"], "gap.tracking_sigma_yaw": v["sigma_yaw"]}))
register(Effect(
    "imu_bias", ("imu",),
    (Param("acc_x", -1.0, 1.0, unit="m/s^2"), Param("acc_y", -1.0, 1.0, unit="m/s^2"),
     Param("gyro", -0.5, 0.5, unit="rad/s")),
    lambda b, v: b.with_(imu=b.imu._replace(acc_bias_x=b.imu.acc_bias_x + v["acc_x"],
                                            acc_bias_y=b.imu.acc_bias_y + v["acc_y"],
                                            gyro_bias=b.imu.gyro_bias + v["gyro"])),
    fit=fits.fit_imu_bias,
    doc="constant accelerometer and gyro biases", initial=lambda b: {"acc_x": 0.0, "acc_y": 0.0, "gyro": 0.0},
    calibrate=lambda v, cfg: {"imu.acc_bias": [cfg.imu.acc_bias[0] + v["acc_x"], cfg.imu.acc_bias[1] + v["acc_y"]],
                              "imu.gyro_bias": cfg.imu.gyro_bias + v["gyro"]},
    separable=True))

# the radio effects of the ranging kernel (ranging_bias, _scale, _antenna_offset, _node_delay, _nlos_tail)
from . import effects_radio  # noqa: E402,F401  (registers them after the entries above)
