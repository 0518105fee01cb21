"""Text that users typed: a did-you-mean hint for a misspelt name, the byte-order mark some editors add, and TOML.

Every parser of user input (config, sweep and study files, recording topics, metric and task names) words its
suggestions through :func:`suggest`, so they read the same everywhere.
"""
from __future__ import annotations

import difflib
import math
import tomllib
from typing import Any, Callable, Iterable


def suggest(word, options: Iterable[str], show: Callable[[str], str] = repr) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``options`` to ``str(word)``, or "" when none is close."""
    hint = difflib.get_close_matches(str(word), list(options), n=1)
    return f" (did you mean {show(hint[0])}?)" if hint else ""


def strip_bom(text: str) -> str:
    """``text`` without a leading UTF-8 byte-order mark (some editors write one; TOML does not allow it)."""
    return text[1:] if text.startswith("\ufeff") else text


def loads_toml(text: str) -> dict[str, Any]:
    """The tables of TOML ``text`` (a leading byte-order mark ignored). Raises ``tomllib.TOMLDecodeError`` for
    invalid TOML, also for arrays or tables nested deeper than Python's parser can follow (which would otherwise
    end in a RecursionError)."""
    try:
        return tomllib.loads(strip_bom(text))
    except RecursionError:
        raise tomllib.TOMLDecodeError("arrays or inline tables nested too deeply (hundreds of levels); "
                                      "expected a flat file of tables and values") from None


def arena_size(values) -> tuple[float, float]:
    """(width, length) m from an ``--arena`` argument as every command takes it: ``3,4`` or ``3 4`` (a list of
    the words given). Raises ValueError with the words and what was expected."""
    words = [w for v in ([values] if isinstance(values, str) else values) for w in str(v).replace(",", " ").split()]
    shown = " ".join(str(v) for v in ([values] if isinstance(values, str) else values))
    try:
        size = [float(w) for w in words]
    except ValueError:
        size = []
    if len(size) != 2 or not all(math.isfinite(v) and v > 0 for v in size):
        raise ValueError(f"--arena {shown!r}: expected a positive width and length in m, as W,L or W L (e.g. 3,4)")
    return size[0], size[1]
