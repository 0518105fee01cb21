"""Every public name of ``import finkensim as fs`` and of the plug-in contracts has a numpy-style docstring whose
``Parameters`` section names exactly the parameters of its signature, in order (issue 39). The API reference
(``make docs``) is generated from these docstrings."""
from __future__ import annotations

import importlib
import inspect
import re

import pytest

import finkensim as fs

# The classes users subclass, build or call besides the lazy names of ``fs``, and the methods they call.
CONTRACTS = {
    "finkensim.config.SimulationConfig": (),
    "finkensim.gap.attribute.effects.Effect": ("start",),
    "finkensim.gap.attribute.effects.Param": (),
    "finkensim.gap.attribute.effects.register": (),
    "finkensim.gap.attribute.fit_result.FitResult": (),
    "finkensim.gap.diagnosis.Diagnosis": ("fit", "score_heldout", "objective", "fit_group"),
    "finkensim.gap.attribute.objective.FitObjective": ("objective", "fit_group"),
    "finkensim.flightlog.npz.save": (),
}


def resolve(dotted: str):
    module, _, name = dotted.rpartition(".")
    return getattr(importlib.import_module(module), name)


def public_methods(cls) -> list[str]:
    return [name for name, value in vars(cls).items() if not name.startswith("_")
            and (inspect.isfunction(value) or isinstance(value, (classmethod, staticmethod, property)))]


def targets():
    """(label, object) for every callable whose docstring is checked."""
    out = []
    for name in fs._API:
        obj = getattr(fs, name)
        out.append((f"fs.{name}", obj))
        if inspect.isclass(obj):
            out += [(f"fs.{name}.{m}", inspect.getattr_static(obj, m)) for m in public_methods(obj)]
    for dotted, methods in CONTRACTS.items():
        obj = resolve(dotted)
        out.append((dotted, obj))
        out += [(f"{dotted}.{m}", inspect.getattr_static(obj, m)) for m in methods]
    return out


def section(doc: str, title: str) -> list[str] | None:
    """The names a numpy-style section (``Parameters`` underlined with dashes) documents, or None without it."""
    lines = inspect.cleandoc(doc).splitlines()
    for i in range(len(lines) - 1):
        if lines[i].strip() == title and re.fullmatch(r"-{3,}", lines[i + 1].strip()):
            names = []
            for j in range(i + 2, len(lines)):
                line = lines[j]
                if j + 1 < len(lines) and line.strip() and re.fullmatch(r"-{3,}", lines[j + 1].strip()):
                    break  # the next section's title
                if line.strip() and not line[0].isspace():
                    names += [n.strip().lstrip("*") for n in line.split(" : ")[0].split(",")]
            return names
    return None


def signature_names(obj) -> list[str]:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return []
    return [p.name for p in sig.parameters.values() if p.name not in ("self", "cls")]


@pytest.mark.parametrize("label, obj", targets(), ids=[label for label, _ in targets()])
def test_public_docstring(label, obj):
    if isinstance(obj, property):
        assert obj.fget.__doc__, f"{label}: the property has no docstring"
        return
    func = obj.__func__ if isinstance(obj, (classmethod, staticmethod)) else obj
    doc = func.__doc__
    assert doc and doc.strip(), f"{label} has no docstring"
    if inspect.isclass(func) and issubclass(func, BaseException):
        return
    if inspect.isclass(func) and getattr(func, "_is_protocol", False):
        return  # a Protocol is never built (its signature is *args, **kwargs): its methods are checked
    wanted = signature_names(func)
    if is_config_section(func):
        return  # its keys are documented by their field metadata (next test); the docs build lists them
    documented = section(doc, "Parameters")
    if not wanted:
        assert documented in (None, []), f"{label} takes no parameters but documents {documented}"
        return
    assert documented is not None, f"{label}{inspect.signature(func)}: no numpy-style 'Parameters' section"
    assert documented == wanted, f"{label}: the docstring documents {documented}, the signature has {wanted}"


def is_config_section(obj) -> bool:
    from finkensim.config import SECTIONS

    return obj in SECTIONS.values()


@pytest.mark.parametrize("name", sorted(__import__("finkensim.config", fromlist=["SECTIONS"]).SECTIONS))
def test_config_keys_are_documented(name):
    """Every key of every config section has a unit entry and a description or a choice list (``describe``)."""
    from finkensim.config import SECTIONS, describe

    cls = SECTIONS[name]
    assert (cls.__doc__ or "").strip(), f"[{name}] ({cls.__name__}) has no docstring"
    for key, _default, _unit, allowed, doc in describe(cls):
        assert doc or allowed, f"{name}.{key}: neither a description nor the allowed values"


@pytest.mark.parametrize("module", fs._MODULES)
def test_public_modules_are_documented(module):
    """Each module of ``fs`` and every name it exports has a docstring."""
    mod = getattr(fs, module)
    assert mod.__doc__ and mod.__doc__.strip(), f"finkensim.{module} has no module docstring"
    names = getattr(mod, "__all__", [n for n in vars(mod) if not n.startswith("_")])
    missing = []
    for name in names:
        obj = getattr(mod, name)
        if (inspect.isfunction(obj) or inspect.isclass(obj)) and not (obj.__doc__ or "").strip():
            missing.append(name)
    assert not missing, f"finkensim.{module}: no docstring on {missing}"


def test_section_parser():
    doc = """Summary.

    Parameters
    ----------
    a, b : float
        Two, m.
    **rest
        More.

    Returns
    -------
    int
    """
    assert section(doc, "Parameters") == ["a", "b", "rest"]
    assert section(doc, "Returns") == ["int"]
    assert section("No sections.", "Parameters") is None
