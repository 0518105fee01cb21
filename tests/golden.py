"""Golden results: digests of flight logs, a sweep table and a gap report for fixed seeds.

Refactors must keep these bit-identical. ``tests/test_golden.py`` recomputes them and compares with
``tests/golden.json``; a deliberate change of results regenerates the file with

    python -m tests.golden --update

and says so in the commit message (and the docs page where a documented number moves).

Each scenario is small (seconds of flight) but reaches every model: open loop (random walk, hover),
the closed loop with every behaviour option and sensor model, the seed profile, a sweep table and the
numbers of a gap report.
"""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

GOLDEN_FILE = Path(__file__).with_name("golden.json")

# (name, config overrides, duration s, seed)
FLIGHTS = [
    ("random_walk", {}, 4.0, 3),
    ("hover_rigid", {"behaviour.kind": "hover", "walls.bending": False, "sonar.error": "gaussian",
                     "sonar.crosstalk": "off", "ranging.error": "gaussian"}, 3.0, 5),
    ("ar_none", {"behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "none"}, 4.0, 1),
    ("ar_per_reading", {"behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "per_reading",
                        "sonar.crosstalk": "constant", "sonar.schedule": "simultaneous",
                        "ranging.beacons": [[0.5, 0.5], [2.5, 3.5]]}, 4.0, 2),
    ("ar_sequence_cone", {"behaviour.kind": "attraction_repulsion", "behaviour.wall_check": "sequence",
                          "sonar.beam": "cone", "sonar.beam_rays": 5, "sonar.schedule": "random_offset",
                          "sonar.offset": 0.05, "copters.n": 8}, 4.0, 4),
    ("seed_profile", {"profile": "seed", "behaviour.kind": "attraction_repulsion"}, 3.0, 6),
    ("seed_profile_walk", {"profile": "seed"}, 3.0, 7),
    ("none_errors", {"sonar.error": "none", "ranging.error": "none", "sonar.crosstalk": "off"}, 2.0, 8),
]


def digest_array(a) -> str:
    """sha256 of an array's dtype, shape and bytes (first 16 hex digits)."""
    a = np.ascontiguousarray(np.asarray(a))
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    if a.dtype.kind in "OUS":
        h.update(json.dumps(a.tolist()).encode())
    else:
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def digest_log(log) -> dict[str, str]:
    """Digest of every array of a :class:`FlightLog` (core blocks and extras), keyed by name."""
    out = {}
    for name in ("t", "arena", "pose", "copter_ids", "ultrasonic", "ultrasonic_yaw", "ranging", "imu_acc",
                 "imu_gyro"):
        v = getattr(log, name)
        if v is not None:
            out[name] = digest_array(v)
    if log.ultrasonic_offset is not None:
        out["ultrasonic_offset"] = repr(float(log.ultrasonic_offset))
    for name in sorted(log.extras):
        out["extras." + name] = digest_array(log.extras[name])
    return out


def _config(overrides):
    from finkensim.config import load_config
    from finkensim.scenario import DEFAULT_SCENARIO_TOML

    over = dict(overrides)
    profile = over.pop("profile", None)
    text = DEFAULT_SCENARIO_TOML if profile is None else DEFAULT_SCENARIO_TOML.replace(
        'profile = "default"', f'profile = "{profile}"')
    cfg = load_config(text)
    return cfg.replace(over) if over else cfg


def flight_digests() -> dict[str, dict[str, str]]:
    from finkensim.scenario import simulate_flight

    out = {}
    for name, over, duration, seed in FLIGHTS:
        log, _, _ = simulate_flight(_config(over), duration=duration, seed=seed, ideal=True)
        out[name] = digest_log(log)
    return out


def sweep_digest() -> dict[str, str]:
    from finkensim.sweep import Sweep, run_sweep

    sw = Sweep(_config({}), {"behaviour.kind": ["hover", "random_walk", "attraction_repulsion"],
                             "behaviour.speed": [0.2, 0.4]}, replicates=2, duration=2.0, seed=11)
    df = run_sweep(sw, executor="serial", progress=False)
    df = df.drop(columns=["elapsed"])
    out = {"columns": digest_array(np.array(list(df.columns)))}
    for col in df.columns:
        out[col] = digest_array(df[col].to_numpy())
    return out


def _canonical(x):
    """JSON-ready copy with every float as its repr (so a digest sees every bit)."""
    if isinstance(x, dict):
        return {k: _canonical(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_canonical(v) for v in x]
    if isinstance(x, float):
        return repr(x)
    return x


def gap_digest() -> dict[str, str]:
    from finkensim.gap import diagnose
    from finkensim.gap.validation.cases import CASES, generate

    small = {"gap.draws": 8, "gap.max_samples_per_flight": 150, "gap.fit_max_readings": 3000, "gap.n_boot": 60}
    out = {}
    for case, effects in (("wall_bulge", ["wall_bulge", "sonar_bias", "latency"]),
                          ("ranging_nlos", ["ranging_nlos", "ranging_dropout"]),
                          ("imu_bias", ["imu_bias"])):
        logs, cfg, _ = generate(CASES[case], 5, n_flights=2, duration=20.0)
        rep = diagnose(logs, ["a.npz", "b.npz"], cfg.replace(small), effect_names=effects).to_spec()
        for k in ("gap_before", "locations", "effects", "verdict"):
            text = json.dumps(_canonical(rep[k]), sort_keys=True)
            out[f"{case}.{k}"] = hashlib.sha256(text.encode()).hexdigest()[:16]
    return out


def compute() -> dict:
    return {"flights": flight_digests(), "sweep": sweep_digest(), "gap": gap_digest()}


if __name__ == "__main__":
    result = compute()
    if "--update" in sys.argv:
        GOLDEN_FILE.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
        print(f"wrote {GOLDEN_FILE}")
    else:
        print(json.dumps(result, indent=1, sort_keys=True))
