"""Withheld-effect validation: does the diagnosis name the right effect on data where we know it?

Each case generates "real" flights with the simulator plus one effect switched on at a random
strength, then diagnoses them with a model that lacks that effect. All flights carry tracking
noise on the logged poses (declared in ``meta``). Effects the simulator models itself (bending
walls, geometric and constant cross-talk, beam width, Rayleigh scale) are switched on in its
config; the others are applied to the simulated log by code written here, independently of the
diagnosis's own effect models. Controls: ``null`` (nothing withheld: no gap should be found)
and two effects outside the catalogue, ``foreign`` (false first-path detection: 8–15 % of ranging readings read
0.3–1 m short; the catalogue's NLOS tail reads long, a bias or scale moves every reading) and
``foreign_multipath`` (sonar multipath ghosts that read long): the verdict must be ``unexplained``. The radio effects
(``ranging_bias``, ``_scale``, ``_antenna_offset``, ``_node_delay``, ``_nlos_tail``) are flown by the simulator
through their ``[ranging]`` config keys.
"""
from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ...config import Config, load_config
from ...flightlog import FlightLog
from ...scenario import simulate_flight
from .conventions import DEFAULT_CONVENTIONS, Conventions, draw_conventions
from ..diagnosis import Diagnosis
from ..pipeline import run_diagnosis
from ..attribute.effects import REGISTRY


BASE_UPDATES = {"walls.bending": False, "sonar.crosstalk": "off", "sonar.error": "rayleigh", "sonar.sigma": 0.05,
                "ranging.error": "mixture", "behaviour.kind": "random_walk"}


@dataclass
class Case:
    """A withheld effect: ``make(rng)`` → (simulator config updates, log post-process or None, truth dict)."""

    name: str
    effect: str | None  # catalogued effect expected first; None for null/foreign
    make: Callable
    sensor: str | None = None  # sensor where the gap should be located
    effects: tuple[str, ...] = ()  # a pair: every effect that must be named


def _sign(rng):
    return 1.0 if rng.random() < 0.5 else -1.0


def _echo_mask(log: FlightLog, max_range: float) -> np.ndarray:
    """Readings that came from an echo (ideal hit within range) in a log with ideal extras."""
    return log.extras["ultrasonic_hit_type"] > 0


def _post_sonar_bias(b):
    def f(log, cfg, rng):
        m = _echo_mask(log, cfg.sonar.max_range)
        log.ultrasonic = np.where(m, np.clip(log.ultrasonic + b, cfg.sonar.min_range, cfg.sonar.max_range), log.ultrasonic)
    return f


def _post_sound_speed(k):
    def f(log, cfg, rng):
        m = _echo_mask(log, cfg.sonar.max_range)
        log.ultrasonic = np.where(m, np.clip(log.ultrasonic * k, cfg.sonar.min_range, cfg.sonar.max_range), log.ultrasonic)
    return f


def _post_latency(sensor, seconds, truth):
    """Delay one sensor's readings by ``seconds`` (whole log samples, at least one); ``truth[sensor]`` becomes
    the delay actually applied (s). The lag is drawn in seconds so that its strength does not depend on the
    logging rate of the conventions axis."""
    def f(log, cfg, rng):
        steps = max(1, int(round(seconds / cfg.simulation.dt)))
        truth[sensor] = steps * cfg.simulation.dt

        def shift(a):
            out = a.copy()
            out[steps:] = a[:-steps]
            return out

        if sensor == "ultrasonic":
            log.ultrasonic = shift(log.ultrasonic)
        elif sensor == "ranging":
            log.ranging = shift(log.ranging)
        else:
            log.imu_acc, log.imu_gyro = shift(log.imu_acc), shift(log.imu_gyro)
    return f


def _true_clearance(pos):
    """(T, N, N) smallest distance of a third copter's centre to each line of sight."""
    T, N, _ = pos.shape
    out = np.full((T, N, N), np.inf)
    for a in range(N):
        for b in range(a + 1, N):
            A, B = pos[:, a], pos[:, b]
            AB = B - A
            L2 = np.maximum((AB ** 2).sum(-1), 1e-12)
            for c in range(N):
                if c in (a, b):
                    continue
                s = np.clip(((pos[:, c] - A) * AB).sum(-1) / L2, 0.0, 1.0)
                d = np.sqrt(((A + s[:, None] * AB - pos[:, c]) ** 2).sum(-1))
                out[:, a, b] = np.minimum(out[:, a, b], d)
                out[:, b, a] = out[:, a, b]
    return out


def _post_nlos(bias, width, true_pose):
    def f(log, cfg, rng):
        clear = _true_clearance(true_pose[:, :, :2])
        add = bias * np.exp(-(clear / width) ** 2)
        inside = log.extras["ranging_ideal"] < cfg.ranging.max_range
        np.fill_diagonal(add[0], 0.0)
        log.ranging = np.where(inside, np.maximum(log.ranging + add, 0.0), log.ranging)
        for t in range(log.ranging.shape[0]):
            np.fill_diagonal(log.ranging[t], 0.0)
    return f


def _post_dropout(a, b):
    def f(log, cfg, rng):
        d = log.extras["ranging_ideal"]
        p = 1.0 / (1.0 + np.exp(-(a + b * d)))
        drop = rng.random(d.shape) < p
        N = d.shape[1]
        drop[:, np.arange(N), np.arange(N)] = False
        log.ranging = np.where(drop, np.nan, log.ranging)
    return f


def _post_imu_bias(bx, by, bg):
    def f(log, cfg, rng):
        log.imu_acc = log.imu_acc + np.array([bx, by])
        log.imu_gyro = log.imu_gyro + bg
    return f


def _post_sonar_multipath(p_ghost, lo, hi):
    """Multipath ghosts: with probability p an echo reads long by U(lo, hi) m (a second-bounce path)."""
    def f(log, cfg, rng):
        m = _echo_mask(log, cfg.sonar.max_range) & (rng.random(log.ultrasonic.shape) < p_ghost)
        extra = rng.uniform(lo, hi, log.ultrasonic.shape)
        log.ultrasonic = np.where(m, np.minimum(log.ultrasonic + extra, cfg.sonar.max_range), log.ultrasonic)
    return f


def _post_ranging_early(p_early, lo, hi):
    """False first-path detection: with probability p a reading triggers on noise before the true first path and
    reads short by U(lo, hi) m (clipped at 0). No catalogued effect reads short by a random amount in a fraction
    of readings (the NLOS tail reads long; a bias or a scale moves every reading)."""
    def f(log, cfg, rng):
        d = log.extras["ranging_ideal"]
        hit = (d < cfg.ranging.max_range) & (rng.random(d.shape) < p_early)
        N = d.shape[1]
        hit[:, np.arange(N), np.arange(N)] = False
        log.ranging = np.where(hit, np.maximum(log.ranging - rng.uniform(lo, hi, d.shape), 0.0), log.ranging)
    return f


def _antenna_case(r):
    """A tag 0.1-0.25 m off the centre in a random body-frame direction."""
    radius, angle = float(r.uniform(0.1, 0.25)), float(r.uniform(-np.pi, np.pi))
    x, y = radius * math.cos(angle), radius * math.sin(angle)
    return {"ranging.antenna_offset": [x, y, 0.0]}, None, {"x": x, "y": y}


def _node_delay_case(r):
    """Every node's own delay in ±(0.05 … 0.2) m (nodes beyond the swarm are unused)."""
    delays = [_sign(r) * float(r.uniform(0.05, 0.2)) for _ in range(10)]
    return {"ranging.node_delay": delays}, None, {f"delay_{k}": d for k, d in enumerate(delays)}


#: catalogued effects whose model another effect's model contains exactly, so the other alone reproduces both: a
#: constant ranging offset b reads as every node's delay raised by b / 2, since a pair reads the sum of its two
#: nodes' delays (``finkensim.sensors.ranging_radio.radio_line``; ``tests/test_gap_validate_nesting.py`` flies both).
#: A trial that withholds both is explained exactly by the larger effect alone; parsimony should then name only it.
NESTED: dict[str, str] = {"ranging_bias": "ranging_node_delay"}


def essential(effects) -> set[str]:
    """``effects`` without those nested (:data:`NESTED`) in another of them: what a parsimonious verdict names.

    Parameters
    ----------
    effects : iterable of str
        Effect names.

    Returns
    -------
    set of str
    """
    effects = set(effects)
    return {e for e in effects if NESTED.get(e) not in effects}


def pair_right(significant: bool, unexplained: bool, named, withheld) -> bool:
    """A trial withholding several effects is right when its verdict is a significant, explained gap whose effects
    explain every withheld one (:func:`explains`).

    Parameters
    ----------
    significant, unexplained : bool
        The verdict's ``significant_gap`` and ``unexplained``.
    named, withheld : iterable of str
        The verdict's effects and the trial's withheld ones.

    Returns
    -------
    bool
    """
    return bool(significant) and not unexplained and explains(named, withheld)


def explains(named, withheld) -> bool:
    """Every withheld effect is named, or nested (:data:`NESTED`) in a named one, so the named model reproduces the
    truth.

    Parameters
    ----------
    named, withheld : iterable of str
        The verdict's effects and the trial's withheld ones.

    Returns
    -------
    bool
    """
    named = set(named)
    return all(e in named or NESTED.get(e) in named for e in withheld)


CASES: dict[str, Case] = {
    "null": Case("null", None, lambda r: ({}, None, {})),
    "wall_bulge": Case("wall_bulge", "wall_bulge", lambda r: (
        {"walls.bending": True, "walls.max_amplitude_deg": (a := float(r.uniform(25, 40)))}, None,
        {"_max_amplitude_deg": a}), "ultrasonic"),
    "crosstalk_geometric": Case("crosstalk_geometric", "crosstalk_geometric", lambda r: (
        {"sonar.crosstalk": "geometric", "sonar.schedule": "simultaneous",
         "sonar.cone_half_angle_deg": (c := float(r.uniform(35, 50)))}, None,
        {"probability": 1.0, "cone_half_angle_deg": c}), "ultrasonic"),
    "crosstalk_constant": Case("crosstalk_constant", "crosstalk_constant", lambda r: (
        {"sonar.crosstalk": "constant", "sonar.crosstalk_probability": (p := float(r.uniform(0.1, 0.4)))}, None,
        {"probability": p}), "ultrasonic"),
    "sonar_rayleigh_scale": Case("sonar_rayleigh_scale", "sonar_rayleigh_scale", lambda r: (
        {"sonar.sigma": 0.05 * (k := float(r.uniform(2.5, 4.0)))}, None, {"scale": k}), "ultrasonic"),
    "sonar_bias": Case("sonar_bias", "sonar_bias", lambda r: (
        {}, _post_sonar_bias(b := _sign(r) * float(r.uniform(0.05, 0.15))), {"bias": b}), "ultrasonic"),
    "beam_width": Case("beam_width", "beam_width", lambda r: (
        {"sonar.beam": "cone", "sonar.beam_rays": 9, "sonar.cone_half_angle_deg": (h := float(r.uniform(15, 30)))},
        None, {"half_angle_deg": h}), "ultrasonic"),
    "sound_speed": Case("sound_speed", "sound_speed", lambda r: (
        {}, _post_sound_speed(k := 1.0 + _sign(r) * float(r.uniform(0.06, 0.12))), {"factor": k}), "ultrasonic"),
    # held at 2-4.5 Hz: at least two samples per measurement at every logging rate of the conventions (10-50 Hz)
    "sonar_update_rate": Case("sonar_update_rate", "sonar_update_rate", lambda r: (
        {"sonar.update_hz": (hz := float(r.uniform(2.0, 4.5)))}, None, {"rate_hz": hz}), "ultrasonic"),
    "latency": Case("latency", "latency", lambda r: (
        {}, _post_latency(s := ("ultrasonic", "ranging", "imu")[int(r.integers(3))], float(r.uniform(0.15, 0.4)),
                          truth := {"_sensor": s}), truth)),
    "ranging_nlos": Case("ranging_nlos", "ranging_nlos", lambda r: (
        {"copters.n": 8}, ("nlos", b := float(r.uniform(0.2, 0.4)), w := float(r.uniform(0.15, 0.3))),
        {"bias": b, "width": w}), "ranging"),
    "ranging_dropout": Case("ranging_dropout", "ranging_dropout", lambda r: (
        {}, _post_dropout(a := float(r.uniform(-4.0, -3.0)), b := float(r.uniform(1.0, 2.0))), {"a": a, "b": b}),
        "ranging"),
    "pose_noise": Case("pose_noise", "pose_noise", lambda r: (
        {}, ("pose", s := float(r.uniform(0.01, 0.025))), {"sigma_xy": s})),
    "imu_bias": Case("imu_bias", "imu_bias", lambda r: (
        {}, _post_imu_bias(bx := _sign(r) * float(r.uniform(0.05, 0.2)), by := _sign(r) * float(r.uniform(0.05, 0.2)),
                           bg := _sign(r) * float(r.uniform(0.01, 0.05))),
        {"acc_x": bx, "acc_y": by, "gyro": bg}), "imu"),
    "ranging_bias": Case("ranging_bias", "ranging_bias", lambda r: (
        {"ranging.bias": (b := _sign(r) * float(r.uniform(0.08, 0.2)))}, None, {"bias": b}), "ranging"),
    "ranging_scale": Case("ranging_scale", "ranging_scale", lambda r: (
        {"ranging.scale": (k := 1.0 + _sign(r) * float(r.uniform(0.06, 0.12)))}, None, {"factor": k}), "ranging"),
    "ranging_antenna_offset": Case("ranging_antenna_offset", "ranging_antenna_offset", _antenna_case, "ranging"),
    "ranging_node_delay": Case("ranging_node_delay", "ranging_node_delay", _node_delay_case, "ranging"),
    "ranging_nlos_tail": Case("ranging_nlos_tail", "ranging_nlos_tail", lambda r: (
        {"ranging.nlos_tail_probability": (p := float(r.uniform(0.1, 0.25))),
         "ranging.nlos_tail_mean": (m := float(r.uniform(0.2, 0.5)))}, None, {"probability": p, "mean": m}),
        "ranging"),
    "foreign": Case("foreign", None, lambda r: (
        {}, _post_ranging_early(float(r.uniform(0.08, 0.15)), 0.3, 1.0), {}), "ranging"),
    "foreign_multipath": Case("foreign_multipath", None, lambda r: (
        {}, _post_sonar_multipath(float(r.uniform(0.08, 0.15)), 0.3, 1.0), {}), "ultrasonic"),
}
"""Every ``gap-validate`` case by name: ``null``, each catalogued effect, the foreign controls."""


def base_config(updates: dict | None = None) -> Config:
    """The diagnosed model: defaults with rigid walls and no cross-talk (each case adds one effect)."""
    return load_config().replace({**BASE_UPDATES, **(updates or {})})


def generate(case: Case, seed: int, n_flights: int = 2, duration: float = 60.0, n_copters: int | None = None,
             conventions: Conventions | None = None, flights_from: int = 0):
    """Simulated "real" flights with the case's effect at a random strength, recorded in ``conventions``
    (default :data:`~finkensim.gap.validation.conventions.DEFAULT_CONVENTIONS`; ``n_copters`` overrides its swarm size).

    Returns (logs, base config for the diagnosis, truth dict). Poses carry the conventions' tracking noise
    (declared in meta) unless the case is ``pose_noise``, whose noise is larger than declared. For
    ``wall_bulge`` the simulated walls hang from a hinge at least 0.4 m above the flight (so they bend at any
    altitude) while the diagnosed model keeps its own, possibly rigid, walls. ``flights_from``: the index of the
    first flight (other flights of the same truth: ``gap-validate --calibrate``).
    """
    conv = conventions or DEFAULT_CONVENTIONS
    if n_copters is not None:
        conv = replace(conv, n_copters=int(n_copters))
    rng = np.random.default_rng(seed)
    updates, post, truth = case.make(rng)
    extra = {}
    if updates.get("walls.bending"):  # bending walls in the "real" flight: give them a lever at any altitude
        extra["walls.hinge_height"] = max(1.0, conv.altitude + 0.4)
    sim_cfg = base_config({**conv.sim_updates(), **extra, **updates})
    diag_cfg = base_config({"copters.n": conv.n_copters, **conv.diag_updates()})
    logs = []
    for i in range(n_flights):
        log, traj, _ = simulate_flight(sim_cfg, duration=duration, seed=int(seed * 1000 + flights_from + i), ideal=True)
        true_pose = log.pose.copy()
        sx, sy = conv.tracking_sigma_xy, conv.tracking_sigma_yaw
        for pp in (post if isinstance(post, list) else [post]):
            if isinstance(pp, tuple) and pp[0] == "pose":
                sx = pp[1]
            elif isinstance(pp, tuple) and pp[0] == "nlos":
                _post_nlos(pp[1], pp[2], true_pose)(log, sim_cfg, rng)
            elif callable(pp):
                pp(log, sim_cfg, rng)
        conv.record(log, sim_cfg, rng)
        noise = rng.normal(size=log.pose.shape) * np.array([sx, sx, sy])
        pose = log.pose + noise
        r = sim_cfg.copters.radius
        pose[..., 0] = np.clip(pose[..., 0], 0.0, log.arena[0])
        pose[..., 1] = np.clip(pose[..., 1], 0.0, log.arena[1])
        log.pose = pose
        log.meta = {**log.meta, "tracking_sigma_xy": conv.tracking_sigma_xy,
                    "tracking_sigma_yaw": conv.tracking_sigma_yaw,
                    "source": f"finkensim gap-validate case {case.name}", "copter_radius": r}
        for k in [k for k in log.extras if k.endswith("_ideal") or k == "ultrasonic_hit_type"]:
            del log.extras[k]
        logs.append(log)
    # per-node truths of nodes the swarm does not have (ranging_node_delay draws ten) are not the log's
    truth = {k: v for k, v in truth.items() if not (k.startswith("delay_") and int(k[6:]) >= conv.n_copters)}
    return logs, diag_cfg, truth


def location_ok(report: dict, case: Case, truth: dict) -> bool | None:
    """Whether the top significant location lies on the case's sensor (and an expected feature)."""
    sensor = truth.get("_sensor", case.sensor)
    if case.effect is None and case.name == "null":
        return None
    sig = report.details.significant_locations
    if not sig:
        return False
    top = report["locations"][sig[0]] if sig else None
    if sensor is not None and top["sensor"] != sensor:
        return False
    if case.effect and REGISTRY[case.effect].expected_features:
        feats = REGISTRY[case.effect].expected_features
        return any(report["locations"][i]["feature"] in feats for i in sig[:3]
                   if report["locations"][i]["sensor"] == top["sensor"])
    return True


def param_error(report: dict, case: Case, truth: dict) -> float:
    """Largest relative error of the fitted parameters (those in the truth) of the case's effect."""
    if not case.effect:
        return math.nan
    eff = next((e for e in report["effects"] if e["name"] == case.effect), None)
    if eff is None:
        return math.nan
    errs = []
    for k, v in truth.items():
        if k.startswith("_") or k not in eff["params"]:
            continue
        errs.append(abs(eff["params"][k] - v) / max(abs(v), 1e-9))
    return float(max(errs)) if errs else math.nan


def pair_case(a: str, b: str) -> Case:
    """Both catalogued effects ``a`` and ``b`` at once (each at its own random strength). ValueError when
    they need different values of the same simulator setting (e.g. two cross-talk modes)."""
    ca, cb = CASES[a], CASES[b]
    if ca.effect is None or cb.effect is None or a == b:
        raise ValueError(f"pair {a!r} + {b!r}: expected two different catalogued effects")

    def make(rng):
        ua, pa, ta = ca.make(rng)
        ub, pb, tb = cb.make(rng)
        clash = sorted(k for k in ua.keys() & ub.keys() if ua[k] != ub[k])
        if clash:
            raise ValueError(f"pair {a!r} + {b!r}: both set {', '.join(clash)}")
        truth = {}

        def merge():  # a post-process may fill in its truth when it runs (the latency in whole samples)
            truth.update({f"{a}.{k}": v for k, v in ta.items()} | {f"{b}.{k}": v for k, v in tb.items()})

        def after(post):
            if not callable(post):
                return post

            def run(log, cfg, rng):
                post(log, cfg, rng)
                merge()
            return run

        merge()
        return {**ua, **ub}, [after(pa), after(pb)], truth

    return Case(f"{a}+{b}", a, make, None, effects=(a, b))


def all_pairs() -> list[str]:
    """Names ``a+b`` of every pair of catalogued effects that can be simulated together."""
    names = [c.name for c in CASES.values() if c.effect is not None]
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            try:
                pair_case(a, b).make(np.random.default_rng(0))
            except ValueError:
                continue
            out.append(f"{a}+{b}")
    return out


def expand_cases(cases: list[str] | None, pairs: bool = False) -> list[str]:
    """The case names to run: ``cases`` (default: every single case and control), with the name ``pairs`` standing
    for every pair (:func:`all_pairs`), and every pair added when ``pairs`` is true; in order, each once."""
    out = []
    for c in list(cases or CASES) + (["pairs"] if pairs else []):
        for name in (all_pairs() if c == "pairs" else [c]):
            if name not in out:
                out.append(name)
    return out


def get_case(name: str) -> Case:
    """A case by name: a key of :data:`CASES` or a pair ``a+b``."""
    if name in CASES:
        return CASES[name]
    if "+" in name:
        a, b = name.split("+", 1)
        if a in CASES and b in CASES:
            return pair_case(a, b)
    raise KeyError(name)


def run_case(name: str, seed: int, n_flights=2, duration=60.0, n_copters=None, progress=None,
             conventions: Conventions | str | None = None, keep: dict | None = None) -> dict:
    """Generate and diagnose one trial; returns a result row. conventions: a :class:`Conventions`, "random"
    (drawn from the axis, keyed by the case name and the seed) or None (the defaults); ``keep`` (a dict, filled in):
    the report and the conventions used."""
    case = get_case(name)
    if conventions == "random":  # its own point of the axis per (case, seed)
        conventions = draw_conventions(np.random.default_rng([seed, zlib.crc32(name.encode())]))
    t0 = time.perf_counter()
    logs, cfg, truth = generate(case, seed, n_flights=n_flights, duration=duration, n_copters=n_copters,
                                conventions=conventions)
    names = [f"{name}-{seed}-{i}.npz" for i in range(len(logs))]
    report = run_diagnosis(Diagnosis(logs, names, cfg, progress=progress))
    if keep is not None:
        keep.update(report=report, conventions=conventions)
    v = report["verdict"]
    named = v["effect"]
    if case.effects:
        correct = pair_right(v["significant_gap"], v["unexplained"], v["effects"], case.effects)
    elif name == "null":
        correct = not v["significant_gap"]
    else:
        correct = v["unexplained"] if case.effect is None else named == case.effect
    corr = report.correction
    return {
        "case": name, "seed": seed, "truth": {k: v_ for k, v_ in truth.items()},
        "conventions": (conventions or DEFAULT_CONVENTIONS).to_dict(),
        "significant": v["significant_gap"], "found_by": None if not v["significant_gap"] else (
            "targeted" if report.details.targeted is not None else "omnibus"),
        "targeted_p": report.details.targeted["p"] if report.details.targeted is not None else math.nan,
        "named": named, "effects": list(v["effects"]),
        "ambiguous": list(v["ambiguous"]), "unexplained": v["unexplained"], "correct": bool(correct),
        "flagged_locations": sum(bool(loc.get("significant")) for loc in report["locations"]),
        "location_ok": location_ok(report, case, truth), "param_error": param_error(report, case, truth),
        "shrink_heldout": next((e["shrink_heldout"] for e in report["effects"] if e["name"] == case.effect), math.nan)
        if case.effect and not case.effects else v["shrink_heldout"],
        "correction_shrink": corr["shrink_heldout"] if corr else math.nan,
        "gap_before": report["gap_before"], "seconds": time.perf_counter() - t0,
        "top_effects": [e["name"] for e in report["effects"][:3]],
    }
