"""``finkensim compile --gap``: the diagnosis's kernels compiled ahead of the first ``finkensim gap``."""
from __future__ import annotations

from ..config import Config
from ..scenario import simulate_flight

__all__ = ["WARMUP_SECONDS", "compile_diagnosis"]

WARMUP_SECONDS = 20.0  # s per simulated flight: longer than the IMU window of the default [gap] settings


def compile_diagnosis(cfg: Config) -> None:
    """Diagnose two short flights of ``cfg`` (seeds 1 and 2, ``WARMUP_SECONDS`` each, with the error-free values
    a simulated log carries) against ``cfg`` itself: numba compiles (or loads) the replay, predictive, scoring and
    fit kernels a diagnosis of such logs calls. The report is discarded."""
    from .pipeline import diagnose

    logs = [simulate_flight(cfg, duration=WARMUP_SECONDS, seed=seed, ideal=True)[0] for seed in (1, 2)]
    diagnose(logs, ["warmup-1.npz", "warmup-2.npz"], cfg)
