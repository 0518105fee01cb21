"""Run keys: run ids, replicate seeds, the design fingerprint and the text form of parameter values.

Runs are numbered ``run_id = combination * replicates + replicate``. Replicate r of combination k
flies with a seed derived from (sweep seed, k, r) alone (``numpy.random.SeedSequence``), so results
do not depend on the executor, the number of workers or the order of completion.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

DEFAULT_REPLICATES = 20  # seeds per parameter combination
SEED_TAG_RUN = 1     # SeedSequence([seed, 1, k, r]) -> run seeds
SEED_TAG_DESIGN = 2  # SeedSequence([seed, 2]) -> random design samples


@dataclass(frozen=True)
class Run:
    """One episode of a sweep: combination ``combination``, replicate ``replicate``, seed ``seed``."""

    run_id: int
    combination: int
    replicate: int
    seed: int
    params: Mapping[str, Any]


def format_value(value) -> str:
    """A parameter value for people: floats as ``%g``, tuples as ``[a, b]``."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    return str(value)


def format_params(params: Mapping[str, Any]) -> str:
    """``copters.n=4, behaviour.speed=0.2`` (or ``base`` when nothing is swept)."""
    return ", ".join(f"{k}={format_value(v)}" for k, v in params.items()) or "base"


def seed_for(sweep_seed: int, combination: int, replicate: int) -> int:
    """The seed of replicate ``replicate`` of ``combination``: 63 bits of SeedSequence([seed, 1, k, r])."""
    state = np.random.SeedSequence([sweep_seed, SEED_TAG_RUN, combination, replicate]).generate_state(1, np.uint64)
    return int(state[0] >> np.uint64(1))


def content_hash(content: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of ``content`` as JSON with sorted keys (non-JSON values by ``str``)."""
    payload = json.dumps(content, sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()
