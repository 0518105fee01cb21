"""Text that users typed: a did-you-mean hint for a misspelt name, and the byte-order mark some editors add.

Every parser of user input (config, sweep and study files, recording topics, metric and task names) words its
suggestions through :func:`suggest`, so they read the same everywhere.
"""
from __future__ import annotations

import difflib
from typing import Callable, Iterable


def suggest(word, options: Iterable[str], show: Callable[[str], str] = repr) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``options`` to ``str(word)``, or "" when none is close."""
    hint = difflib.get_close_matches(str(word), list(options), n=1)
    return f" (did you mean {show(hint[0])}?)" if hint else ""


def strip_bom(text: str) -> str:
    """``text`` without a leading UTF-8 byte-order mark (some editors write one; TOML does not allow it)."""
    return text[1:] if text.startswith("\ufeff") else text
