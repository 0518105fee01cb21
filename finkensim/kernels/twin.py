"""Non-inlined twins of ``inline="always"`` kernels.

A batched or closed-loop kernel that inlined every per-environment kernel at numba's IR level would take minutes to
compile (IR inlining and type inference grow steeply with size); it calls a *twin* instead: the same Python function
compiled once as a called function. Identical results.
"""
from __future__ import annotations

from numba import njit

__all__ = ["twin"]

#: the options that change generated code (and so must agree between two compilations of one function)
_CODE_OPTIONS = ("error_model", "fastmath", "boundscheck", "nogil")


def twin(kernel):
    """``kernel``'s Python function compiled as a called function, with the kernel's own code options.

    numba's on-disk cache files the compilations of one Python function under one entry whatever their options,
    so a twin must have the options of its kernel (``tests/test_architecture.py`` checks every pair). The engine's
    per-environment kernels use ``error_model="numpy"``: a float division by zero gives inf/NaN instead of raising
    (they never divide by zero on valid input; the results are the same), and without Python's raise paths numba
    0.68 can prune the reference counting of the arrays they hand to their inlined per-ray functions — an atomic
    increment and decrement of each, for every sonar reading, before.
    """
    opts = {k: v for k, v in kernel.targetoptions.items() if k in _CODE_OPTIONS}
    return njit(cache=True, **opts)(kernel.py_func)
