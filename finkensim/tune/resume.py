"""What makes a resumed study the same study: its fingerprint, re-queued interrupted trials, reproducible sampling.

* :func:`fingerprint` — the parts of a study file that decide its trials (base scenario, ``[params]``,
  ``[objectives]``, duration, seeds, sampler, ``n_envs``), as canonical JSON. :func:`check_same_study` stores it
  in a new study and refuses to add trials to an old study made from a different file (a changed range would mix
  trials of two studies and report a best value outside the new range). ``n_trials``, ``description``, the
  held-out settings and ``[compare]`` may change: they do not change any trial.
* :func:`requeue_interrupted` — a trial that Ctrl-C or SIGTERM stopped is FAIL with the user attribute
  ``interrupted``; a trial whose process was killed (SIGKILL, a crash) stays RUNNING with the host and process id
  that ran it, and is marked FAIL when that process no longer exists on this host. Each such trial is enqueued
  again with its parameters (user attribute ``requeued_from``), so the resumed study runs the same trials.
* :func:`reseeded_sampler` — the sampler is created afresh for every trial, seeded with the study seed and the
  number of trials finished so far (interrupted ones not counted) and of trials running ahead of it (other
  processes sharing the study): with one process, a resumed study samples the same trials as an uninterrupted
  one, whatever happened between.
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import threading
from typing import Any, Callable

__all__ = ["InterruptGate", "fingerprint", "check_same_study", "requeue_interrupted", "mark_process", "reseeded_sampler", "finished_count",
           "INTERRUPTED", "REQUEUED_FROM", "FINGERPRINT"]

INTERRUPTED = "interrupted"
REQUEUED_FROM = "requeued_from"
FINGERPRINT = "finkensim_study"
_HOST, _PID = "host", "pid"


def fingerprint(spec) -> str:
    """Canonical JSON of what decides the trials of the study ``spec`` (a :class:`~.studyfile.StudySpec`)."""
    return json.dumps({
        "base": spec.base.to_dict(), "params": [[p.key, p.kind, p.low, p.high, p.log, list(p.choices or [])]
                                                for p in spec.params],
        "objectives": [list(o) for o in spec.objectives], "duration": spec.duration, "seed": spec.seed,
        "sampler": spec.sampler, "n_envs": spec.n_envs, "eval_seed": spec.eval_seed,
    }, sort_keys=True, default=str)


def _differences(old: dict, new: dict) -> list[str]:
    keys = sorted(set(old) | set(new))
    return [k for k in keys if old.get(k) != new.get(k)]


def check_same_study(study, spec, created: bool, where: str) -> None:
    """Store the fingerprint of ``spec`` in a ``created`` study, or raise ConfigError if the stored one differs."""
    from ..config import ConfigError

    fp = fingerprint(spec)
    if created:
        study.set_user_attr(FINGERPRINT, fp)
        return
    # Trials first, then the record: the creating process stores the record before its first trial, so a study
    # seen with trials shows the record when read after them (read the other way round, a process that loads the
    # study while its creator starts the first trial would take it for an older finkensim's).
    has_trials = bool(study.get_trials(deepcopy=False))
    old = study.user_attrs.get(FINGERPRINT)
    if old is None:
        if has_trials:
            raise ConfigError(f"{where} holds a study {spec.study_name!r} without a record of its study file (an "
                              "older finkensim made it): use another --out or study_name")
        study.set_user_attr(FINGERPRINT, fp)
        return
    if old != fp:
        changed = _differences(json.loads(old), json.loads(fp))
        raise ConfigError(f"{where} holds the study {spec.study_name!r} made from a different study file (changed: "
                          f"{', '.join(changed)}); its trials would mix with the new ones: use another --out (or "
                          "study_name), or restore the study file to resume")


def mark_process(trial) -> None:
    """Record in the running ``trial`` which host and process run it (to tell a killed trial later)."""
    trial.set_user_attr(_HOST, socket.gethostname())
    trial.set_user_attr(_PID, os.getpid())


def _process_gone(attrs: dict) -> bool:
    if attrs.get(_HOST) != socket.gethostname() or not isinstance(attrs.get(_PID), int):
        return False  # another machine's trial: Optuna's heartbeat fails it when it goes stale
    try:
        os.kill(attrs[_PID], 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # a live process of another user
        return False
    return False


def requeue_interrupted(study) -> list[int]:
    """Mark the trials of dead processes FAIL and enqueue every interrupted or killed trial again (once); returns
    the numbers of the re-queued trials."""
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False)
    done = {t.user_attrs.get(REQUEUED_FROM) for t in trials}
    again = []
    for t in trials:
        if t.state == TrialState.RUNNING and _process_gone(t.user_attrs):
            study._storage.set_trial_user_attr(t._trial_id, INTERRUPTED, True)
            study._storage.set_trial_state_values(t._trial_id, TrialState.FAIL)
            again.append(t)
        elif t.state == TrialState.FAIL and t.user_attrs.get(INTERRUPTED):
            again.append(t)
    queued = []
    for t in again:
        if t.number in done:
            continue
        attrs = {k: v for k, v in t.user_attrs.items() if k not in (_HOST, _PID, INTERRUPTED, REQUEUED_FROM)
                 and not k.endswith("_se")}
        study.enqueue_trial(dict(t.params), user_attrs={**attrs, REQUEUED_FROM: t.number})
        queued.append(t.number)
    return queued


def finished_count(study) -> int:
    """Trials finished so far, interrupted ones not counted (they are re-queued)."""
    from optuna.trial import TrialState

    return sum(1 for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.FAIL,
                                                                  TrialState.PRUNED))
               if not t.user_attrs.get(INTERRUPTED))


def reseeded_sampler(make: Callable[[int], Any], seed: int):
    """An Optuna sampler built anew for every trial by ``make(seed)``, seeded with ``(seed, finished trials)``
    (see the module doc). Optuna is imported here, when a study runs, not with the command line."""
    import numpy as np
    from optuna.samplers import BaseSampler

    class ReseededSampler(BaseSampler):
        def __init__(self):
            self._inner = make(int(seed))

        def before_trial(self, study, trial) -> None:
            from optuna.trial import TrialState

            # processes sharing the study at once differ in the trials running before theirs
            ahead = sum(1 for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
                        if t.number < trial.number)
            key = int(np.random.SeedSequence([int(seed), finished_count(study), ahead]).generate_state(1)[0])
            self._inner = make(key)
            self._inner.before_trial(study, trial)

        def infer_relative_search_space(self, study, trial):
            return self._inner.infer_relative_search_space(study, trial)

        def sample_relative(self, study, trial, search_space):
            return self._inner.sample_relative(study, trial, search_space)

        def sample_independent(self, study, trial, param_name, param_distribution):
            return self._inner.sample_independent(study, trial, param_name, param_distribution)

        def after_trial(self, study, trial, state, values) -> None:
            self._inner.after_trial(study, trial, state, values)

        def reseed_rng(self) -> None:
            self._inner.reseed_rng()

    return ReseededSampler()


class InterruptGate:
    """Ctrl-C and SIGTERM stop a study only inside a trial's evaluation, never inside Optuna's own bookkeeping.

    A signal that arrives while Optuna records a trial (its heartbeat thread, a storage transaction) would leave
    a thread running or a trial half-told, and the process could hang at exit. Within ``with gate:`` a signal is
    kept while Optuna works and raised as the previous handler would (KeyboardInterrupt; the CLI's SIGTERM
    handler records the signal first) at once inside ``with gate.trial():`` or at the next :meth:`check`
    (the start of the next evaluation, or the callback after a trial is told). Outside the main thread it
    changes nothing."""

    SIGNALS = ("SIGINT", "SIGTERM")

    def __init__(self):
        self._inside, self._pending, self._old = False, None, {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                sig = getattr(signal, name)
                self._old[sig] = signal.signal(sig, self._on_signal)
        return self

    def __exit__(self, *exc):
        for sig, old in self._old.items():
            signal.signal(sig, old)
        return False

    def _on_signal(self, signum, frame):
        self._pending = (signum, frame)
        if self._inside:
            self.check()

    def check(self, *_args) -> None:
        """Raise the kept signal (as its previous handler would), if one arrived."""
        if self._pending is None:
            return
        signum, frame = self._pending
        self._pending = None
        old = self._old.get(signum)
        if callable(old):
            old(signum, frame)  # the CLI's SIGTERM handler records the signal and raises KeyboardInterrupt
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def trial(self):
        """The evaluation of a trial: a signal interrupts it at once."""
        self._inside = True
        try:
            self.check()
            yield
        finally:
            self._inside = False
