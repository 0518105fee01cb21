"""Outlined copies of ``inline="always"`` kernels.

A batched or closed-loop kernel that inlined every per-environment kernel at numba's IR level would take minutes to
compile (IR inlining and type inference grow steeply with size); it calls an *outlined* copy instead: the same Python
code compiled once as a called function (LLVM's word for code moved out of line into a function of its own).
Identical results.

Compile time compounds with depth: numba links the LLVM IR of every callee into each caller's module and optimizes
the whole module again (so each level of calls re-optimizes everything below it). Functions that only compiled code
calls therefore carry no wrappers (:data:`INTERNAL`): 41.8 → 38.8 s of cold compile of the full workload.

Not to be confused with a kernel's *reference*: the plain-NumPy restatement of a kernel in ``tests/naive/`` that the
property tests compare it with.
"""
from __future__ import annotations

import types

from numba import njit

__all__ = ["outlined", "python_function", "INTERNAL"]

#: njit options of a function that only compiled code calls: no Python entry point and no C callback are generated.
#: Each compiled function carries both wrappers by default (unboxing every field of its record arguments: for
#: ``swarm_env`` a quarter of its LLVM IR), and every caller links them in and optimizes them again.
INTERNAL = {"no_cpython_wrapper": True, "no_cfunc_wrapper": True}

#: the options that change generated code: an outlined copy takes its kernel's, so that both give identical results
_CODE_OPTIONS = ("error_model", "fastmath", "boundscheck", "nogil")


def python_function(kernel):
    """The plain Python function behind a numba dispatcher (the function itself when ``NUMBA_DISABLE_JIT=1`` made
    ``njit`` return it unchanged, as in a line-coverage run).

    Parameters
    ----------
    kernel : numba dispatcher or function
        A compiled kernel, or the plain function when compilation is disabled.
    """
    return getattr(kernel, "py_func", kernel)


def outlined(kernel, cache: bool = True):
    """``kernel``'s Python code compiled as a called function, with the kernel's own code options (identical results),
    for compiled callers only (:data:`INTERNAL`: no Python entry point).

    The outlined copy is a copy of the function named ``<name>_outlined``: numba's on-disk cache files compilations
    under the Python function's name and line whatever their options, so a compilation without wrappers must not share
    the kernel's entry (a cached one would then be handed to a call from Python). The engine's
    per-environment kernels use ``error_model="numpy"``: a float division by zero gives inf/NaN instead of raising
    (they never divide by zero on valid input; the results are the same), and without Python's raise paths numba
    0.68 can prune the reference counting of the arrays they hand to their inlined per-ray functions — an atomic
    increment and decrement of each, for every sonar reading, before.

    Parameters
    ----------
    kernel : numba dispatcher
        An ``@njit`` kernel (typically ``inline="always"``).
    cache : bool
        Keep the copy in numba's on-disk cache (False for functions whose source the cache would not see change,
        such as a notebook's).
    """
    if not hasattr(kernel, "targetoptions"):  # NUMBA_DISABLE_JIT=1: nothing is compiled, the kernel is its own copy
        return kernel
    opts = {k: v for k, v in kernel.targetoptions.items() if k in _CODE_OPTIONS}
    f = kernel.py_func
    g = types.FunctionType(f.__code__, f.__globals__, f.__name__ + "_outlined", f.__defaults__, f.__closure__)
    g.__qualname__ = f.__qualname__ + "_outlined"
    g.__module__ = f.__module__
    g.__doc__ = f.__doc__
    return njit(cache=cache, **INTERNAL, **opts)(g)
