"""How much of a call was numba compiling: ``with compile_timer() as ct: ...; ct.seconds``.

Listens to numba's ``numba:compile`` events (``numba.core.event``) while the block runs and adds up the
outermost compile intervals (a kernel that compiles its callees nests their events inside its own, which count
once). Loading a kernel from numba's on-disk cache is not compiling and is not counted: with a warm cache the
figure is about 0 s. ``ct.kernels`` is the number of outermost compilations.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass

__all__ = ["CompileTime", "compile_timer"]


@dataclass
class CompileTime:
    """seconds: total outermost numba compile time (s) in the block; kernels: how many outermost compilations."""

    seconds: float = 0.0
    kernels: int = 0


def outermost_seconds(events) -> tuple[float, int]:
    """(seconds, count) of the outermost START..END intervals in a time-ordered list of (timestamp, is_start)."""
    depth, start, total, count = 0, 0.0, 0.0, 0
    for ts, is_start in events:
        if is_start:
            if depth == 0:
                start = ts
            depth += 1
        elif depth > 0:
            depth -= 1
            if depth == 0:
                total += ts - start
                count += 1
    return total, count


@contextlib.contextmanager
def compile_timer():
    """Context manager yielding a :class:`CompileTime` that is filled in when the block ends."""
    from numba.core import event

    result = CompileTime()
    with event.install_recorder("numba:compile") as rec:
        yield result
    result.seconds, result.kernels = outermost_seconds(
        (ts, ev.status == event.EventStatus.START) for ts, ev in rec.buffer)
