"""Suite-wide checks, and the Hypothesis profile (``FINKENSIM_HYPOTHESIS=fast|thorough``, docs/testing.md)."""
import os

import numba
import pytest

from finkensim.testing.profiles import load_profile

load_profile()


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
    """The fuzz suite's counts per category (``make fuzz`` prints them; docs/reliability.md quotes them)."""
    import sys

    mod = sys.modules.get("tests.test_fuzz_cli")
    counts = getattr(mod, "COUNTS", None)
    if not counts:
        return
    write = terminalreporter.write_line
    write("fuzz counts (inputs tried / named errors without a traceback, per category):")
    for cat, (tried, named) in sorted(counts.items()):
        write(f"  {cat}: {tried} / {named}")
    write(f"  total: {sum(v[0] for v in counts.values())} / {sum(v[1] for v in counts.values())}")
