"""The prepared diagnosis (:class:`Diagnosis`): the logs replayed and tabulated once, and the evaluations every stage
of :func:`~finkensim.gap.pipeline.run_diagnosis` asks of them.

1. **Replay** every log (:mod:`.replay`) and build per-sensor tables of the real readings with
   context features and a predictive ensemble of M draws per reading (:mod:`.predictive`).
2. **Score**: per reading, CRPS(F, y) and the gap E|X − y| − E|X − X'| (zero-mean when the real
   readings could have come from the model, :mod:`.scoring`). Each sensor's values are divided
   by a fixed scale, the base model's mean absolute error E|X − y| on the training flights, so
   sensors with different units share one dimensionless score; ranging adds the Brier score of
   missing readings. The overall score is the mean over sensors of the per-reading mean.
3. **Where**: per sensor, channel and feature, quantile bins with block-bootstrap CIs, ranked by
   gap, Benjamini–Hochberg across all bins (:mod:`.detect.locations`).
4. **Which**: fit every catalogued effect (:mod:`.effects`) on the training flights, score it on
   held-out flights (:meth:`Diagnosis.fit`, :meth:`Diagnosis.score_heldout`).

The selection and the verdict (``docs/formats/gap-report.md``) are the stages of
:func:`~finkensim.gap.pipeline.run_diagnosis`: :mod:`.attribute.selection`, :mod:`.quantify.verdict`.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy import optimize

from ..budget import check_memory, gap_arrays
from ..config import Config
from ..flightlog import FlightLog
from .attribute import effects as fx
from ..sensors.sonar_model import ERROR_NONE
from .detect.censoring import detect_censoring
from .attribute.fits import nelder_mead
from .detect.limits import range_limits
from .detect.locations import locate_gap
from .attribute.fit_result import FitResult
from .model.params import SENSORS, ModelParams
from .model.cache import CACHE_BYTES
from .model.predictive import LRU, ImuTable, RangingTable, SonarTable
from .model.inputs import GapInputError, check_heldout  # check_heldout: public here too (it moved)
from .model.replay import prepare_flights
from .model.scoring import brier, brier_gap, ensemble_terms_grouped, normal_sf
from .detect.stats import BlockBootstrap

class Diagnosis:
    """Holds the prepared flights, tables and row sets; evaluates models; runs the search.

    Parameters
    ----------
    logs : list of FlightLog
        The flights to diagnose.
    names : list of str
        Their names (file names), in the same order.
    cfg : Config
        Simulator configuration (error models, walls, ``[gap]`` settings).
    heldout : list of str, optional
        Names of the held-out flights (default: every other flight; a single flight's second half is held
        out).
    progress : callable, optional
        ``progress(message)``, told what the diagnosis is doing.
    seed : int
        Seed of the predictive draws (common random numbers for every model evaluated).
    limits : {"config", "from-log"}
        "config": readings beyond a sensor's configured ``max_range`` are a named error; "from-log": such limits
        are raised to the logs' largest reading (:mod:`.limits`); ``limit_notes`` says what was taken from the logs.
    """

    def __init__(self, logs: list[FlightLog], names: list[str], cfg: Config, heldout: list[str] | None = None,
                 progress: Callable[[str], None] | None = None, seed: int = 20261122, limits: str = "config"):
        if not logs:
            raise GapInputError("no flight logs given: expected at least one REAL.npz")
        cfg, self.limit_notes = range_limits(cfg, logs, names, limits)
        self.cfg = cfg
        self.seed = int(seed)
        self.M = cfg.gap.draws
        self.say = progress or (lambda msg: None)
        self.names = list(names)
        self._replay(logs)
        self.base = ModelParams.from_config(cfg)
        self._split(heldout)
        self._tabulate()
        self.censoring = self._censoring()
        self._choose_rows()
        self._blocks()
        self._score_cache = LRU(64)
        self._score_cache_eval = LRU(64, CACHE_BYTES)  # held-out and all rows: apart from the fits' training rows
        self._fit_means = {}  # (sensor, predictive key) → mean training score
        self._scales()

    # ------------------------------------------------------------------ set-up
    def _replay(self, logs):
        """The logs replayed through the simulator's geometry (:func:`~finkensim.gap.model.replay.prepare_flights`),
        refused before the tables are built when their arrays would not fit in memory."""
        cfg = self.cfg
        self.say("replaying flights")
        self.flights = prepare_flights(logs, self.names, cfg)
        readings = 0.0
        for f in self.flights:  # per sample: sonars, ranging row, IMU channels of every copter
            lg = f.log
            per = (lg.ultrasonic.shape[2] if lg.ultrasonic is not None else 0) + (
                f.n_copters - 1 if lg.ranging is not None else 0) + (3 if lg.imu_acc is not None else 0)
            readings += f.samples.size * f.n_copters * per
        check_memory(gap_arrays(cfg, readings), f"the diagnosis of {len(self.flights)} flight(s)",
                     "lower gap.max_samples_per_flight or gap.draws, or diagnose fewer flights at once")

    def _tabulate(self):
        """Per sensor, the table of its real readings with their context and predictive draws."""
        cfg = self.cfg
        self.say("building reading tables")
        self.tables = {}
        for sensor, cls in (("ultrasonic", SonarTable), ("ranging", RangingTable), ("imu", ImuTable)):
            tab = cls.build(self.flights, cfg, self.seed)
            if tab is not None and tab.n > 0:
                self.tables[sensor] = tab
        if not self.tables:
            raise GapInputError("the logs carry no sensor readings (ultrasonic, ranging or imu): nothing to compare")

    def _scales(self):
        """Each sensor's fixed scale: the configured model's mean absolute error E|X − y| on the training rows."""
        self.scale = {}
        for s in self.tables:
            a, _ = self._terms(s, self.base, self.rows_fit[s])
            v = float(np.nanmean(a)) if np.isfinite(a).any() else 1.0
            self.scale[s] = max(v, 1e-9)

    def _split(self, heldout):
        n = len(self.flights)
        self.single = n == 1
        check_heldout(self.names, heldout)
        if self.single:
            f = self.flights[0]
            mid = f.t[0] + 0.5 * (f.t[-1] - f.t[0])
            self._is_heldout = lambda fl, sec: (f.t[0] + sec) >= mid
            # spec: flights are named by file; with one flight both lists name it (its halves)
            self.train_names, self.heldout_names = [f.name], [f.name]
            return
        if heldout:
            ho = set(heldout)
        else:
            ho = {f.name for f in self.flights[1::2]}
        self.heldout_names = [f.name for f in self.flights if f.name in ho]
        self.train_names = [f.name for f in self.flights if f.name not in ho]
        hidx = {f.index for f in self.flights if f.name in ho}
        self._is_heldout = lambda fl, sec: np.isin(fl, list(hidx))

    def _censoring(self) -> dict:
        """Per range sensor, the :class:`~.censoring.Censoring` of its readings (limits from the config and
        the logs, fixed for the whole diagnosis so that every model is scored on the same scale)."""
        out = {}
        if "ultrasonic" in self.tables:
            sp = self.base.sonar
            out["ultrasonic"] = detect_censoring(self.tables["ultrasonic"].y, sp.min_range, sp.max_range,
                                                 sp.sigma if sp.error != ERROR_NONE else 0.0,
                                                 margin_floor=0.02 * sp.max_range)
        if "ranging" in self.tables:
            r = self.base.ranging
            out["ranging"] = detect_censoring(self.tables["ranging"].y, -np.inf, r.max_range, 0.0,
                                              margin_floor=0.05 * r.max_range)
        return out

    def _choose_rows(self):
        rng = np.random.default_rng(self.seed)
        cap = self.cfg.gap.fit_max_readings
        self.rows_fit, self.rows_ho, self.rows_all = {}, {}, {}
        for s, tab in self.tables.items():
            if self.single:
                ho = self._is_heldout(tab.flight, tab.seconds)
            else:
                ho = self._is_heldout(tab.flight, tab.seconds)
            tr_rows = np.nonzero(~ho)[0]
            ho_rows = np.nonzero(ho)[0]
            if tr_rows.size == 0 or ho_rows.size == 0:
                part = "training" if tr_rows.size == 0 else "held-out"
                why = ""
                if s == "imu":
                    w, bl = self.cfg.gap.imu_window, self.cfg.gap.imu_velocity_baseline
                    why = (f"; an IMU reading integrates gap.imu_window = {w:g} s of a flight (after "
                           f"gap.imu_velocity_baseline = {bl:g} s), so each {part} flight "
                           f"(or half of a single flight) must be longer than that: use longer flights or a smaller "
                           f"gap.imu_window")
                raise GapInputError(f"{s}: no readings in the {part} flights{why}")
            self.rows_fit[s] = np.sort(rng.choice(tr_rows, min(cap, tr_rows.size), replace=False))
            tab.mark_training(self.rows_fit[s])
            self.rows_ho[s] = np.sort(rng.choice(ho_rows, min(4 * cap, ho_rows.size), replace=False))
            allr = np.arange(tab.n)
            self.rows_all[s] = np.sort(rng.choice(allr, min(6 * cap, allr.size), replace=False))

    def _blocks(self):
        """Bootstrap blocks: contiguous time windows per flight, at least 25 on the held-out set."""
        ho_span = 0.0
        for f in self.flights:
            span = f.t[-1] - f.t[0]
            ho_span += 0.5 * span if self.single else (span if f.name in self.heldout_names else 0.0)
        self.block_seconds = min(self.cfg.gap.block_seconds, max(ho_span / 25.0, 1e-3))

    def block_ids(self, sensor, rows):
        tab = self.tables[sensor]
        return tab.flight[rows] * 10_000_000 + np.floor(tab.seconds[rows] / self.block_seconds).astype(np.int64)

    # ------------------------------------------------------------------ scoring
    def censored_draws(self, sensor, p: ModelParams, rows):
        """(draws (n, M), readings (n,), period (n,)) of ``rows`` under p, both sides through the sensor's
        censoring (the chaining function of the threshold-weighted CRPS) when it has one."""
        tab = self.tables[sensor]
        D, period = tab.draws(self.flights, p, rows, self.seed, self.M)
        y = tab.y[rows]
        cens = self.censoring.get(sensor)
        if cens is not None:
            D, y = cens.draws(D), cens.observed(y)
        return D, y, period

    def _terms(self, sensor, p: ModelParams, rows):
        D, y, period = self.censored_draws(sensor, p, rows)
        return ensemble_terms_grouped(np.ascontiguousarray(D), np.ascontiguousarray(y), period)

    def score_rows(self, sensor, p: ModelParams, rows):
        """Per-row normalised (CRPS, gap) of a sensor under parameters p. Each (len(rows),).

        Cached by the parameters that this sensor depends on, so effects on other sensors (and
        repeated evaluations of the same model) cost nothing.
        """
        key = (sensor, id(rows), rows.size, p.sensor_key(sensor))
        cache = self._score_cache if rows is self.rows_fit.get(sensor) else self._score_cache_eval
        hit = cache.get(key)
        if hit is not None:
            return hit
        out = self._score_rows(sensor, p, rows)
        cache.put(key, out)
        return out

    def _score_rows(self, sensor, p: ModelParams, rows):
        a, b = self._terms(sensor, p, rows)
        sc = self.scale.get(sensor, 1.0)
        crps = (a - 0.5 * b) / sc
        gap = (a - b) / sc
        if sensor == "ranging":
            tab = self.tables[sensor]
            prob = tab.dropout_prob(p, rows)
            z = tab.missing[rows].astype(float)
            crps = np.nan_to_num(crps, nan=0.0) + brier(prob, z)
            gap = np.nan_to_num(gap, nan=0.0) + brier_gap(prob, z)
        return crps, gap

    def overall(self, values: dict, rows: dict, n_boot=None):
        """Mean over sensors of the per-row mean of ``values`` (sensor → (n,)), with block-bootstrap
        CI and one-sided p-value for a positive mean. Returns (mean, (lo, hi), p)."""
        sensors = [s for s in values if np.isfinite(values[s]).any()]
        if not sensors:
            return math.nan, (math.nan, math.nan), math.nan
        ids = {s: self.block_ids(s, rows[s]) for s in sensors}
        uniq = np.unique(np.concatenate(list(ids.values())))
        bb = BlockBootstrap(uniq, n_boot=n_boot or self.cfg.gap.n_boot, seed=self.seed)
        means, reps = [], []
        for s in sensors:
            v = values[s]
            ok = np.isfinite(v)
            inv = np.searchsorted(uniq, ids[s][ok])
            sums = np.bincount(inv, weights=v[ok], minlength=uniq.size)
            cnt = np.bincount(inv, minlength=uniq.size).astype(float)
            means.append(sums.sum() / cnt.sum())
            with np.errstate(invalid="ignore", divide="ignore"):
                reps.append((bb.weights @ sums) / (bb.weights @ cnt))
        mean = float(np.mean(means))
        rep = np.nanmean(np.vstack(reps), axis=0)
        rep = rep[np.isfinite(rep)]
        if rep.size < 10:
            return mean, (math.nan, math.nan), math.nan
        lo, hi = np.quantile(rep, [0.025, 0.975])
        se = float(np.std(rep, ddof=1))
        p = normal_sf(mean / se) if se > 0 else (0.0 if mean > 0 else 1.0)
        return mean, (float(lo), float(hi)), p

    def evaluate(self, p: ModelParams, which="heldout", sensors=None):
        """Per-sensor per-row (crps, gap) on a row set ('fit', 'heldout', 'all')."""
        rows = {"fit": self.rows_fit, "heldout": self.rows_ho, "all": self.rows_all}[which]
        out = {}
        for s in (sensors or self.tables):
            if s in self.tables:
                out[s] = self.score_rows(s, p, rows[s])
        return out, rows

    # ------------------------------------------------------------------ where
    def locations(self, p: ModelParams):
        """Gap per (sensor, channel, feature, bin) on all flights under p, sorted by gap
        (:func:`~finkensim.gap.detect.locations.locate_gap`)."""
        return locate_gap(self, p)

    # ------------------------------------------------------------------ which
    def objective(self, effect, current: ModelParams, sensors, values: dict) -> float:
        """The training score of ``effect`` at ``values`` on top of ``current`` (lower is better): what every fit
        minimises (:class:`~finkensim.gap.attribute.objective.FitObjective`).

        Parameters
        ----------
        effect : Effect
            Anything with ``apply(current, values) -> ModelParams``.
        current : ModelParams
            The model the effect is added to.
        sensors : sequence of str
            The sensors scored (a sensor without readings adds nothing).
        values : dict
            Parameter name → value.

        Returns
        -------
        float
            The sum over ``sensors`` of the mean normalised CRPS on their training rows.
        """
        p = effect.apply(current, values)
        tot = 0.0
        for s in sensors:
            if s in self.tables:
                # a mean is small: every one is kept, so a later round's refits (which see the same predictive
                # of every sensor that the selected effects leave alone) cost nothing
                key = (s, p.sensor_key(s))
                mean = self._fit_means.get(key)
                if mean is None:
                    crps, _ = self.score_rows(s, p, self.rows_fit[s])
                    mean = self._fit_means[key] = float(np.nanmean(crps))
                tot += mean
        return tot

    def fit(self, effect: fx.Effect, current: ModelParams) -> FitResult:
        """Fit an effect's parameters on the training rows (the rest of the model fixed at ``current``).

        Parameters
        ----------
        effect : Effect
            The effect to fit.
        current : ModelParams
            The model it is added to.

        Returns
        -------
        FitResult
            The fitted values and the training score; held-out fields NaN (see :meth:`score_heldout`).
        """
        vals = dict(effect.start(current))
        sensors = [s for s in effect.sensors if s in self.tables]
        if effect.fit is not None:
            vals = effect.fit(self, effect, current, vals)
        else:
            free = effect.free(self)
            groups = [[p] for p in free] if effect.separable else [list(free)] if free else []
            for group in groups:
                sens = [group[0].name] if (effect.separable and group[0].name in SENSORS) else sensors
                if not any(s in self.tables for s in sens):
                    continue
                vals = self.fit_group(effect, current, sens, vals, group)
        p = effect.apply(current, vals)
        return FitResult(effect.name, vals, p, self.objective(effect, current, sensors, vals))

    def fit_group(self, effect, current: ModelParams, sensors, vals: dict, group) -> dict:
        """The generic search over the parameters ``group`` of ``effect``, the others fixed at ``vals``: an integer
        parameter over every integer in its range, a continuous one on a grid refined by a bounded scalar search,
        several together on a coarse grid refined by Nelder–Mead (:class:`~finkensim.gap.attribute.objective.FitObjective`).

        Parameters
        ----------
        effect : Effect
            The effect fitted.
        current : ModelParams
            The model it is added to.
        sensors : sequence of str
            The sensors scored.
        vals : dict
            Parameter name → starting value.
        group : sequence of Param
            The parameters searched together.

        Returns
        -------
        dict
            ``vals`` with the group's parameters at the best point found.
        """
        f = lambda v: self.objective(effect, current, sensors, v)  # noqa: E731
        if len(group) == 1:
            prm = group[0]
            if prm.integer:
                cands = range(int(prm.lo), int(prm.hi) + 1)
                scores = [f({**vals, prm.name: c}) for c in cands]
                return {**vals, prm.name: int(list(cands)[int(np.argmin(scores))])}
            grid = np.unique(np.concatenate([prm.grid(9), [vals[prm.name]]]))
            scores = np.array([f({**vals, prm.name: g}) for g in grid])
            j = int(np.argmin(scores))
            a, b = grid[max(0, j - 1)], grid[min(grid.size - 1, j + 1)]
            if b > a:
                r = optimize.minimize_scalar(lambda x: f({**vals, prm.name: x}), bounds=(a, b), method="bounded",
                                             options={"xatol": (prm.hi - prm.lo) / 400, "maxiter": 12})
                best = r.x if r.fun < scores[j] else grid[j]
            else:
                best = grid[j]
            return {**vals, prm.name: float(best)}
        # several continuous parameters: coarse grid, then Nelder–Mead inside the bounds
        axes = [q.grid(5) for q in group]
        best_x, best_f = np.array([vals[q.name] for q in group], float), None
        best_f = f(vals)
        for pt in np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(group), -1).T:
            v = f({**vals, **{q.name: float(x) for q, x in zip(group, pt)}})
            if v < best_f:
                best_f, best_x = v, pt
        return nelder_mead(f, vals, group, best_x, best_f)

    def score_heldout(self, res: FitResult, gap_before_parts=None):
        """Score a fitted effect on the held-out rows (and its gap on the training rows).

        Parameters
        ----------
        res : FitResult
            A result of :meth:`fit`; updated in place.
        gap_before_parts : object, optional
            Not used (kept for callers that pass the configured model's gap).

        Returns
        -------
        FitResult
            ``res``, with ``score_heldout``, ``gap_heldout``, ``gap_train``, ``rows_score`` and ``rows_gap``
            set (per reading, normalised; lower is better).
        """
        ev, rows = self.evaluate(res.params, "heldout")
        res.rows_score = {s: c for s, (c, _) in ev.items()}
        res.rows_gap = {s: g for s, (_, g) in ev.items()}
        res.score_heldout = float(np.mean([np.nanmean(c) for c, _ in ev.values()]))
        res.gap_heldout = float(np.mean([np.nanmean(g) for _, g in ev.values()]))
        evt, _ = self.evaluate(res.params, "fit")
        res.gap_train = float(np.mean([np.nanmean(g) for _, g in evt.values()]))
        return res
