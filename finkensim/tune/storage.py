"""Optuna RDB storage that several processes can share safely, SQLite included.

Optuna hands an enqueued trial (the defaults trial of every study) to a worker by switching it from WAITING to
RUNNING with a read-check-write in one transaction, relying on ``SELECT ... FOR UPDATE``. SQLite ignores
``FOR UPDATE``: two processes starting at once can both read WAITING and both run the trial, and the slower one
then fails with "Cannot tell a COMPLETE trial". For SQLite URLs :func:`open_storage` therefore serialises that one
transition across processes with an advisory file lock beside the database (``DB.pop-lock``); SQLite files are
local to one machine, so a POSIX ``flock`` covers every process that can open them. Server databases (PostgreSQL,
MySQL) lock the row themselves and get Optuna's storage unchanged.
"""
from __future__ import annotations

import contextlib
import os

__all__ = ["open_storage"]


def _pop_lock_path(url: str) -> str | None:
    """The lock file of an ``sqlite:///PATH`` URL (None for other databases and in-memory SQLite)."""
    prefix = "sqlite:///"
    if not url.startswith(prefix) or url[len(prefix):] in ("", ":memory:"):
        return None
    return url[len(prefix):] + ".pop-lock"


@contextlib.contextmanager
def _exclusive(path: str):
    try:
        import fcntl
    except ImportError:  # not POSIX: no cross-process lock available; Optuna's own behaviour
        yield
        return
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def open_storage(url: str, **kwargs):
    """An ``optuna.storages.RDBStorage`` for ``url`` (keyword arguments passed on); for an SQLite file, one whose
    WAITING → RUNNING transition is serialised across processes (see the module doc)."""
    from optuna.storages import RDBStorage
    from optuna.trial import TrialState

    lock = _pop_lock_path(url)
    if lock is None:
        return RDBStorage(url, **kwargs)

    class SerialPopStorage(RDBStorage):
        def set_trial_state_values(self, trial_id, state, values=None):
            if state != TrialState.RUNNING:
                return super().set_trial_state_values(trial_id, state, values)
            with _exclusive(lock):
                return super().set_trial_state_values(trial_id, state, values)

    return SerialPopStorage(url, **kwargs)
