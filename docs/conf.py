"""Sphinx configuration of the finkensim documentation (``make docs`` → ``docs/_build/html``).

The pages are MyST Markdown; the notebooks (``docs/notebooks`` links to ``../notebooks``) are rendered with the
outputs they were committed with (``nb_execution_mode = "off"``); the API reference is generated from the
docstrings (autodoc + napoleon, numpy style). ``make docs`` turns every warning into an error, so a broken
cross-reference in a page or a docstring fails the build.
"""
from __future__ import annotations

import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

import finkensim  # noqa: E402

project = "finkensim"
author = "the finkensim authors"
copyright = "the finkensim authors"
version = release = finkensim.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "myst_nb",  # includes myst_parser
]

# --- sources -----------------------------------------------------------------------------------------------------
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}  # .rst first: autosummary writes its stubs as reST
root_doc = "index"
exclude_patterns = [
    "_build", "Thumbs.db", ".DS_Store",
    "notebooks/.ipynb_checkpoints",
    "validation/*/**",  # raw rows of the validation sweeps (validation/README.md describes them)
]
# A page in no toctree is still built (and can be linked to) but is in no navigation: add new pages to a toctree in
# index.md (see contributing.md). The warning is not an error so that a page added on another branch builds at once.
suppress_warnings = ["toc.not_included"]

# --- MyST and notebooks ------------------------------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
myst_heading_anchors = 3
nb_execution_mode = "off"  # notebooks are rendered with their committed outputs (make test executes them)
nb_merge_streams = True

# --- API reference -----------------------------------------------------------------------------------------------
autosummary_generate = True
autosummary_ignore_module_all = True  # document what each module defines, each object once
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_inherit_docstrings = False  # an override without a docstring does not borrow its (foreign) base class's
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented_params"
autodoc_mock_imports: list[str] = []
napoleon_google_docstring = True  # a few older docstrings use "Args:"; new ones are numpy style
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_param = False  # types are prose here ("ndarray, shape (B, N, 2)"), not names to cross-reference
napoleon_custom_sections = [("Attributes", "params_style")]  # a field list: autodoc documents the members once

# Broken cross-references are errors; names of other libraries (no intersphinx: the build is offline) are not ours
# to resolve.
nitpicky = True
_EXTERNAL = r"(numpy|np|numba|scipy|pandas|pd|pyarrow|matplotlib|plt|mpl|dask|distributed|gymnasium|gym|pettingzoo|" \
            r"optuna|cma|sklearn|rosbags|mcap|PIL|tqdm|hypothesis|tomlkit|tomllib|tomli|pathlib|os|io|typing|collections|" \
            r"concurrent|multiprocessing|dataclasses|enum|types|abc|json|re|datetime|argparse|subprocess|gc)"
nitpick_ignore_regex = [
    (r"py:.*", r"(.*\.)?_\w+"),  # private helpers that a docstring names are not part of the reference
    (r"py:.*", _EXTERNAL + r"(\..*)?"),
    (r"py:class", r"(ndarray|ArrayLike|NDArray|DataFrame|Series|Figure|Axes|Path|PathLike|Callable|Iterable|"
                  r"Iterator|Sequence|Mapping|Any|Literal|Optional|Union|NamedTuple|T|self|optional|"
                  r"array_like|array|array-like|float|int|bool|str|bytes|dict|list|tuple|object|None)"),
]

# --- HTML --------------------------------------------------------------------------------------------------------
html_theme = "furo"
html_title = "finkensim"
html_static_path: list[str] = []


# --- references written as the code reads them -------------------------------------------------------------------
def _import_target(dotted: str):
    """The object a dotted name points to (module, then attributes), or None."""
    import importlib

    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except Exception:  # noqa: BLE001 (not a module: try a shorter prefix)
            continue
        try:
            for attr in parts[i:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return None
        return obj
    return None


def _canonical(dotted: str) -> str | None:
    """Where the object a dotted name points to is documented: its defining module and qualified name."""
    obj = _import_target(dotted)
    if obj is None:
        return None
    if isinstance(obj, type(sys)):
        return obj.__name__
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if isinstance(module, str) and isinstance(qualname, str) and "<" not in qualname:
        return f"{module}.{qualname}"
    return dotted  # data: documented under the name it was reached by


def _resolve_reexport(app, env, node, contnode):
    """Resolve ``:class:`GapReport```-style references the way Python resolves the name.

    A docstring names an object as its module sees it: relative to the module (``csvtables.read_csv`` in
    ``finkensim.importing``) or by a package that re-exports it (``finkensim.gap.GapReport``). Sphinx looks only for
    the exact documented name; this tries the name relative to the referring module and its parents, then the place
    the object is defined. A name that resolves nowhere is left to Sphinx (and fails the build).
    """
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    module = node.get("py:module") or ""
    classname = node.get("py:class") or ""
    prefixes = []
    if module:
        parts = module.split(".")
        if classname:
            prefixes.append(f"{module}.{classname}")
        prefixes += [".".join(parts[:i]) for i in range(len(parts), 0, -1)]
    prefixes.append("")
    domain = env.get_domain("py")
    for prefix in prefixes:
        dotted = f"{prefix}.{target}" if prefix else target
        canonical = _canonical(dotted)
        for name in dict.fromkeys(x for x in (dotted, canonical) if x):
            found = domain.resolve_any_xref(env, node["refdoc"], app.builder, name, node, contnode)
            found = [r for r in found if r[0].startswith("py:")]
            if found:
                return found[0][1]
    return None


# --- the docstrings' own conventions ------------------------------------------------------------------------------
# |x| is an absolute value or a norm in this project's docstrings, never a reST substitution: escape the bars.
_BARS = re.compile(r"(?<![\\|`])\|(?=[^\s|`])([^|`\n]*?[^\s\\|`])\|(?![|`])")


# (*leading, 2) is a shape with a starred name, not the start of emphasis.
_STARRED = re.compile(r"(?<=[(\[, ])\*(?=\w+[,)\]])")


def _escape_text(text: str) -> str:
    """Escape ``|x|`` and ``(*leading, 2)`` in running text, leaving inline literals (double backquotes) alone."""
    parts = re.split(r"(``.*?``)", text)
    return "".join(part if part.startswith("``") else _STARRED.sub(r"\\*", _BARS.sub(r"\\|\1\\|", part))
                   for part in parts)


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _literal_blocks(lines: list[str]) -> list[str]:
    """Mark indented examples as literal blocks.

    This project's docstrings show code as a block indented under a paragraph, after a blank line (plain-text
    style); reST would make it a block quote. A ``::`` paragraph before such a block makes it literal. A block that
    continues a list item (indented to the item's text) is left alone.
    """
    out: list[str] = []
    para_indent, para_first, in_literal = None, "", None
    for i, line in enumerate(lines):
        if not line.strip():
            out.append(line)
            continue
        indent = _indent(line)
        if in_literal is not None and indent > in_literal:
            out.append(line)
            continue
        in_literal = None
        previous = out[-1] if out else ""
        if para_indent is not None and not previous.strip() and indent > para_indent:
            prev_text = next((x for x in reversed(out) if x.strip()), "")
            item = re.match(r"\s*(?:[-*+]|\d+\.|\(\w\))\s+", para_first)
            continues_item = item and indent == item.end()
            if prev_text.rstrip().endswith("::") or continues_item:
                in_literal = para_indent if prev_text.rstrip().endswith("::") else None
            else:
                out[-1:] = ["", " " * para_indent + "::", ""]
                in_literal = para_indent
            out.append(line)
            continue
        if not previous.strip():
            para_first = line
        para_indent = indent
        out.append(line)
    return out


def _escape_bars(app, what, name, obj, options, lines):
    """Escape ``|x|`` (absolute values) and ``(*leading, 2)`` so that reST reads them as text (not in literal blocks)."""
    lines[:] = _literal_blocks(lines)
    literal_indent = None
    for i, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if literal_indent is not None and line.strip() and indent <= literal_indent:
            literal_indent = None
        if literal_indent is None:
            lines[i] = _escape_text(line)
            if line.rstrip().endswith("::"):
                literal_indent = indent


def _config_keys(app, what, name, obj, options, lines):
    """A config section's keys, from their field metadata (``finkensim.config.describe``), as its Parameters."""
    from finkensim.config import SECTIONS, describe

    if what != "class" or obj not in SECTIONS.values():
        return
    table = next(k for k, v in SECTIONS.items() if v is obj)
    lines += ["", f"TOML table ``[{table}]``; every key is validated on construction.", "", "Parameters", "----------"]
    for key, default, unit, allowed, doc in describe(obj):
        lines.append(f"{key} : {unit or 'no unit'}; default ``{default!r}``" + (f"; {allowed}" if allowed else ""))
        lines.append(f"    {_escape_text(doc)}" if doc else "    (see the user guide)")


def _plain_attribute_docstring(self):
    """An attribute's docstring is prose here: napoleon would read ``Text: more`` as ``type: description``."""
    return self._consume_to_end()


def _prefer_modules(import_by_name):
    """``finkensim.gap.diagnose`` is a module and, re-exported by the package, a function: autosummary must document
    the module there (the function is documented where it is defined)."""
    import importlib
    import importlib.util

    def wrapped(name, *args, **kwargs):
        try:
            is_module = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError, AttributeError):
            is_module = False
        if is_module:
            module = importlib.import_module(name)
            return module, None, name
        return import_by_name(name, *args, **kwargs)

    return wrapped


def setup(app):
    import sphinx.ext.autosummary as autosummary
    from sphinx.ext.napoleon.docstring import GoogleDocstring

    autosummary._import_by_name = _prefer_modules(autosummary._import_by_name)
    GoogleDocstring._parse_attribute_docstring = _plain_attribute_docstring
    app.connect("missing-reference", _resolve_reexport)
    app.connect("autodoc-process-docstring", _escape_bars, priority=400)  # before napoleon (500)
    app.connect("autodoc-process-docstring", _config_keys, priority=450)
