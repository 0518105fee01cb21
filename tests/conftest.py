"""Suite-wide checks, the Hypothesis profile (``FINKENSIM_HYPOTHESIS=fast|thorough``, docs/testing.md), the kernels
several xdist workers need compiled once before they start (opt-in: ``FINKENSIM_PRECOMPILE=1``,
tests/suite_precompile.py), and an opt-in log of numba's compilations (``FINKENSIM_COMPILE_LOG=path``, docs/performance.md)."""
import os
import time

import numba
import pytest

from finkensim.testing.profiles import load_profile
from tests import suite_precompile

load_profile()

#: environment variable naming a file to which every pytest process (each xdist worker) appends one line per outermost
#: numba compilation: pid, xdist worker, wall seconds, kernel, argument types, test, CPU seconds (this process's
#: ``time.process_time``); the summary counts the CPU seconds of
#: kernels that several processes compiled for the same argument types
COMPILE_LOG = "FINKENSIM_COMPILE_LOG"


def _log_compilations(path: str) -> None:
    """Append a tab-separated line to ``path`` for each outermost compilation of this process (numba's
    ``numba:compile`` events; callees compiled inside a kernel's compilation are part of its seconds)."""
    from numba.core import event

    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")

    class _Log(event.Listener):
        def __init__(self):
            self.stack = []

        def on_start(self, ev):
            disp = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
            name = getattr(getattr(disp, "py_func", None), "__qualname__", None) or str(disp)
            self.stack.append((time.perf_counter(), time.process_time(), name, ev))

        def on_end(self, ev):
            if not self.stack:
                return
            t0, cpu0, name, ev = self.stack.pop()
            if self.stack:
                return
            test = os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0]
            args = ev.data.get("args") if isinstance(ev.data, dict) else None
            with open(path, "a") as f:
                f.write(f"{os.getpid()}\t{worker}\t{time.perf_counter() - t0:.2f}\t{name}\t{args}\t{test}\t"
                        f"{time.process_time() - cpu0:.2f}\n")

    event.register("numba:compile", _Log())


#: what the precompile did (tests/suite_precompile.py), said in the terminal summary
PRECOMPILED = pytest.StashKey[str]()


def pytest_configure(config):
    if os.environ.get(COMPILE_LOG):
        _log_compilations(os.environ[COMPILE_LOG])
    # the xdist controller, before it starts the workers: the kernels several workers need, compiled once (opt-in)
    workers = suite_precompile.wanted(config)
    if workers:
        config.stash[PRECOMPILED] = suite_precompile.precompile(workers)


def _compile_log_summary(write, path: str) -> None:
    """How many seconds went into compilations that another process had made too (same kernel and signature)."""
    try:
        rows = [line.rstrip("\n").split("\t") for line in open(path)]
    except OSError:
        return
    by_kernel: dict = {}
    for row in (r for r in rows if len(r) == 7):
        pid, name, args, cpu = row[0], row[3], row[4], row[6]
        by_kernel.setdefault((name, args), []).append((float(cpu), pid))
    total = sum(s for runs in by_kernel.values() for s, _ in runs)
    again = [(key, runs) for key, runs in by_kernel.items() if len({pid for _, pid in runs}) > 1]
    extra = sum(sum(sorted(s for s, _ in runs)[:-1]) for _, runs in again)
    write(f"numba compilations ({COMPILE_LOG}={path}): {len(rows)} in {total:.1f} s; {len(again)} kernel(s) compiled "
          f"by more than one process, {extra:.1f} s of it beyond each kernel's longest compilation")
    for (name, _), runs in sorted(again, key=lambda kr: -sum(s for s, _ in kr[1]))[:10]:
        write(f"  {name}: {len(runs)} times, {sum(s for s, _ in runs):.1f} s")


@pytest.fixture(autouse=True)
def _numba_threads_restored():
    """A test that changes numba's thread count (thread-local: the main thread's) must restore it: otherwise every
    later test runs its parallel kernels on one thread, and what they check depends on the order of the tests."""
    before = numba.get_num_threads()
    yield
    after = numba.get_num_threads()
    if after != before:
        numba.set_num_threads(before)
        pytest.fail(f"the test left numba's thread count at {after} (it was {before}); restore it in a finally block")


def pytest_collection_modifyitems(config, items):
    """Under ``NUMBA_DISABLE_JIT=1`` (``make coverage``) skip the tests marked ``jit_only``: they feed the counter-based
    generator negative or 64-bit indices, which numba wraps to uint64 and plain Python refuses (the engine's indices
    are never negative, so its flights are the same either way: tests/test_nojit.py)."""
    if os.environ.get("NUMBA_DISABLE_JIT") != "1":
        return
    skip = pytest.mark.skip(reason="needs numba's uint64 wrap-around (NUMBA_DISABLE_JIT=1)")
    for item in items:
        if "jit_only" in item.keywords:
            item.add_marker(skip)


def pytest_terminal_summary(terminalreporter):
    """The fuzz suite's counts per category (``make fuzz`` prints them; docs/reliability.md quotes them), and with
    ``FINKENSIM_COMPILE_LOG`` the compilations several processes made."""
    import sys

    if PRECOMPILED in terminalreporter.config.stash:
        terminalreporter.write_line(terminalreporter.config.stash[PRECOMPILED])
    if os.environ.get(COMPILE_LOG) and not hasattr(terminalreporter.config, "workerinput"):
        _compile_log_summary(terminalreporter.write_line, os.environ[COMPILE_LOG])

    mod = sys.modules.get("tests.test_fuzz_cli")
    counts = getattr(mod, "COUNTS", None)
    if not counts:
        return
    write = terminalreporter.write_line
    write("fuzz counts (inputs tried / named errors without a traceback, per category):")
    for cat, (tried, named) in sorted(counts.items()):
        write(f"  {cat}: {tried} / {named}")
    write(f"  total: {sum(v[0] for v in counts.values())} / {sum(v[1] for v in counts.values())}")
