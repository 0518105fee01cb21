"""Atomic file output: every file finkensim writes appears whole under its final name, or not at all.

The data goes to a temporary file in the same directory (same file system), which is then renamed
over the final name with :func:`os.replace` (atomic on POSIX and Windows). If writing fails or is
interrupted (an exception, Ctrl-C), the temporary file is removed and the final name is untouched;
a process killed with SIGKILL mid-write can leave only a hidden ``.NAME.PID.XXXX.tmp.EXT`` file, never a
partial file under the final name. The temporary name keeps the suffix, so writers that pick the
format from it (matplotlib, Pillow) still do::

    with atomic_path("out/arena.png") as tmp:
        fig.savefig(tmp)
    write_atomic(Path("out/summary.csv"), lambda p: df.to_csv(p, index=False))
"""
from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path
from typing import Any, Callable, Iterator

__all__ = ["temp_beside", "atomic_path", "write_atomic", "write_text_atomic"]


def temp_beside(path: str | os.PathLike) -> Path:
    """A fresh hidden temporary name in ``path``'s directory that keeps its suffix: ``.NAME.PID.XXXXXXXX.tmp.EXT``."""
    p = Path(path)
    return p.with_name(f".{p.stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{p.suffix}")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on normal exit rename it to ``path``, otherwise remove it."""
    final = Path(path)
    tmp = temp_beside(final)
    try:
        yield tmp
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_atomic(path: str | os.PathLike, write: Callable[[Path], Any]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it to ``path`` (never half a file)."""
    with atomic_path(path) as tmp:
        write(tmp)
    return Path(path)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """``Path(path).write_text(text)``, atomically."""
    return write_atomic(path, lambda p: p.write_text(text))
