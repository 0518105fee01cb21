"""Argument checks shared by the ``finkensim`` subcommands: the usage error, scenario files, output
directories, the headless plotting backend. Every helper raises :class:`UsageError` (printed by
:func:`finkensim.cli.main` as one line, exit code 2) for bad input.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["UsageError", "one_line", "load_scenario_arg", "output_dir", "use_agg", "require_flight_log"]


class UsageError(Exception):
    """Bad input from the user; ``main`` prints it as one line and returns exit code 2."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog = prog


def one_line(text: str) -> str:
    """``text`` on one line (runs of whitespace, newlines included, become one space)."""
    return " ".join(str(text).split())


def load_scenario_arg(prog: str, scenario: str | None):
    """The Config of the scenario file ``scenario`` (None: the built-in scenario), or a UsageError naming the file."""
    from .config import ConfigError
    from .default_scenario import load_scenario  # not .scenario: a refused file never imports the engine

    if scenario is None:
        return load_scenario(None)
    path = Path(scenario)
    if not path.exists():
        raise UsageError(prog, f"scenario file {scenario!r} does not exist")
    if not path.is_file():
        raise UsageError(prog, f"scenario {scenario!r} is not a file")
    try:
        return load_scenario(path)
    except ConfigError as exc:
        msg = str(exc)
        raise UsageError(prog, msg if str(path) in msg else f"{scenario}: {msg}") from None
    except UnicodeDecodeError:
        raise UsageError(prog, f"{scenario}: not a text (TOML) file") from None
    except OSError as exc:
        raise UsageError(prog, f"cannot read scenario {scenario!r}: {exc.strerror or exc}") from None


def output_dir(prog: str, out: str, create: bool = True) -> Path:
    """``out`` created as a directory (with its parents; only checked if not ``create``), or a UsageError
    naming it and why not."""
    if not str(out).strip():
        raise UsageError(prog, "--out '': expected a directory name")
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise UsageError(prog, f"--out {str(path)!r} is a file: expected a directory")
    if not create:
        return path
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(prog, f"cannot create output directory {str(path)!r}: {exc.strerror or exc}") from None
    return path


def use_agg() -> None:
    """Headless plotting for the CLI unless the user chose a backend (or pyplot is already in use)."""
    if "MPLBACKEND" not in os.environ and "matplotlib.pyplot" not in sys.modules:
        import matplotlib

        matplotlib.use("Agg")


def require_flight_log(prog: str, path: str) -> None:
    """A UsageError unless ``path`` (if it exists: ``load`` names a missing file) is a flight log; the message says
    what the file is and how to use it (:func:`finkensim.filekinds.file_kind`, the detector check uses)."""
    from .filekinds import FileKindError, describe_kind, file_kind

    p = Path(path)
    if not p.exists():
        return
    try:
        kind = file_kind(p)
    except (FileKindError, OSError) as exc:
        raise UsageError(prog, f"{path}: not a flight log (.npz): {exc}") from None
    if kind == "log":
        return
    advice = {"csv": "turn it into one with finkensim import --tracking ... --readings ... --out FLIGHT.npz",
              "readings": "turn it into one with finkensim import --tracking ... --readings ... --out FLIGHT.npz",
              "bag": "turn it into one with finkensim import --bag ... --topics ... --out FLIGHT.npz",
              "scenario": "give a simulator config as --config"}.get(kind, "gap reads flight logs (spec/flightlog.md)")
    raise UsageError(prog, f"{path} is a {describe_kind(kind)}, not a flight log (.npz): {advice}")
