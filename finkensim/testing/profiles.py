"""Hypothesis settings profiles: ``fast`` for ``make test``, ``thorough`` for nightly-size runs.

The environment variable ``FINKENSIM_HYPOTHESIS`` (``fast`` or ``thorough``) selects one; the project's
``tests/conftest.py`` calls :func:`load_profile`, and so can a user's own ``conftest.py``::

    from finkensim.testing.profiles import load_profile
    load_profile()          # FINKENSIM_HYPOTHESIS, default "fast"

A test that sets its own ``max_examples`` keeps it under ``fast``; write it as ``examples(40)`` to get ten times
as many under ``thorough``.
"""
from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

__all__ = ["PROFILE_ENV", "PROFILES", "THOROUGH_FACTOR", "register_profiles", "load_profile", "current_profile",
           "examples"]

PROFILE_ENV = "FINKENSIM_HYPOTHESIS"
"""Environment variable naming the profile."""

THOROUGH_FACTOR = 10
"""How many times more examples ``thorough`` runs than ``fast``."""

PROFILES = {
    # Hypothesis's own example count; no deadline (a first call compiles numba kernels for seconds)
    "fast": dict(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow]),
    "thorough": dict(max_examples=100 * THOROUGH_FACTOR, deadline=None,
                     suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large]),
}
"""Profile name -> :class:`hypothesis.settings` keywords."""


def register_profiles() -> None:
    """Register every profile of :data:`PROFILES` with Hypothesis (names prefixed ``finkensim-``)."""
    for name, kw in PROFILES.items():
        settings.register_profile(f"finkensim-{name}", **kw)


def current_profile() -> str:
    """The profile ``FINKENSIM_HYPOTHESIS`` selects (default ``fast``); a ValueError names an unknown one."""
    name = os.environ.get(PROFILE_ENV, "").strip() or "fast"
    if name not in PROFILES:
        raise ValueError(f"{PROFILE_ENV} = {name!r}: expected one of {', '.join(map(repr, PROFILES))}")
    return name


def load_profile(name: str | None = None) -> str:
    """Register the profiles and load ``name`` (default :func:`current_profile`); returns the name loaded."""
    name = current_profile() if name is None else name
    if name not in PROFILES:
        raise ValueError(f"profile {name!r}: expected one of {', '.join(map(repr, PROFILES))}")
    register_profiles()
    settings.load_profile(f"finkensim-{name}")
    return name


def examples(n: int) -> int:
    """``n`` under ``fast``, ``THOROUGH_FACTOR * n`` under ``thorough``: for a test's own ``max_examples``."""
    return int(n) * (THOROUGH_FACTOR if current_profile() == "thorough" else 1)
