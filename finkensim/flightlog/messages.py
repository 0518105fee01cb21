"""Text pieces of flight-log error messages: numbers, shapes, positions in a log, unit hints.

Every :class:`~finkensim.flightlog.format.FlightLogError` message is built from these, so the
validation, NPZ and CSV modules word numbers and places the same way.
"""
from __future__ import annotations

__all__ = ["fmt", "shape_text", "where", "unit_hint", "plural"]


def fmt(x: float) -> str:
    """A number in at most 6 significant digits, e.g. ``1.5`` or ``1e-07``."""
    return f"{x:.6g}"


def shape_text(shape: tuple) -> str:
    """A shape as Python writes a tuple: ``(3,)``, ``(20, 3, 4)``, ``()``."""
    return "(" + ", ".join(str(int(s)) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def where(log_t, ids, index: tuple, axes: str) -> str:
    """Describe an index like (step, copter, sonar) for error messages.

    Args:
        log_t: (T,) sample times in s (or None): a step is named with its time.
        ids: (N,) copter names (or None): a copter is named by its id.
        index: the integer index, one entry per letter of ``axes``.
        axes: one letter per index entry: ``t`` step, ``c`` copter, ``o`` target copter
            (ranging column), ``s`` sonar, ``a`` axis.

    Returns:
        e.g. ``"t = 1.05 s (step 1), copter 'cf2', sonar 3"``.
    """
    parts = []
    for ax, i in zip(axes, index):
        i = int(i)
        if ax == "t":
            t = float(log_t[i]) if log_t is not None and i < len(log_t) else float("nan")
            parts.append(f"t = {fmt(t)} s (step {i})")
        elif ax == "c":
            parts.append(f"copter {str(ids[i])!r}" if ids is not None and i < len(ids) else f"copter {i}")
        elif ax == "o":
            parts.append(f"target copter {str(ids[i])!r}" if ids is not None and i < len(ids) else f"target copter {i}")
        elif ax == "s":
            parts.append(f"sonar {i}")
        elif ax == "a":
            parts.append(f"axis {i}")
    return ", ".join(parts)


def unit_hint(value: float, cm_above: float, mm_above: float, unit: str = "m") -> str | None:
    """'looks like centimetres: divide by 100' (or mm) if ``value`` exceeds the thresholds.

    ``value`` is in the (claimed) ``unit`` (``"m"`` or e.g. ``"m/s^2"``); above ``mm_above``
    it reads as millimetres, above ``cm_above`` as centimetres; None when it is plausible.
    """
    cm, mm = ("centimetres", "millimetres") if unit == "m" else (unit.replace("m", "cm", 1), unit.replace("m", "mm", 1))
    if value > mm_above:
        return f"looks like {mm}: divide by 1000"
    if value > cm_above:
        return f"looks like {cm}: divide by 100"
    return None


def plural(count: int, word: str) -> str:
    """``"1 sample"``, ``"3 samples"``: ``count`` and ``word`` with an ``s`` unless count is 1."""
    return f"{count} {word}" + ("" if count == 1 else "s")
