"""The sonar model record: :class:`SonarModel` (every parameter of the sonars in SI units,
as the kernels take it), its integer codes, and, re-exported from :mod:`finkensim.arena`, :class:`WallGeometry` (the arena as the kernels see it).

Built once from a config (:meth:`SonarModel.from_config`); the simulator and the gap diagnosis both pass
this record to the same kernels (:mod:`finkensim.sensors.sonar_kernels`), and the diagnosis expresses
candidate effects as changes of its fields (``model._replace(sigma=...)``). The physics is described in
:mod:`finkensim.sensors.sonar`.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from numba import njit

from ..arena import WallGeometry, wall_geometry
from ..config import Config, ConfigError, SonarConfig

__all__ = [
    "ERROR_NONE", "ERROR_GAUSSIAN", "ERROR_RAYLEIGH", "ERROR_SEED", "ERROR_CODES",
    "CROSSTALK_OFF", "CROSSTALK_CONSTANT", "CROSSTALK_GEOMETRIC", "CROSSTALK_CODES",
    "SCHEDULE_SIMULTANEOUS", "SCHEDULE_ROUND_ROBIN", "SCHEDULE_RANDOM_OFFSET", "SCHEDULE_CODES",
    "N_SONARS", "DOWN_SONAR", "RAYLEIGH_STD_FACTOR", "rayleigh_std", "SonarModel", "SonarScalars", "sonar_scalars", "WallGeometry", "wall_geometry",
]

ERROR_NONE = 0
ERROR_GAUSSIAN = 1
ERROR_RAYLEIGH = 2
ERROR_SEED = 3
ERROR_CODES = {"none": ERROR_NONE, "gaussian": ERROR_GAUSSIAN, "rayleigh": ERROR_RAYLEIGH, "seed": ERROR_SEED}

# bit flags: a model may combine both kinds (the gap diagnosis adds one to the other)
CROSSTALK_OFF = 0
CROSSTALK_CONSTANT = 1
CROSSTALK_GEOMETRIC = 2
CROSSTALK_CODES = {"off": CROSSTALK_OFF, "constant": CROSSTALK_CONSTANT, "geometric": CROSSTALK_GEOMETRIC,
                   "geometric+constant": CROSSTALK_GEOMETRIC | CROSSTALK_CONSTANT}

SCHEDULE_SIMULTANEOUS = 0
SCHEDULE_ROUND_ROBIN = 1
SCHEDULE_RANDOM_OFFSET = 2
SCHEDULE_CODES = {"simultaneous": SCHEDULE_SIMULTANEOUS, "round_robin": SCHEDULE_ROUND_ROBIN,
                  "random_offset": SCHEDULE_RANDOM_OFFSET}

N_SONARS = 4  # horizontal: front, left, back, right
DOWN_SONAR = 4  # index of the down sonar in the random-number layout

RAYLEIGH_STD_FACTOR = math.sqrt((4.0 - math.pi) / 2.0)


def rayleigh_std(sigma: float) -> float:
    """Standard deviation of Rayleigh(σ): sqrt((4 − π)/2)·σ ≈ 0.655σ (m)."""
    return RAYLEIGH_STD_FACTOR * float(sigma)


class SonarModel(NamedTuple):
    """Sonar parameters in SI units, as passed to the kernels (arrays, ints, floats, bools only).

    mount_yaw (S,) rad: mounting yaw of each horizontal sonar relative to the heading (the simulator has
    S = 4: front, left, back, right; a replayed log may have any number).
    offset m: sonar distance from the copter centre. min_range, max_range m: reading clamp; no echo
    within max_range reads max_range. error, crosstalk, schedule: integer codes (``ERROR_*``,
    ``CROSSTALK_*``, ``SCHEDULE_*``). sigma m: Rayleigh scale or Gaussian std. rayleigh_sign: ±1 (or
    any value in [−1, 1]) multiplying (R − s) in the ``rayleigh`` model. rayleigh_s m: s, the Rayleigh
    std. crosstalk_probability: constant model's per-reading probability. half_angle rad,
    cos_half_angle: sonar cone. n_slots: slots of the round-robin / random-offset schedules.
    crosstalk_jitter m: std of the cross-talk reading's jitter. ray_angles (R,) rad: ray directions
    relative to the sonar heading (``[0]`` for ``beam = "ray"``, ``linspace(−h, h, beam_rays)`` for
    ``"cone"``). radius m: copter body radius (echo circles). altitude m: flight height (down sonar).
    enabled, down_enabled: whether the caller should produce horizontal / down readings (the
    functions here always compute).

    Fields whose defaults change nothing and which the gap diagnosis fits as candidate effects (config keys
    ``sonar.range_scale``, ``sonar.bias``, ``sonar.crosstalk_hear_probability``): range_scale, the factor on every
    echo distance and its error (speed of sound differs from the assumed one: the echo's time is converted with the
    wrong speed); bias m, added to every echo (both apply to cross-talk readings as well: they are echo times
    converted to distance like any other); crosstalk_hear_probability, the probability that a
    receiver in geometric cross-talk position actually hears the emitter (1 = always, drawn only below 1).
    update_hz (``sonar.update_hz``; 0 = every step) and update_phase s (``sonar.update_phase``): the sample-and-hold
    of the readings (:mod:`finkensim.sensors.sonar_hold`; the diagnosis fits both).
    """

    mount_yaw: np.ndarray
    offset: float
    min_range: float
    max_range: float
    error: int
    sigma: float
    rayleigh_sign: float
    rayleigh_s: float
    crosstalk: int
    crosstalk_probability: float
    half_angle: float
    cos_half_angle: float
    schedule: int
    n_slots: int
    crosstalk_jitter: float
    ray_angles: np.ndarray
    radius: float
    altitude: float
    enabled: bool
    down_enabled: bool
    range_scale: float = 1.0
    bias: float = 0.0
    crosstalk_hear_probability: float = 1.0
    update_hz: float = 0.0
    update_phase: float = 0.0
    correction: np.ndarray = np.zeros((0, 0))

    @classmethod
    def from_config(cls, cfg: Config | SonarConfig, radius: float | None = None,
                    altitude: float | None = None) -> "SonarModel":
        """Build from a whole :class:`~finkensim.config.Config` (uses ``sonar``, ``copters.radius`` and
        ``arena.altitude``) or from a ``SonarConfig`` plus ``radius`` and ``altitude`` (m)."""
        if isinstance(cfg, SonarConfig):
            sc = cfg
            if radius is None or altitude is None:
                raise ConfigError("SonarModel.from_config(SonarConfig): radius and altitude (m) are required "
                                  "(or pass the whole Config)")
        else:
            sc = cfg.sonar
            radius = cfg.copters.radius if radius is None else radius
            altitude = cfg.arena.altitude if altitude is None else altitude
        if sc.min_range > sc.max_range:
            raise ConfigError(f"sonar.min_range = {sc.min_range!r}: expected <= sonar.max_range = {sc.max_range!r} m")
        h = math.radians(sc.cone_half_angle_deg)
        return cls(
            mount_yaw=np.ascontiguousarray(np.radians(np.asarray(sc.yaw_deg, dtype=np.float64))),
            offset=float(sc.offset),
            min_range=float(sc.min_range),
            max_range=float(sc.max_range),
            error=int(ERROR_CODES[sc.error]),
            sigma=float(sc.sigma),
            rayleigh_sign=float(sc.rayleigh_sign),
            rayleigh_s=rayleigh_std(sc.sigma),
            crosstalk=int(CROSSTALK_CODES[sc.crosstalk]),
            crosstalk_probability=float(sc.crosstalk_probability),
            half_angle=float(h),
            cos_half_angle=float(math.cos(h)),
            schedule=int(SCHEDULE_CODES[sc.schedule]),
            n_slots=int(sc.n_slots),
            crosstalk_jitter=float(sc.crosstalk_jitter),
            ray_angles=np.zeros(1),
            radius=float(radius),
            altitude=float(altitude),
            enabled=bool(sc.enabled),
            down_enabled=bool(sc.down_enabled),
            range_scale=float(sc.range_scale),
            bias=float(sc.bias),
            crosstalk_hear_probability=float(sc.crosstalk_hear_probability),
            update_hz=float(sc.update_hz),
            update_phase=float(sc.update_phase),
            correction=_correction(sc),
        ).with_beam((h if sc.beam_half_angle_deg < 0.0 else math.radians(sc.beam_half_angle_deg))
                    if sc.beam == "cone" else 0.0, sc.beam_rays)

    @property
    def n_rays(self) -> int:
        return int(self.ray_angles.shape[0])

    @property
    def n_sonars(self) -> int:
        return int(self.mount_yaw.shape[0])

    def with_beam(self, half_angle: float, n_rays: int) -> "SonarModel":
        """The same model with ``n_rays`` rays spread evenly over ±``half_angle`` rad (one ray along the
        heading when ``half_angle`` is 0 or ``n_rays`` is 1), as ``beam = "cone"`` builds them."""
        if half_angle > 0.0 and n_rays > 1:
            rays = np.linspace(-half_angle, half_angle, int(n_rays))
        else:
            rays = np.zeros(1)
        return self._replace(ray_angles=np.ascontiguousarray(rays, dtype=np.float64))


def _correction(sc) -> np.ndarray:
    """The packed correction table of ``sonar.correction_file`` (:mod:`finkensim.sensors.correction_table`)."""
    if not sc.correction_file:
        return np.zeros((0, 0))
    from .correction_table import read_correction

    return read_correction(sc.correction_file, "ultrasonic", key="sonar.correction_file").packed()


#: The array fields of :class:`SonarModel`, at these positions (``sonar_scalars`` slices around them).
_ARRAY_FIELDS = ("mount_yaw", "ray_angles", "correction")
if tuple(SonarModel._fields.index(f) for f in _ARRAY_FIELDS) != (0, 15, len(SonarModel._fields) - 1):
    raise ImportError("SonarModel's array fields moved: update sonar_scalars")

SonarScalars = NamedTuple("SonarScalars", [(f, SonarModel.__annotations__[f]) for f in SonarModel._fields
                                           if f not in _ARRAY_FIELDS])
SonarScalars.__doc__ = """The scalar fields of a :class:`SonarModel` (same names and meanings), without its arrays.

The kernels hand this record, not the model, to the functions they call once per ray or reading: numba does not
always elide the reference counting of arrays handed to an inlined function (an atomic increment and decrement
each), and the model's two arrays were counted on every such call (the sonar step 8.6 → 7.75 µs per
environment-step of 10 copters without them).
:func:`sonar_scalars` builds it inside compiled code."""


@njit(cache=True, inline="always")
def sonar_scalars(sp):
    """The :class:`SonarScalars` of a :class:`SonarModel` (fields 1–14 and 16 up to the last)."""
    return SonarScalars(*(sp[1:15] + sp[16:-1]))
