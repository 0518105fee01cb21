"""What the diagnosis refuses before it reads a flight: the error it raises for logs, arguments and config that
cannot be diagnosed together, and the cheap checks of the arguments. This module imports nothing heavy, so the
command line refuses a bad argument without loading the diagnosis (numba, scipy, matplotlib)."""
from __future__ import annotations

__all__ = ["GapInputError", "check_heldout"]


class GapInputError(ValueError):
    """Logs and config that cannot be diagnosed together; the message says which and why."""


def check_heldout(names: list[str], heldout: list[str] | None) -> None:
    """Raise :class:`GapInputError` unless ``heldout`` (flight names, or None/empty for the default split) names
    only given flights, leaves one for training, and is not given with a single flight (whose second half is
    always the held-out part). Cheap: the CLI calls it before any flight is read.

    Parameters
    ----------
    names : list of str
        The given flights' names.
    heldout : list of str or None
        The flights to hold out.
    """
    if not heldout:
        return
    unknown = [h for h in heldout if h not in names]
    if unknown:
        raise GapInputError(f"--heldout names {unknown}: not among the given flights {list(names)}")
    if len(names) == 1:
        raise GapInputError(f"--heldout {' '.join(heldout)}: with a single flight its second half is held out; "
                            "--heldout chooses held-out flights among two or more")
    if len(set(heldout)) == len(set(names)):
        raise GapInputError("--heldout names every flight: expected at least one training flight")
