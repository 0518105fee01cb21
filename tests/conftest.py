"""Suite-wide checks, and the Hypothesis profile (``FINKENSIM_HYPOTHESIS=fast|thorough``, docs/testing.md)."""
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
