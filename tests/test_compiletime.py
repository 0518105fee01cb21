"""finkensim.compiletime: outermost numba compile intervals, measured on a real compilation."""
from __future__ import annotations

from numba import njit

from finkensim.compiletime import compile_timer, outermost_seconds


def test_nested_compilations_count_once():
    # outer 0..10 holds inner 2..5 and 6..7; then a separate 12..13
    events = [(0, True), (2, True), (5, False), (6, True), (7, False), (10, False), (12, True), (13, False)]
    assert outermost_seconds(events) == (11, 2)
    assert outermost_seconds([]) == (0.0, 0)
    assert outermost_seconds([(1, False)]) == (0.0, 0)  # an END without START (recorder installed mid-compile)


def test_compile_timer_sees_a_compilation_and_not_a_second_call():
    @njit  # no cache: a fresh function compiles on its first call
    def add_one(x):
        return x + 1

    with compile_timer() as first:
        assert add_one(1) == 2
    with compile_timer() as second:
        assert add_one(2) == 3
    assert first.kernels >= 1 and first.seconds > 0.0
    assert second.kernels == 0 and second.seconds == 0.0


def test_profile_nests_and_subtracts_children():
    from finkensim.compiletime import CompileTime

    ct = CompileTime(intervals=[(0.0, 0, 10.0, "outer"), (1.0, 1, 3.0, "a"), (5.0, 1, 2.0, "b"),
                                (5.5, 2, 1.0, "b_inner"), (11.0, 0, 0.1, "tiny")])
    prof = ct.profile(max_depth=1, min_seconds=0.2)
    assert [(r["name"], r["depth"]) for r in prof] == [("outer", 0), ("a", 1), ("b", 1)]
    assert prof[0]["own_seconds"] == 5.0 and prof[2]["own_seconds"] == 1.0


def test_the_garbage_collector_is_held_back_during_a_compile_and_restored_after():
    """finkensim.kernels installs (once) a compile listener: during the outermost compilation, callees included, the
    objects that existed are frozen and the thresholds raised; afterwards both are as before, also after a compile
    that fails."""
    import gc

    import pytest
    from numba.core import event

    from finkensim.kernels import compile_gc

    assert compile_gc.install() is compile_gc.install()  # registered once
    seen = []

    class Spy(event.Listener):
        def on_start(self, ev):
            seen.append((gc.get_threshold(), gc.get_freeze_count()))

        def on_end(self, ev):
            pass

    @njit
    def inner(x):
        return x * 2

    @njit
    def outer(x):
        return inner(x) + 1

    @njit
    def broken(x):
        return x.no_such_attribute

    before = gc.get_threshold()
    with event.install_listener("numba:compile", Spy()):
        assert outer(3) == 7
        with pytest.raises(Exception):
            broken(1)
    assert len(seen) >= 3  # outer, inner nested in it, broken
    assert all(t == compile_gc.COMPILE_THRESHOLDS and frozen > 0 for t, frozen in seen)
    assert gc.get_threshold() == before and gc.get_freeze_count() == 0

    @njit
    def again(x):
        return x - 1

    gc.freeze()  # a process's own freeze survives a compile
    try:
        frozen = gc.get_freeze_count()
        assert again(2) == 1
        assert gc.get_freeze_count() > frozen // 2 > 0  # not unfrozen (frozen objects freed meanwhile leave it)
    finally:
        gc.unfreeze()
