"""Run an Optuna study of a study file: trials, storage, figures, and the held-out comparison.

    from finkensim.tune import run_study
    res = run_study("examples/tune.toml", out="out/tune")
    res.best            # dotted key -> tuned value
    res.comparison      # pandas DataFrame: defaults vs tuned on held-out environments, 95 % CIs

Each trial is one batched Monte-Carlo evaluation (:func:`~finkensim.tune.evaluate.evaluate`: ``n_envs``
environments in one compiled rollout, the same environments for every trial). Trial 0 is the base
scenario's own values (enqueued), so the defaults are part of the study. The study lives in an SQLite file
(``DIR/study.db``) or the RDB URL of the study file's ``storage``: a killed study resumes where it stopped
(finished trials are kept; ``n_trials`` counts finished trials), and several processes — on one machine
with SQLite, or on many with an RDB server such as PostgreSQL — can run the same study file at once.

Outputs in DIR: ``study.db``, ``trials.csv``, ``best.json``, ``heldout.csv``, ``figures/history*.png``,
``figures/importances*.png`` and (several objectives) ``figures/pareto.png``.
"""
from __future__ import annotations

import json
import os
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import write_atomic, write_text_atomic
from ..config import ConfigError
from .evaluate import compare, evaluate
from .resume import INTERRUPTED, InterruptGate, check_same_study, mark_process, requeue_interrupted, reseeded_sampler
from .storage import open_storage
from .studyfile import StudySpec, parse_study

__all__ = ["run_study", "StudyResult", "storage_url", "select_best"]

DEFAULTS_ROLE = "defaults"
#: a trial whose process died is marked failed once its heartbeat is older than two of these (s)
HEARTBEAT_S = 30


@dataclass
class StudyResult:
    """What :func:`run_study` produced: the Optuna ``study``, the selected ``best`` values (dotted key ->
    value) and its ``best_trial`` number, the held-out ``comparison`` (DataFrame, None when skipped),
    ``out`` (Path) and the written ``figures`` (paths)."""

    study: Any
    spec: StudySpec
    best: dict
    best_trial: int
    comparison: Any
    out: Path
    figures: list


def storage_url(spec: StudySpec, out: Path, storage: str | None = None) -> str:
    """The storage URL: an RDB URL as given, else ``sqlite:///`` of the file relative to ``out``."""
    s = storage or spec.storage
    if "://" in s:
        return s
    path = Path(s) if Path(s).is_absolute() else out / s
    return f"sqlite:///{path.resolve()}"


def _sampler(spec: StudySpec):
    """The study's sampler, seeded anew for each trial from the seed and the trials finished so far
    (:func:`~.resume.reseeded_sampler`): a resumed study samples what an uninterrupted one does."""
    import optuna

    if spec.sampler == "random":
        make = lambda seed: optuna.samplers.RandomSampler(seed=seed)  # noqa: E731
    elif spec.sampler == "nsga2":
        make = lambda seed: optuna.samplers.NSGAIISampler(  # noqa: E731
            seed=seed, population_size=max(4, min(50, spec.n_trials // 4)))
    else:
        make = lambda seed: optuna.samplers.TPESampler(  # noqa: E731
            seed=seed, n_startup_trials=max(2, min(10, spec.n_trials // 4)))
    return reseeded_sampler(make, spec.seed)


def _suggest(trial, spec: StudySpec) -> dict:
    values = {}
    for p in spec.params:
        if p.choices is not None:
            values[p.key] = trial.suggest_categorical(p.key, list(p.choices))
        elif p.kind == "int":
            values[p.key] = trial.suggest_int(p.key, int(p.low), int(p.high), log=p.log)
        else:
            values[p.key] = trial.suggest_float(p.key, float(p.low), float(p.high), log=p.log)
    return values


def _objective(spec: StudySpec, gate: InterruptGate):
    metrics = [m for m, _ in spec.objectives]

    def objective(trial):
        mark_process(trial)
        values = _suggest(trial, spec)
        try:
            with gate.trial():
                m = evaluate(spec.config(values), spec.n_envs, spec.eval_seed, spec.duration, metrics)
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: FAIL, re-queued when the study resumes
            trial.set_user_attr(INTERRUPTED, True)
            raise
        except ConfigError as exc:  # one line, no traceback (Optuna's log is off); the trial is FAIL
            warnings.warn(f"trial {trial.number} failed ({', '.join(f'{k} = {v!r}' for k, v in values.items())}): "
                          f"{exc}", RuntimeWarning, stacklevel=2)
            raise
        out = []
        for name in metrics:
            x = m[name][np.isfinite(m[name])]
            trial.set_user_attr(f"{name}_se", float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else float("nan"))
            out.append(float(x.mean()) if x.size else float("nan"))
        return out[0] if len(out) == 1 else tuple(out)

    return objective


def _open_study(url: str, spec: StudySpec, directions: list[str], attempts: int = 10):
    """(study, created): create the study in the RDB storage ``url``, or load it if it exists. Processes that
    start at once on a new SQLite file race to create its tables; the loser retries after a short pause. Only
    the process that created the study gets ``created`` True (the storage's unique study name decides)."""
    import optuna
    from optuna.exceptions import DuplicatedStudyError
    from sqlalchemy.exc import DBAPIError, SQLAlchemyError

    for attempt in range(attempts):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                rdb = open_storage(url, heartbeat_interval=HEARTBEAT_S, grace_period=2 * HEARTBEAT_S)
            try:
                return optuna.create_study(study_name=spec.study_name, storage=rdb, sampler=_sampler(spec),
                                           directions=directions), True
            except DuplicatedStudyError:
                return optuna.load_study(study_name=spec.study_name, storage=rdb, sampler=_sampler(spec)), False
        except DBAPIError as exc:
            if attempt == attempts - 1 or "unable to open" in str(exc):  # a race for a new file retries
                raise _storage_error(url, exc) from None
            time.sleep(0.2 * (attempt + 1))
        except (SQLAlchemyError, ImportError, OSError, ValueError) as exc:  # bad URL, missing driver, no such dir
            raise _storage_error(url, exc) from None


def _storage_error(url: str, exc: BaseException) -> ConfigError:
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return ConfigError(f"storage {url!r} cannot be opened ({type(exc).__name__}: {first}); expected an SQLite file "
                       "in a writable directory or an RDB URL such as postgresql://user@host/db with its driver "
                       "installed")


def _enqueue_defaults(study, spec: StudySpec) -> None:
    """Enqueue the base scenario's values as the first trial (those inside the ranges; others are sampled)."""
    fixed = {}
    for p in spec.params:
        v = spec.defaults()[p.key]
        inside = v in p.choices if p.choices is not None else p.low <= v <= p.high
        if inside:
            fixed[p.key] = v
    study.enqueue_trial(fixed, user_attrs={"role": DEFAULTS_ROLE}, skip_if_exists=True)


def select_best(study, spec: StudySpec):
    """The selected trial: the best one for one objective; for several, the Pareto-optimal trial with the
    largest summed relative improvement over the defaults trial (over the min-max range of all finished
    trials when there is no finished defaults trial)."""
    if len(spec.objectives) == 1:
        return study.best_trial
    from optuna.trial import TrialState

    done = [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))]
    vals = np.array([t.values for t in done], dtype=float)
    sign = np.array([1.0 if d == "minimize" else -1.0 for _, d in spec.objectives])
    ref = [t for t in done if t.user_attrs.get("role") == DEFAULTS_ROLE]
    if ref:
        base = np.asarray(ref[0].values, dtype=float)
        scale = np.maximum(np.abs(base), 1e-12)
    else:
        base = vals.min(axis=0)
        scale = np.maximum(vals.max(axis=0) - vals.min(axis=0), 1e-12)
    pareto = study.best_trials
    score = [float(np.sum(sign * (np.asarray(t.values) - base) / scale)) for t in pareto]
    return pareto[int(np.argmin(score))]


def _figures(study, spec: StudySpec, out: Path) -> list[Path]:
    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as ovm

    fdir = out / "figures"
    fdir.mkdir(parents=True, exist_ok=True)
    multi = len(spec.objectives) > 1
    jobs = []
    for i, (metric, _) in enumerate(spec.objectives):
        kw = dict(target=lambda t, i=i: t.values[i], target_name=metric) if multi else dict(target_name=metric)
        suffix = f"_{metric}" if multi else ""
        jobs.append((f"history{suffix}.png", lambda kw=kw: ovm.plot_optimization_history(study, **kw)))
        jobs.append((f"importances{suffix}.png", lambda kw=kw: ovm.plot_param_importances(study, **kw)))
    if multi:
        names = [m for m, _ in spec.objectives]
        jobs.append(("pareto.png", lambda: ovm.plot_pareto_front(study, target_names=names)))
    written = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # optuna marks its matplotlib backend experimental
        for name, make in jobs:
            try:
                ax = make()
            except (ValueError, RuntimeError, ZeroDivisionError) as exc:  # e.g. too few finished trials
                warnings.warn(f"figure {name} skipped: {exc}", RuntimeWarning, stacklevel=2)
                continue
            fig = (ax.flat[0] if isinstance(ax, np.ndarray) else ax).figure
            fig.set_size_inches(7, 4.5)
            write_atomic(fdir / name, lambda tmp: fig.savefig(tmp, dpi=100, bbox_inches="tight"))
            plt.close(fig)
            written.append(fdir / name)
    return written


def _prepare(spec: StudySpec, out: Path, storage: str | None):
    """(study, created): ``out`` created, the storage opened, the study checked to be the same study as any
    already stored there (:func:`~.resume.check_same_study`) and only then ``out/study.toml`` written. On a
    refusal nothing is left behind: an ``out`` this call created is removed again."""
    import shutil

    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r} is a file: expected a directory")
    made = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {str(out)!r}: cannot create the directory ({exc.strerror or exc})") from None
    try:
        if not os.access(out, os.W_OK | os.X_OK):
            raise ConfigError(f"--out {str(out)!r}: the directory is not writable")
        url = storage_url(spec, out, storage)
        directions = [d for _, d in spec.objectives]
        st, created = _open_study(url, spec, directions)
        if [d.name.lower() for d in st.directions] != directions:
            raise ConfigError(f"storage {url!r} holds a study {spec.study_name!r} with directions "
                              f"{[d.name.lower() for d in st.directions]}, not {directions}: use another study_name "
                              "or --out")
        check_same_study(st, spec, created, f"storage {url!r}")
        if spec.text is not None:
            write_text_atomic(out / "study.toml", spec.text)
    except (ConfigError, OSError) as exc:
        if made:
            shutil.rmtree(out, ignore_errors=True)
        if isinstance(exc, OSError):
            raise ConfigError(f"--out {str(out)!r}: cannot write ({exc.strerror or exc})") from None
        raise
    return st, created


def _progress_bar(spec: StudySpec, todo: int):
    """A labelled trial bar; its first trial compiles the kernels (its rate and ETA settle from the second)."""
    import sys

    from tqdm import tqdm

    return tqdm(total=todo, desc=f"tune trials ({spec.n_envs} envs x {spec.duration:g} s; the first compiles)",
                unit="trial", file=sys.stderr, smoothing=0.5)


def run_study(study: StudySpec | str | Path, out: str | Path = "out/tune", *, n_trials: int | None = None,
              storage: str | None = None, progress: bool = True, heldout: bool = True,
              figures: bool = True) -> StudyResult:
    """Run (or resume) the study of a study file / :class:`StudySpec` and write its outputs to ``out``.

    Args:
        study: a study TOML path or text, or a parsed :class:`StudySpec`.
        out: output directory (created).
        n_trials: finished trials to reach (default: the file's ``n_trials``).
        storage: an RDB URL or SQLite path overriding the file's ``storage``.
        progress: show a progress bar.
        heldout: re-evaluate the selected values and the defaults on the held-out environments.
        figures: write the Optuna figures as PNG.
    """
    import optuna
    from optuna.study import MaxTrialsCallback
    from optuna.trial import TrialState

    spec = study if isinstance(study, StudySpec) else parse_study(study)
    if n_trials is not None:
        if isinstance(n_trials, bool) or not isinstance(n_trials, int) or n_trials < 1:
            raise ConfigError(f"n_trials = {n_trials!r}: expected a positive integer")
        spec = replace(spec, n_trials=n_trials)
    out = Path(out)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    st, created = _prepare(spec, out, storage)
    if created:  # once, by the process that created the study
        _enqueue_defaults(st, spec)
    requeue_interrupted(st)
    done = len(st.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)))
    todo = max(0, spec.n_trials - done)
    if todo:
        optuna.logging.set_verbosity(optuna.logging.ERROR)  # failed trials: our one-line warning, no traceback
        bar = _progress_bar(spec, todo) if progress else None
        callbacks = [MaxTrialsCallback(spec.n_trials, states=(TrialState.COMPLETE,))]
        if bar is not None:
            callbacks.append(lambda study, trial: bar.update(1))
        try:
            with InterruptGate() as gate:  # Ctrl-C / SIGTERM act inside a trial's evaluation, not in Optuna's records
                st.optimize(_objective(spec, gate), n_trials=todo, catch=(ConfigError,),
                            callbacks=[*callbacks, gate.check])
        finally:
            if bar is not None:
                bar.close()
    trials = st.trials_dataframe()
    write_atomic(out / "trials.csv", lambda tmp: trials.to_csv(tmp, index=False))
    best_trial = select_best(st, spec)
    best = {p.key: best_trial.params[p.key] for p in spec.params if p.key in best_trial.params}
    write_text_atomic(out / "best.json", json.dumps(
        {"trial": best_trial.number, "params": best, "values": dict(zip([m for m, _ in spec.objectives],
                                                                        best_trial.values)),
         "defaults": spec.defaults(), "n_trials_finished": len(st.get_trials(states=(TrialState.COMPLETE,)))},
        indent=2, default=str))
    comparison = None
    if heldout:
        import pandas as pd

        comparison = pd.DataFrame(compare(spec, best))
        write_atomic(out / "heldout.csv", lambda tmp: comparison.to_csv(tmp, index=False))
    figs = _figures(st, spec, out) if figures else []
    return StudyResult(study=st, spec=spec, best=best, best_trial=best_trial.number, comparison=comparison, out=out,
                       figures=figs)
