"""A package's public names loaded on first use (PEP 562), so that importing the package — e.g. for the command
line's argument parser — does not import numba, pandas or optuna before a command needs them."""
from __future__ import annotations

import importlib

__all__ = ["lazy_exports"]


def lazy_exports(package: str, table: dict):
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` that import each public name from its
    submodule on first use and keep it.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    table : dict
        Public name → relative submodule (``".run"``) that defines it.

    Returns
    -------
    tuple
        ``(__getattr__, __dir__)`` to assign at the package's top level.
    """
    def __getattr__(name: str):
        if name not in table:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(table[name], package), name)
        vars(importlib.import_module(package))[name] = value
        return value

    def __dir__():
        return sorted(table)

    return __getattr__, __dir__
