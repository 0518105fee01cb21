"""A package's public names loaded on first use (PEP 562), so that importing the package — e.g. for the command
line's argument parser — does not import numba, pandas or optuna before a command needs them."""
from __future__ import annotations

import importlib

__all__ = ["lazy_exports"]


def lazy_exports(package: str, table: dict, modules=()):
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` that import each public name from its
    submodule on first use and keep it.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    table : dict
        Public name → the module that defines it (``".run"`` relative to ``package``, or absolute), or → a pair
        ``(module, attribute)`` when the public name is an alias of another attribute.
    modules : sequence of str, optional
        Names of ``package``'s submodules that are public names themselves (``fs.gap``).

    Returns
    -------
    tuple
        ``(__getattr__, __dir__)`` to assign at the package's top level; ``__dir__`` lists the package's ``__all__``
        when it has one, else the lazy names.
    """
    modules = tuple(modules)

    def __getattr__(name: str):
        if name in table:
            module, attr = table[name] if isinstance(table[name], tuple) else (table[name], name)
            value = getattr(importlib.import_module(module, package), attr)
        elif name in modules:
            value = importlib.import_module(f".{name}", package)
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        vars(importlib.import_module(package))[name] = value
        return value

    def __dir__():
        names = vars(importlib.import_module(package)).get("__all__")
        return sorted(names if names is not None else [*table, *modules])

    return __getattr__, __dir__
