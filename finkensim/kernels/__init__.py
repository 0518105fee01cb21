"""Numba kernels shared across the package. Importing it holds Python's garbage collector back while numba
compiles (:mod:`finkensim.kernels.compile_gc`)."""
from .compile_gc import install as _install_gc_pause

_install_gc_pause()
