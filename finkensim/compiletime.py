"""How much of a call was numba compiling: ``with compile_timer() as ct: ...; ct.seconds``.

Listens to numba's ``numba:compile`` events (``numba.core.event``) while the block runs and adds up the
outermost compile intervals (a kernel that compiles its callees nests their events inside its own, which count
once). Loading a kernel from numba's on-disk cache is not compiling and is not counted: with a warm cache the
figure is about 0 s. ``ct.kernels`` is the number of outermost compilations; ``ct.intervals`` lists every
compilation (nested ones too) for a profile of where compile time goes (:meth:`CompileTime.profile`).

``with compiling_notice(bar):`` makes a tqdm progress bar say :data:`COMPILING` while numba compiles in the block
and leaves the compile time out of its rate and ETA.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

__all__ = ["COMPILING", "CompileTime", "compile_timer", "compiling_notice", "outermost_seconds"]

#: what a progress bar says while numba compiles, instead of an ETA that would count the compile as progress
COMPILING = "compiling (first run only)…"


@dataclass
class CompileTime:
    """seconds: total outermost numba compile time (s) in the block; kernels: how many outermost compilations;
    intervals: every compilation as (start (s, from the first event), depth, seconds, name), nested ones included."""

    seconds: float = 0.0
    kernels: int = 0
    intervals: list = field(default_factory=list)

    def profile(self, max_depth: int = 2, min_seconds: float = 0.2) -> list[dict]:
        """Compilations up to ``max_depth`` lasting at least ``min_seconds``, in start order: dicts {name, depth,
        seconds (inclusive), own_seconds (minus the nested compilations it triggered)}."""
        rows = sorted(self.intervals)
        out = []
        for i, (start, depth, secs, name) in enumerate(rows):
            if depth > max_depth or secs < min_seconds:
                continue
            inner = sum(s for st, d, s, _ in rows[i + 1:] if d == depth + 1 and start <= st < start + secs)
            out.append(dict(name=name, depth=depth, seconds=secs, own_seconds=secs - inner))
        return out


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


def _intervals(buffer) -> list:
    from numba.core import event

    t0 = buffer[0][0] if buffer else 0.0
    stack, out = [], []
    for ts, ev in buffer:
        if ev.status == event.EventStatus.START:
            disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
            fn = getattr(disp, "py_func", None)
            stack.append((ts, getattr(fn, "__qualname__", None) or str(disp)))
        elif stack:
            start, name = stack.pop()
            out.append((start - t0, len(stack), ts - start, name))
    return out


@contextlib.contextmanager
def compile_timer():
    """Context manager yielding a :class:`CompileTime` that is filled in when the block ends."""
    from numba.core import event

    result = CompileTime()
    with event.install_recorder("numba:compile") as rec:
        yield result
    result.seconds, result.kernels = outermost_seconds(
        (ts, ev.status == event.EventStatus.START) for ts, ev in rec.buffer)
    result.intervals = _intervals(rec.buffer)


@contextlib.contextmanager
def compiling_notice(bar):
    """While the block runs, a tqdm ``bar`` shows :data:`COMPILING` as its description during each outermost numba
    compilation (its ETA then reads ``?``), and afterwards takes its label back and restarts its clock from the end
    of the compilation (tqdm's ``unpause``), so the rate and ETA count running steps only."""
    from numba.core import event

    label = bar.desc
    depth = [0]

    class _Notice(event.Listener):
        def on_start(self, ev):
            depth[0] += 1
            if depth[0] == 1:
                bar.set_description_str(COMPILING, refresh=True)

        def on_end(self, ev):
            depth[0] -= 1
            if depth[0] == 0:
                bar.set_description_str(label, refresh=False)
                bar.unpause()

    with event.install_listener("numba:compile", _Notice()):
        yield bar
