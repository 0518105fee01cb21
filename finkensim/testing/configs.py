"""Hypothesis strategies for configurations: :func:`configs` (any valid config) and :func:`scenarios` (small ones
that fly in a fraction of a second).

Every range comes from the package's own declarations: the metadata of each field in :mod:`finkensim.config`
(``lo``/``hi``/open ends, ``choices``, tuple ``length``), the profiles in :data:`~finkensim.config.PROFILES`, the
sections registered in :data:`~finkensim.config.SECTIONS` (a section a plug-in registers is generated too) and
the effect catalogue :data:`finkensim.gap.attribute.effects.REGISTRY` (``gap.effects``). Nothing is copied by hand, so a
range changed in ``config.py`` changes what is generated.

Shrinking: each key is either left at its (profile) default or drawn, and "left at its default" is what
Hypothesis shrinks toward, so a minimal counterexample is the default configuration plus the few keys that
matter.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterable, Mapping

from hypothesis import assume as reject_unless
from hypothesis import strategies as st

__all__ = ["configs", "scenarios", "field_values", "config_toml", "toml_value", "SCENARIO_BOUNDS", "SCENARIO_SECTIONS"]

SCENARIO_SECTIONS = ("arena", "walls", "copters", "simulation", "behaviour", "sonar", "ranging", "imu")
"""Sections :func:`scenarios` varies (everything a flight uses; ``gap`` is the diagnosis's)."""

SCENARIO_BOUNDS: dict[str, tuple[float, float]] = {
    "arena.width": (0.5, 8.0), "arena.length": (0.5, 8.0),
    "walls.n_segments": (1, 20), "walls.substeps": (1, 20),
    "copters.n": (1, 6),
    # a copter accelerating at tens of m/s^2 logs accelerations the flight-log loader reads as cm/s^2 (median > 50)
    "copters.max_accel": (0.01, 20.0),
    "simulation.dt": (0.01, 0.2), "simulation.n_envs": (1, 3),
    "behaviour.redraw_steps": (1, 50),
    "sonar.beam_rays": (1, 9), "sonar.n_slots": (1, 8), "ranging.max_range": (0.1, 10.0),
    # IMU noise well above a real sensor's, yet below what the flight-log loader's unit check reads as cm/s^2
    "imu.acc_noise_density": (0.0, 1.0), "imu.acc_bias_walk": (0.0, 1.0),
}
"""Narrower ranges :func:`scenarios` uses so that a flight is small (each inside the declared range)."""

# strings without declared choices: where their valid values come from (others keep their default: a file
# name such as ranging.mixture_file is not generated)
_STRING_CHOICES = {"gap.effects": lambda: sorted(__import__("finkensim.gap.attribute.effects", fromlist=["REGISTRY"]).REGISTRY)}

_MAX_STEPS = 1e9  # most steps of a drawn flight (before the memory cap)
_MAX_LATENCY_STEPS = 50  # most steps of a drawn sensor latency (its ring buffer holds that many readings)
_MAX_LIST = 3  # longest list drawn for a list field of any length (ranging.beacons, gap.effects)


def _fields(section: str):
    from ..config import SECTIONS

    return {f.name: f for f in dataclasses.fields(SECTIONS[section])}


def _type_name(f) -> str:
    return f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))


def _narrow(dotted: str, meta: Mapping, bounds: tuple[float, float] | None) -> tuple[Any, Any, bool, bool]:
    """(lo, hi, lo_open, hi_open) of a number field, narrowed to ``bounds`` (which must lie inside it)."""
    lo, hi, lo_open, hi_open = meta["lo"], meta["hi"], meta["lo_open"], meta["hi_open"]
    if bounds is None:
        return lo, hi, lo_open, hi_open
    blo, bhi = bounds
    if blo > bhi:
        raise ValueError(f"bounds[{dotted!r}] = {bounds!r}: expected (low, high) with low <= high")
    if (lo is not None and (blo < lo or (blo == lo and lo_open))) or (hi is not None and (bhi > hi or (bhi == hi and hi_open))):
        from ..config import SECTIONS, describe

        section, key = dotted.split(".")
        allowed = next(row[3] for row in describe(SECTIONS[section]) if row[0] == key)
        raise ValueError(f"bounds[{dotted!r}] = {bounds!r}: expected a range inside the declared {allowed}")
    return blo, bhi, False, False


def _numbers(kind: str, lo, hi, lo_open: bool, hi_open: bool) -> st.SearchStrategy:
    if kind == "int":
        return st.integers(None if lo is None else math.ceil(lo) + (1 if lo_open and lo == math.ceil(lo) else 0),
                           None if hi is None else math.floor(hi) - (1 if hi_open and hi == math.floor(hi) else 0))
    return st.floats(lo, hi, exclude_min=bool(lo_open and lo is not None), exclude_max=bool(hi_open and hi is not None),
                     allow_nan=False, allow_infinity=False, allow_subnormal=False)


def field_values(section: str, key: str, bounds: tuple[float, float] | None = None) -> st.SearchStrategy:
    """Values of config key ``section.key`` that its own validator accepts (from the field's metadata).

    ``bounds`` (low, high) narrows a number field (or each number of a list field); it must lie inside the
    declared range. Strings draw from their ``choices``; lists of strings from their known names (``gap.effects``:
    the effect catalogue); a free string (a file name) is only its default.
    """
    fields = _fields(section)
    if key not in fields:
        from ..config import check_key

        check_key(section, key)
    f = fields[key]
    meta, t, dotted = f.metadata, _type_name(f), f"{section}.{key}"
    default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    if t == "bool":
        return st.booleans()
    if t == "str":
        if meta["choices"] is None:
            return st.just(default)
        # the built-in names of a registry (NameRegistry): what a session registered does not change the draws
        return st.sampled_from(getattr(meta["choices"], "builtin", meta["choices"]))
    if t == "tuple[str, ...]":
        if dotted not in _STRING_CHOICES:
            return st.just(default)
        return st.lists(st.sampled_from(_STRING_CHOICES[dotted]()), max_size=_MAX_LIST, unique=True).map(tuple)
    if t in ("int", "float"):
        return _numbers(t, *_narrow(dotted, meta, bounds))
    if t.startswith("tuple"):
        number = _numbers("float", *_narrow(dotted, meta, bounds))
        if "tuple[float, float]" in t or "tuple[tuple" in t:  # a list of 2-D points
            return st.lists(st.tuples(number, number), max_size=_MAX_LIST).map(tuple)
        if meta["length"] is not None:
            return st.tuples(*[number] * meta["length"])
        return st.lists(number, max_size=_MAX_LIST).map(tuple)
    raise TypeError(f"{dotted}: no strategy for field type {t}")  # a new field type: teach this function


def _within(value: Any, bounds: tuple[float, float]) -> bool:
    """Whether a number, or every number of a list (of points), lies in [low, high]."""
    values = value if isinstance(value, tuple) else (value,)
    flat = [v for item in values for v in (item if isinstance(item, tuple) else (item,))]
    return all(bounds[0] <= v <= bounds[1] for v in flat)


class _Draft:
    """The keys drawn so far (explicit values by section) over the profile's defaults."""

    def __init__(self, profile: str, data: dict[str, dict[str, Any]], fixed: set[str]):
        self.profile, self.data, self.fixed = profile, data, fixed

    def get(self, dotted: str) -> Any:
        from ..config import PROFILES

        sec, key = dotted.split(".")
        if key in self.data.get(sec, {}):
            return self.data[sec][key]
        if key in PROFILES[self.profile].get(sec, {}):
            return PROFILES[self.profile][sec][key]
        f = _fields(sec)[key]
        return f.default if f.default is not dataclasses.MISSING else f.default_factory()

    def set(self, dotted: str, value: Any) -> None:
        sec, key = dotted.split(".")
        self.data.setdefault(sec, {})[key] = value

    def settable(self, dotted: str) -> bool:
        return dotted not in self.fixed

    def as_dict(self) -> dict[str, Any]:
        return {"profile": self.profile, **self.data}


def _require(d: _Draft, when: str, value: Any, needs: str, why: str) -> None:
    """If key ``when`` equals ``value``, boolean key ``needs`` must be true: set it, or undo ``when`` to its default."""
    if d.get(when) != value or d.get(needs):
        return
    if d.settable(needs):
        d.set(needs, True)
        return
    fields = _fields(when.split(".")[0])
    default = fields[when.split(".")[1]].default
    if d.settable(when) and default != value:
        d.set(when, default)
        return
    raise ValueError(f"fixed {when} = {value!r} with {needs} = false: {why}; no valid config has both")


def _combine(draw, d: _Draft, max_flight_bytes: float) -> None:
    """Make the drawn keys a combination ``finkensim run`` accepts (the cross-key checks of config.py,
    World.init, SonarModel and SwarmSim), changing only keys that were not fixed; shrinks with the draws."""
    from ..budget import flight_arrays
    from ..config import MAX_ACC_SAMPLE_NOISE, PACKING_DENSITY, config_from_dict

    if d.get("walls.plate_length") > d.get("walls.hinge_height"):
        target = "walls.plate_length" if d.settable("walls.plate_length") else "walls.hinge_height"
        d.set(target, d.get("walls.hinge_height") if target == "walls.plate_length" else d.get("walls.plate_length"))
    if d.get("sonar.min_range") > d.get("sonar.max_range"):
        target = "sonar.min_range" if d.settable("sonar.min_range") else "sonar.max_range"
        d.set(target, d.get("sonar.max_range") if target == "sonar.min_range" else d.get("sonar.min_range"))
    width, length = d.get("arena.width"), d.get("arena.length")
    if 2 * d.get("copters.radius") >= min(width, length) and d.settable("copters.radius"):
        d.set("copters.radius", draw(st.floats(1e-3 * min(width, length), 0.45 * min(width, length))))
    body = math.pi * d.get("copters.radius") ** 2  # m^2 (0 for a subnormal radius: room for any number)
    if body > 0 and d.get("copters.n") * body > PACKING_DENSITY * width * length and d.settable("copters.n"):
        d.set("copters.n", max(1, int(PACKING_DENSITY * width * length / body)))
    _require(d, "behaviour.kind", "attraction_repulsion", "sonar.enabled", "attraction-repulsion steers by the sonars")
    for mode, sensors in (("per_reading", ("sonar", "ranging")), ("sequence", ("sonar", "ranging", "imu"))):
        for sensor in sensors:
            _require(d, "behaviour.wall_check", mode, f"{sensor}.enabled", "the wall check compares sensors")
    dt, duration = d.get("simulation.dt"), d.get("simulation.duration")
    noise_cap = MAX_ACC_SAMPLE_NOISE * math.sqrt(dt)  # config.py: white accelerometer noise per sample
    if d.get("imu.acc_noise_density") > noise_cap:
        target = "imu.acc_noise_density" if d.settable("imu.acc_noise_density") else "simulation.dt"
        if target == "imu.acc_noise_density":
            d.set(target, noise_cap)
        else:
            dt = (d.get("imu.acc_noise_density") / MAX_ACC_SAMPLE_NOISE) ** 2
            d.set("simulation.dt", dt)
    for sensor in ("sonar", "ranging", "imu"):  # a latency of many steps is a ring buffer of that many readings
        key = f"{sensor}.latency"
        if d.get(key) > _MAX_LATENCY_STEPS * dt and d.settable(key):
            d.set(key, _MAX_LATENCY_STEPS * dt)
    if duration < dt and d.settable("simulation.duration"):
        d.set("simulation.duration", dt)
    if duration / dt > _MAX_STEPS and d.settable("simulation.duration"):  # (also overflows budget.flight_arrays)
        d.set("simulation.duration", dt * _MAX_STEPS)
    cfg = config_from_dict(d.as_dict())
    total = sum(flight_arrays(cfg).values())
    if total > max_flight_bytes and d.settable("simulation.duration"):
        steps = max(1.0, (max_flight_bytes / total) * (cfg.simulation.duration / cfg.simulation.dt))
        d.set("simulation.duration", cfg.simulation.dt * math.floor(steps))
        total = sum(flight_arrays(config_from_dict(d.as_dict())).values())
    if total > max_flight_bytes and d.settable("copters.n"):
        per_copter_sq = total / max(cfg.copters.n, 1) ** 2  # ranging grows as N^2, the rest slower
        d.set("copters.n", max(1, min(cfg.copters.n, int(math.sqrt(max_flight_bytes / per_copter_sq)))))


@st.composite
def configs(draw, sections: Iterable[str] | None = None, *, bounds: Mapping[str, tuple[float, float]] | None = None,
            fixed: Mapping[str, Any] | None = None, profiles: Iterable[str] | None = None,
            max_flight_bytes: float = 64 * 2**20):
    """Valid :class:`~finkensim.config.Config` objects: any section, every key within its declared range, in
    combinations ``finkensim run`` accepts.

    Args:
        sections: config sections whose keys are drawn (default: every registered section); the other keys keep
            their (profile) defaults.
        bounds: ``{"copters.n": (1, 4), ...}``: narrower ranges for number keys (each inside the declared range;
            a list key's numbers each), drawn also when their section is not in ``sections``: always when the
            default lies outside the bounds, else like any other key (shrinking to its default).
        fixed: ``{"behaviour.kind": "hover", ...}``: keys set to these values (checked by the config itself).
        profiles: profiles to draw from (default: every one in :data:`~finkensim.config.PROFILES`).
        max_flight_bytes: the arrays of one recorded flight (:func:`finkensim.budget.flight_arrays`) stay below
            this, so a run never meets the memory check: ``simulation.duration``, then ``copters.n``, are lowered.

    Cross-key rules are kept by construction, changing only keys not in ``fixed``: plates no longer than their
    hinge height, ``sonar.min_range <= sonar.max_range``, copters that fit in the arena (``World.init``) and
    within its packing room, the sensors a behaviour or wall check reads enabled (``SwarmSim``), at least one
    step. A combination of ``fixed`` keys no config allows is a ValueError.
    """
    from ..config import PROFILES, SECTIONS, check_key, config_from_dict

    bounds = dict(bounds or {})
    fixed = dict(fixed or {})
    for dotted in [*bounds, *fixed]:
        section, _, key = dotted.partition(".")
        check_key(section, key or None)
    names = list(SECTIONS) if sections is None else list(sections)
    for name in names:
        check_key(name)
    profile = draw(st.sampled_from(sorted(PROFILES, key=lambda p: p != "default") if profiles is None else list(profiles)))
    data: dict[str, dict[str, Any]] = {}
    base = _Draft(profile, {}, set())

    def violates(dotted: str) -> bool:  # the (profile) default lies outside the key's bounds
        return dotted in bounds and not _within(base.get(dotted), bounds[dotted])

    keys = [f"{sec}.{key}" for sec in names for key in _fields(sec)]
    keys += [k for k in bounds if k not in keys]
    for dotted in keys:
        if dotted in fixed:
            continue
        sec, key = dotted.split(".")
        if violates(dotted) or draw(st.booleans()):  # shrinks to False: the key keeps its default
            data.setdefault(sec, {})[key] = draw(field_values(sec, key, bounds.get(dotted)))
    for dotted, value in fixed.items():
        sec, key = dotted.split(".")
        data.setdefault(sec, {})[key] = value
    draft = _Draft(profile, data, set(fixed))
    _combine(draw, draft, max_flight_bytes)
    for dotted, pair in bounds.items():  # a combination rule moved a bounded key out: not this example
        reject_unless(_within(draft.get(dotted), pair))
    return config_from_dict(draft.as_dict())


@st.composite
def scenarios(draw, *, max_copters: int = 6, max_steps: int = 40, sections: Iterable[str] = SCENARIO_SECTIONS,
              bounds: Mapping[str, tuple[float, float]] | None = None, fixed: Mapping[str, Any] | None = None,
              profiles: Iterable[str] | None = None):
    """Small flyable scenarios: :func:`configs` of the flight's sections within :data:`SCENARIO_BOUNDS`, with at
    most ``max_copters`` copters and 1 to ``max_steps`` steps (``simulation.duration`` = steps x
    ``simulation.dt`` unless fixed), so a flight takes milliseconds once compiled. ``bounds`` and ``fixed``
    refine further (as in :func:`configs`)."""
    sections = tuple(sections)
    merged = {}
    for dotted, pair in {**SCENARIO_BOUNDS, "copters.n": (1, int(max_copters))}.items():
        section, key = dotted.split(".")
        default = _fields(section)[key].default
        if section in sections or not _within(default, pair):  # keys of other sections stay at their defaults
            merged[dotted] = pair
    merged.update(bounds or {})
    fixed = dict(fixed or {})
    cfg = draw(configs(sections, bounds=merged, fixed=fixed, profiles=profiles))
    if "simulation.duration" in fixed or "simulation.duration" in (bounds or {}):
        return cfg
    steps = draw(st.integers(1, max(1, int(max_steps))))
    return cfg.replace({"simulation.duration": cfg.simulation.dt * steps})


def toml_value(v: Any) -> str:
    """``v`` (bool, int, float incl. nan/inf, str, list/tuple, dict) as a TOML value; floats at full precision."""
    import json

    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"no TOML form for {type(v).__name__} {v!r}")


def config_toml(cfg) -> str:
    """A scenario file (TOML text) that :func:`~finkensim.config.load_config` reads back as ``cfg``, every key
    written."""
    data = cfg.to_dict()
    lines = [f"profile = {toml_value(data.pop('profile'))}"]
    for section, values in data.items():
        lines.append(f"\n[{section}]")
        lines += [f"{key} = {toml_value(value)}" for key, value in values.items()]
    return "\n".join(lines) + "\n"
