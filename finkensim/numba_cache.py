"""Where numba keeps finkensim's compiled kernels: one on-disk cache for every entry point.

``import finkensim`` calls :func:`configure` before any kernel module (and before finkensim imports numba), so
``make demo``, ``make test``, the ``finkensim`` command, notebooks, plain Python and the workers of a process pool or
a Dask cluster all load the kernels that any of them compiled, instead of compiling them again.

The directory is ``<user cache>/finkensim/numba/<source hash>`` (``platformdirs.user_cache_path``: on Linux
``~/.cache/finkensim/numba/…``), or ``NUMBA_CACHE_DIR`` when the user set it. The source hash covers every ``.py``
file of the package: numba invalidates a cached kernel only when its *own* file changes, not when a kernel it calls
(in another module) or a record it takes does, so a kernel compiled from other sources must never be found. A change
anywhere in the package therefore starts a new, empty directory (the old ones can be deleted at any time; numba
compiles again what it does not find). :func:`configure` deletes them itself: a version directory not chosen for
``PRUNE_AFTER_DAYS`` days goes when another is chosen (choosing one marks it used; ``NUMBA_CACHE_DIR`` set by the user
is never pruned).

This module must not import numba: numba reads ``NUMBA_CACHE_DIR`` when it is imported, and each kernel chooses
its cache location when it is decorated. If numba was imported first, :func:`configure` also sets numba's
``config.CACHE_DIR``, which the kernels decorated afterwards (all of finkensim's) use.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

__all__ = ["ENV_VAR", "PACKAGE_DIR", "PRUNE_AFTER_DAYS", "configure", "default_cache_dir", "prune", "source_hash"]

ENV_VAR = "NUMBA_CACHE_DIR"
PACKAGE_DIR = Path(__file__).resolve().parent
HASH_CHARS = 16  # hex digits of the SHA-1 of the sources that name the cache directory
#: a version directory of the default cache not chosen for this many days is deleted (≈ 10–100 MB each)
PRUNE_AFTER_DAYS = 30


def source_hash(package_dir: Path = PACKAGE_DIR) -> str:
    """SHA-1 (first ``HASH_CHARS`` hex digits) of every ``*.py`` file under ``package_dir``: relative paths
    and contents, in sorted order (≈ 2 ms for the package's ≈ 150 files)."""
    digest = hashlib.sha1()
    for path in sorted(package_dir.rglob("*.py")):
        digest.update(path.relative_to(package_dir).as_posix().encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()[:HASH_CHARS]


def default_cache_dir(package_dir: Path = PACKAGE_DIR) -> Path:
    """``<user cache dir>/finkensim/numba/<source hash>``: the cache used when ``NUMBA_CACHE_DIR`` is not set."""
    from platformdirs import user_cache_path

    return user_cache_path("finkensim", appauthor=False) / "numba" / source_hash(package_dir)


def prune(keep: Path, max_age_days: float = PRUNE_AFTER_DAYS, now: float | None = None) -> list[Path]:
    """Delete the sibling version directories of ``keep`` (the directories beside it whose name is a source hash)
    last marked used more than ``max_age_days`` ago, mark ``keep`` used (its modification time := now), and return
    the deleted paths. Errors (a directory another process is deleting, no permission) leave that directory as it is:
    a cache is never worth a failed import."""
    now = time.time() if now is None else now
    deleted = []
    try:
        keep.mkdir(parents=True, exist_ok=True)
        os.utime(keep, (now, now))
        siblings = list(keep.parent.iterdir())
    except OSError:
        return deleted
    for path in siblings:
        if path == keep or len(path.name) != HASH_CHARS or not path.is_dir():
            continue
        try:
            if now - path.stat().st_mtime > max_age_days * 86400.0:
                shutil.rmtree(path)
                deleted.append(path)
        except OSError:
            continue
    return deleted


def configure() -> str:
    """Choose the cache directory (``NUMBA_CACHE_DIR`` if set and not empty, else :func:`default_cache_dir`, whose
    stale siblings :func:`prune` deletes), export it in ``os.environ`` (child processes inherit it) and return it.
    Does not import numba."""
    chosen = os.environ.get(ENV_VAR, "")
    if not chosen:
        default = default_cache_dir()
        prune(default)
        chosen = str(default)
        os.environ[ENV_VAR] = chosen
        numba_config = sys.modules.get("numba.core.config")
        if numba_config is not None:  # numba was imported before finkensim: it has read the variable already
            numba_config.CACHE_DIR = chosen
    return chosen
