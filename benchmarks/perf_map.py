"""Profile compiled code with Linux ``perf``: name numba's machine code for it.

perf samples JIT-compiled code as bare addresses; it resolves them through ``/tmp/perf-PID.map`` (one line per
function: start address, size, name, hex). :func:`write_perf_map` writes that file for every function numba compiled
in this process (those loaded from the on-disk cache carry no symbol table: run with a fresh ``NUMBA_CACHE_DIR``).
Sizes are the gaps between consecutive function starts, so a sample in padding is charged to the function before.

    NUMBA_CACHE_DIR=$(mktemp -d) python -m benchmarks.perf_map --seconds 30 &   # prints its PID when warm
    perf record -g -p PID -- sleep 10
    perf report --no-children --sort sym

The loop profiled is the Gymnasium vector env of ``benchmarks.envs_bench`` (N = 10, B = 1024 by default).
"""
from __future__ import annotations

import argparse
import gc
import os
import re
import sys
import time
from pathlib import Path

_HASH = re.compile(r"B\d+v\d+B\w{40}.*")  # numba's mangled signature suffix


def compiled_functions() -> dict[int, str]:
    """Start address → symbol of every function defined in the LLVM modules of this process's numba
    compilations (empty for compilations loaded from the cache)."""
    from numba.core.registry import CPUDispatcher

    found: dict[int, str] = {}
    libraries = {}
    for obj in gc.get_objects():
        # the object's own type, never isinstance: isinstance asks an object that is not a dispatcher for its
        # __class__, which a proxy or lazy object can answer with any exception (a dead weakref.proxy: ReferenceError)
        if issubclass(type(obj), CPUDispatcher):
            for cres in list(obj.overloads.values()):
                libraries[id(cres.library)] = cres.library
    for lib in libraries.values():
        module = getattr(lib, "_final_module", None)
        if module is None:
            continue
        for fn in module.functions:
            if fn.is_declaration:
                continue
            try:
                addr = lib.get_pointer_to_function(fn.name)
            except Exception:  # noqa: BLE001 - a symbol the JIT did not keep
                continue
            if addr:
                found[addr] = fn.name
    return found


def write_perf_map(path: str | Path | None = None, short: bool = True) -> Path:
    """Write perf's map file (default ``/tmp/perf-PID.map``) for :func:`compiled_functions`; ``short`` drops
    numba's signature suffix from the names. Returns the path."""
    funcs = compiled_functions()
    if not funcs:
        raise RuntimeError("no numba-compiled functions with symbols in this process (were they all loaded from the "
                           "cache? run with a fresh NUMBA_CACHE_DIR)")
    starts = sorted(funcs)
    path = Path(path or f"/tmp/perf-{os.getpid()}.map")
    with path.open("w") as fh:
        for i, a in enumerate(starts):
            size = min((starts[i + 1] - a) if i + 1 < len(starts) else 4096, 1 << 20)
            name = _HASH.sub("", funcs[a]) if short else funcs[a]
            fh.write(f"{a:x} {size:x} {name}\n")
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0, help="how long to run the loop once warm (s)")
    ap.add_argument("--b", type=int, default=1024, help="environments of the vector env")
    a = ap.parse_args(argv)
    if a.seconds <= 0 or a.b < 1:
        ap.error(f"--seconds {a.seconds} / --b {a.b}: expected positive numbers")
    from .envs_bench import _vector_env

    env, act = _vector_env(a.b)
    for _ in range(20):
        env.step(act)
    path = write_perf_map()
    print(f"PID {os.getpid()}: warm, symbols in {path}; attach with: perf record -g -p {os.getpid()} -- sleep 10",
          flush=True)
    t0 = time.perf_counter()
    steps = 0
    while time.perf_counter() - t0 < a.seconds:
        env.step(act)
        steps += 1
    print(f"{steps * a.b / (time.perf_counter() - t0):,.0f} env-steps/s while profiled", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
