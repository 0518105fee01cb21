"""Parameter searches of the diagnosis: a bounded Nelder–Mead, a joint fit of several effects, and the effects'
own fits.

An effect's own fit (its ``Effect.fit``, :data:`~finkensim.gap.attribute.objective.EffectFit`) is
``fit(diag, effect, current, vals) -> vals``: the diagnosis as a fit sees it
(:class:`~finkensim.gap.attribute.objective.FitObjective`: the objective, the generic group search, the tables and
training rows), the effect, the model it is fitted on top of and the starting values; it returns the fitted values
by parameter name. The catalogue's own fits are the ``fit_*`` functions below.
"""
from __future__ import annotations

import dataclasses
import math
import numpy as np
from scipy import optimize

from .objective import FitObjective
from .stated import stated_floor


def nelder_mead(f, vals, group, x0, f0, maxfev=40):
    """Nelder–Mead over the parameters ``group`` from x0 (objective f0 there), inside their bounds."""
    lo = np.array([q.lo for q in group])
    hi = np.array([q.hi for q in group])
    g = lambda x: f({**vals, **{q.name: float(c) for q, c in zip(group, np.clip(x, lo, hi))}})  # noqa: E731
    r = optimize.minimize(g, np.asarray(x0, float), method="Nelder-Mead",
                          options={"maxfev": maxfev, "xatol": 1e-3, "fatol": 1e-6,
                                   "initial_simplex": _simplex(np.asarray(x0, float), (hi - lo) / 8, lo, hi)})
    x = np.clip(r.x, lo, hi) if r.fun < f0 else np.asarray(x0, float)
    return {**vals, **{q.name: float(c) for q, c in zip(group, x)}}


class _Chain:
    """Several effects applied in order as one, their parameters named ``effect.param``."""

    def __init__(self, effects):
        self.effects = list(effects)

    def apply(self, p, values: dict):
        for e in self.effects:
            p = e.apply(p, {q.name: values[f"{e.name}.{q.name}"] for q in e.params})
        return p


def joint_fit(diag: FitObjective, effects, values, maxfev: int = 40):
    """Fit the continuous parameters of ``effects`` together (integer ones stay as given): a Nelder–Mead from
    ``values`` (one dict per effect) on the training rows of their sensors, the effects applied in order on the
    configured model. Returns one dict of values per effect.

    Two effects on one sensor can trade off (a range scale and a bias both shift readings at the distances flown):
    fitted one on top of the other, each stops partway along that valley; fitted together they reach its floor.

    A :attr:`~finkensim.gap.attribute.effects.Effect.profiled` effect is not searched: at each trial value of the
    others its own closed-form fit solves it on top of them (the profile of the objective; eight per-node delays and a
    range scale searched together did not move in the search's budget, and the delays absorbed most of a 1.08 scale)."""
    if any(e.profiled for e in effects) and not all(e.profiled for e in effects):
        return _profiled_joint_fit(diag, effects, values, maxfev)
    chain = _Chain(effects)
    flat, group = _search_space(diag, effects, values)
    sensors = sorted({s for e in effects for s in e.sensors if s in diag.tables})
    f = lambda v: diag.objective(chain, diag.base, sensors, v)  # noqa: E731
    out = nelder_mead(f, flat, group, [flat[q.name] for q in group], f(flat), maxfev=maxfev) if group else flat
    return [{q.name: out[f"{e.name}.{q.name}"] for q in e.params} for e in effects]


def _profiled_joint_fit(diag: FitObjective, effects, values, maxfev: int):
    """:func:`joint_fit` with the profiled effects solved by their own fits on top of the others at each trial value
    of the others' continuous parameters (a Nelder–Mead over those)."""
    searched = [(e, v) for e, v in zip(effects, values) if not e.profiled]
    chain = _Chain([e for e, _ in searched])
    flat, group = _search_space(diag, [e for e, _ in searched], [v for _, v in searched])
    sensors = sorted({s for e in effects for s in e.sensors if s in diag.tables})

    def solved(v):
        """The profiled effects' values fitted on top of the searched ones at ``v``, and the model they make."""
        p = chain.apply(diag.base, v)
        own = {}
        for e, vals in zip(effects, values):
            if e.profiled:
                own[e.name] = e.fit(diag, e, p, dict(vals))
                p = e.apply(p, own[e.name])
        return own, p

    def f(v):
        _, p = solved(v)
        return diag.objective(_Fixed(p), diag.base, sensors, {})

    out = nelder_mead(f, flat, group, [flat[q.name] for q in group], f(flat), maxfev=maxfev) if group else flat
    own, _ = solved(out)
    return [own[e.name] if e.profiled else {q.name: out[f"{e.name}.{q.name}"] for q in e.params} for e in effects]


def _search_space(diag: FitObjective, effects, values):
    """The joint search's start (``effect.param`` → value, every parameter) and its continuous informed parameters
    (named ``effect.param``), each bounded below by what the logs state (:func:`~.stated.stated_floor`; a start below
    it is raised to it)."""
    flat = {f"{e.name}.{k}": v for e, vals in zip(effects, values) for k, v in vals.items()}
    group = [dataclasses.replace(q, name=f"{e.name}.{q.name}") for e in effects for q in e.free(diag) if not q.integer]
    floors = {f"{e.name}.{k}": v for e in effects for k, v in stated_floor(diag.flights, e.name).items()}
    group = [dataclasses.replace(q, lo=max(q.lo, floors[q.name])) if q.name in floors else q for q in group]
    flat = {k: max(v, floors[k]) if k in floors else v for k, v in flat.items()}
    return flat, group


class _Fixed:
    """A model given whole, as an effect for :meth:`objective` (its values ignored)."""

    def __init__(self, p):
        self.p = p

    def apply(self, _current, _values):
        return self.p


def _simplex(x0, step, lo, hi):
    pts = [np.array(x0, float)]
    for i in range(len(x0)):
        p = np.array(x0, float)
        p[i] = p[i] + step[i] if p[i] + step[i] <= hi[i] else p[i] - step[i]
        pts.append(p)
    return np.array(pts)


# ---------------------------------------------------------------------- closed-form fits

def fit_imu_bias(diag: FitObjective, effect, current, vals):
    """Biases by least squares on the windowed residuals around the model's mean draw: the two
    accelerometer biases (body frame) jointly through each window's rotation, the gyro bias alone."""
    if "imu" not in diag.tables:
        return vals
    tab = diag.tables["imu"]
    rows = diag.rows_fit["imu"]
    D, _ = tab.draws(diag.flights, current, rows, diag.seed, diag.M)
    res = tab.y[rows] - D.mean(axis=1)
    ch = tab.channel[rows]
    out = dict(vals)
    lim = {q.name: (q.lo, q.hi) for q in effect.params}
    acc = np.isfinite(res) & (ch < 2)
    if acc.sum() >= 2:
        A = tab.bias_gain[rows[acc]]
        sol = np.linalg.lstsq(A, res[acc], rcond=None)[0]
        out["acc_x"] = float(np.clip(sol[0], *lim["acc_x"]))
        out["acc_y"] = float(np.clip(sol[1], *lim["acc_y"]))
    gy = np.isfinite(res) & (ch == 2)
    if gy.any():
        out["gyro"] = float(np.clip(np.sum(res[gy] * tab.window_s[rows[gy]]) / np.sum(tab.window_s[rows[gy]] ** 2),
                                    *lim["gyro"]))
    return out


def fit_dropout(diag: FitObjective, effect, current, vals):
    """Logistic regression of 'missing' on true distance by maximum likelihood (no draws needed)."""
    if "ranging" not in diag.tables:
        return vals
    tab = diag.tables["ranging"]
    rows = diag.rows_fit["ranging"]
    z = tab.missing[rows].astype(float)
    x = tab.features["true_range"][rows]
    if z.sum() == 0:
        return dict(vals)  # nothing missing: the model's own dropout (the start values)

    def nll(ab):
        s = ab[0] + ab[1] * x
        return float(np.mean(np.logaddexp(0.0, s) - z * s))

    r = optimize.minimize(nll, np.array([math.log(max(z.mean(), 1e-6) / max(1 - z.mean(), 1e-6)), 0.0]),
                          method="L-BFGS-B", bounds=[(effect.params[0].lo, effect.params[0].hi),
                                                     (effect.params[1].lo, effect.params[1].hi)])
    return {"a": float(r.x[0]), "b": float(r.x[1])}


#: points of each of :func:`smoothed_min`'s two grids
SMOOTH_POINTS = 9


def smoothed_min(f, lo: float, hi: float, n: int = SMOOTH_POINTS) -> float:
    """Where a rough 1-D objective ``f`` is least on [lo, hi]: ``n`` points over the interval, ``n`` more between the
    best one's neighbours, and the vertex of a least-squares parabola through the points of that narrower window (the
    best point there when the parabola opens downward or its vertex leaves the window).

    The training score of a parameter that moves the replayed poses (tracking noise) has dips a few percent wide:
    readings whose rays flip between a copter and a wall as σ changes. A bracketing search (Brent) stops in whichever
    dip it meets; the parabola follows the curve's shape (`pose_noise` seed 104 of the calibration table: the
    bracketing search 21.1 mm, the parabola 22.6 mm, the truth 22.6 mm; docs/calibration.md). Costs 2n − 1
    evaluations or fewer (points that coincide are evaluated once).

    Parameters
    ----------
    f : callable
        float → float, the objective.
    lo, hi : float
        The interval, lo < hi.
    n : int
        Points of each grid (≥ 3).

    Returns
    -------
    float
        The minimiser's estimate, within [lo, hi].
    """
    xs = [float(x) for x in np.linspace(lo, hi, n)]
    ys = [f(x) for x in xs]
    j = int(np.argmin(np.where(np.isfinite(ys), ys, np.inf)))
    a, b = xs[max(0, j - 1)], xs[min(n - 1, j + 1)]
    fine = [float(x) for x in np.linspace(a, b, n) if not np.any(np.isclose(x, xs, rtol=0.0, atol=1e-15))]
    xs += fine
    ys += [f(x) for x in fine]
    x = np.asarray(xs)
    y = np.asarray(ys)
    window = (x >= a) & (x <= b) & np.isfinite(y)
    if not window.any():
        return xs[j]
    best = float(x[window][np.argmin(y[window])])
    if window.sum() < 3:
        return best
    c2, c1, _ = np.polyfit(x[window], y[window], 2)
    if not c2 > 0.0:
        return best
    vertex = -c1 / (2.0 * c2)
    return float(vertex) if a <= vertex <= b else best


def fit_pose_noise(diag: FitObjective, effect, current, vals):
    """Coordinate search over tracking noise: σ_xy first (yaw at its current value), then σ_yaw; each on a
    coarse grid, then refined by :func:`smoothed_min` between the best point's grid neighbours; never below the
    noise the logs state (:func:`~finkensim.gap.attribute.stated.stated_floor`: a best below it is searched again between the
    stated value and the next grid point)."""
    sensors = [s for s in effect.sensors if s in diag.tables]
    sx0 = current.sigma_xy if current.sigma_xy is not None else float(np.mean([f.sigma_xy for f in diag.flights]))
    sy0 = current.sigma_yaw if current.sigma_yaw is not None else float(np.mean([f.sigma_yaw for f in diag.flights]))
    v = {"sigma_xy": sx0, "sigma_yaw": sy0}
    floor = stated_floor(diag.flights, effect.name)  # never less noise than a log states
    f = lambda vv: diag.objective(effect, current, sensors, vv)  # noqa: E731
    for name, grid in (("sigma_xy", [0.0, 0.001, 0.002, 0.004, 0.007, 0.012, 0.02, 0.035, 0.05]),
                       ("sigma_yaw", [0.0, 0.005, 0.01, 0.02, 0.04, 0.08, 0.15, 0.2])):
        cands = sorted(set(grid) | {v[name]})
        scores = [f({**v, name: c}) for c in cands]
        i = int(np.argmin(scores))
        v[name] = float(cands[i])
        lo, hi = cands[max(0, i - 1)], cands[min(len(cands) - 1, i + 1)]
        if hi > lo:
            v[name] = smoothed_min(lambda c: f({**v, name: float(c)}), lo, hi)
        if v[name] < floor.get(name, 0.0):  # the best lies below the stated noise: search between it and the next point
            lo = floor[name]
            hi = min((c for c in grid if c > lo), default=lo)
            v[name] = lo
            if hi > lo:
                v[name] = smoothed_min(lambda c: f({**v, name: float(c)}), lo, hi)
    return v


def fit_latency(diag: FitObjective, effect, current, vals):
    """Per sensor, a search over whole log samples between the bounds (s): every ``stride``-th lag first
    (about 16 candidates), then a pattern search from the best with steps stride/2, stride/4, … and finally 1
    until no neighbour improves (the exhaustive ±stride scan it replaced cost 2·stride − 1 evaluations per
    sensor; this takes about 2·log₂ stride + 2). The CRPS uses common random numbers, so it is a deterministic
    function of the lag; the refinement catches a minimum between coarse points."""
    dt = min(f.dt for f in diag.flights)
    out = dict(vals)
    for prm in effect.params:
        if prm.name not in diag.tables:
            continue
        f = lambda k: diag.objective(effect, current, [prm.name], {**out, prm.name: k * dt})  # noqa: E731
        lo, hi = math.ceil(prm.lo / dt - 1e-9), math.floor(prm.hi / dt + 1e-9)
        stride = max(1, (hi - lo) // 16)
        start = int(round(out[prm.name] / dt))
        scores = {k: f(k) for k in sorted(set(range(0, hi + 1, stride)) | set(range(0, lo - 1, -stride)) | {start})
                  if lo <= k <= hi}
        rank = lambda k: (scores[k], abs(k))  # noqa: E731  (ties go to the smaller lag)
        best = min(scores, key=rank)
        step = max(1, stride // 2)
        while True:
            for k in (best - step, best + step):
                if lo <= k <= hi and k not in scores:
                    scores[k] = f(k)
            moved = min((k for k in (best - step, best, best + step) if k in scores), key=rank)
            if moved == best and step == 1:
                break
            if step > 1:  # halve; at step 1 keep climbing while a neighbour improves
                step //= 2
            best = moved
        best = min(scores, key=rank)
        out[prm.name] = best * dt
    return out


def fit_bulge(diag: FitObjective, effect, current, vals):
    """Amplitude and reach first with the plates following at once (grid, then Nelder–Mead), then a few
    shapes, then a few response times, each with the others fixed, then all four together from the best."""
    sensors = [s for s in effect.sensors if s in diag.tables]
    amp, reach, resp, shape = effect.params
    v = diag.fit_group(effect, current, sensors, vals, [amp, reach])
    f = lambda vv: diag.objective(effect, current, sensors, vv)  # noqa: E731
    for name, grid in (("shape", (2.0, 4.0, 8.0)), ("response", (0.0, 0.3, 0.8, 1.5))):
        cands = [{**v, name: c} for c in sorted({v[name], *grid})]
        scores = [f(c) for c in cands]
        i = int(np.argmin(scores))
        v = cands[i]
    group = [amp, reach, resp, shape]
    return nelder_mead(f, v, group, [v[q.name] for q in group], scores[i], maxfev=60)


#: s of each flight's start searched on the full rate grid by :func:`hold_rhythms` (then refined on all of it)
RHYTHM_WINDOW = 120.0
#: cycles over the longest flight to which :func:`hold_rhythms` refines each of its best rates
REFINE_RESOLUTION = 0.01


def _coherence(rates, times):
    """(strength (R,), mean direction (R,) complex): over flights, |Σ exp(2πi·rate·t)| / count and the flights' unit
    sums; ``times`` a list of (n_f,) arrays of change times (s)."""
    total = np.zeros(rates.size, dtype=np.complex128)
    strength = np.zeros(rates.size)
    for tt in times:
        acc = np.zeros(rates.size, dtype=np.complex128)
        for chunk in np.array_split(tt, max(1, tt.size // 256)):
            acc += np.exp(2j * np.pi * np.outer(rates, chunk)).sum(axis=1)
        strength += np.abs(acc) / tt.size / len(times)
        total += acc / np.maximum(np.abs(acc), 1e-300)
    return strength, total


def hold_rhythms(flights, lo: float, hi: float, n: int = 3, resolution: float = 0.25):
    """The ``n`` strongest sample-and-hold rhythms in the sonar readings: [(rate Hz, phase in periods, strength)].

    A held sonar changes its reading only at measuring samples, so the times of the changes (a sample whose reading
    differs from the previous sample's, any copter and sonar) line up with a period 1/rate: the strength of a rate is
    the mean over flights of |Σ exp(2πi·rate·t)| / count over the changes' times t (1: every change on one rhythm; the
    harmonics of a true rate are smeared by the changes' rounding to samples; rates at or above 2/3 of the log rate
    are not held at all and are not searched). The rate grid stays in phase to ``resolution`` cycles over the first
    :data:`RHYTHM_WINDOW` s of the flights; each of the best rates is then refined on all their changes, on a grid in
    phase to :data:`REFINE_RESOLUTION` cycles over the longest flight.
    The phase is the mean direction of the flights' sums.
    """
    times, longest, fastest = [], 0.0, math.inf
    for fl in flights:
        u = fl.log.ultrasonic
        if u is None or u.shape[0] < 3:
            continue
        prev, cur = u[:-1], u[1:]
        changed = np.any((cur != prev) & np.isfinite(cur) & np.isfinite(prev), axis=(1, 2))
        k = np.flatnonzero(changed) + 1
        if k.size >= 10:
            times.append(k * fl.dt)
            longest = max(longest, u.shape[0] * fl.dt)
            fastest = min(fastest, 1.0 / fl.dt)
    hi = min(hi, fastest / 1.5)
    if not times or hi <= max(lo, 0.5):
        return []
    window = min(longest, RHYTHM_WINDOW)
    rates = np.arange(max(lo, 0.5), hi, resolution / window)
    strength, total = _coherence(rates, [t[t < window] for t in times if (t < window).sum() >= 10] or times)
    out = []
    for i in np.argsort(-strength):
        if all(abs(rates[i] - r) > 2 * resolution / window for r, _, _ in out):
            # refine on every change, over ± one grid step: a grid in phase to REFINE_RESOLUTION cycles over the
            # longest flight (a rate off by a grid step of 0.25 cycles drifts the hold moments by a quarter period
            # over the flight: a calibrated 2.4 Hz sonar, 0.13 % off, left 8 % of the gap)
            step = resolution / window
            r_grid = float(rates[i])
            fine = r_grid + np.arange(-step, step + 1e-12, REFINE_RESOLUTION / longest)
            fs, ft = _coherence(fine, times)
            j = int(np.argmax(fs))
            r, z, st = float(fine[j]), ft[j], float(fs[j])
            out.append((r, float((np.angle(z) / (2 * np.pi)) % 1.0), st))
        if len(out) == n:
            break
    return out


def fit_update_rate(diag: FitObjective, effect, current, vals):
    """Sample-and-hold: the strongest rhythms of the readings' changes (:func:`hold_rhythms`; they pick rate and
    phase to within the grid, a step function of both being hopeless for a simplex over a long flight) scored
    against the starting values, the best kept. The rhythms are found in every sample of the flights (held-out
    ones too): two numbers from thousands of change times; the choice among them is by the training score."""
    rate, phase = effect.params
    f = lambda v: diag.objective(effect, current, ["ultrasonic"], v)  # noqa: E731
    dt = min(fl.dt for fl in diag.flights)
    # a change shows at the first sample at or after its measurement, on average half a sample late
    cands = [dict(vals)] + [{rate.name: r, phase.name: (ph - r * dt * back) % 1.0}
                            for r, ph, _ in hold_rhythms(diag.flights, rate.lo, rate.hi) for back in (0.5, 0.25, 0.0)]
    scores = [f(c) for c in cands]
    return cands[int(np.argmin(scores))]


#: cross-talk cone half-angles (deg) :func:`fit_crosstalk_cone` scores before its local refinement
CONE_GRID = (15.0, 25.0, 35.0, 40.0, 45.0, 50.0, 55.0, 65.0)
#: hearing probabilities scored at each cone of :data:`CONE_GRID`
CONE_GRID_PROBABILITIES = (0.5, 1.0)


def fit_crosstalk_cone(diag: FitObjective, effect, current, vals):
    """Geometric cross-talk's hearing probability p and cone half-angle together: the start values and a coarse grid
    (each cone of :data:`CONE_GRID` with each p of :data:`CONE_GRID_PROBABILITIES`), then a Nelder–Mead over both from
    the best. A cone wider than the model's cannot be reached through p ≤ 1, and a narrower one only roughly through
    p < 1 (p thins every path alike, a cone only the oblique ones), so the cone is searched, not p alone. Every cone
    tried is a replay of the cross-talk paths (p only redraws the readings, on cached geometry), hence the short grid.
    With p at 0 the cone changes nothing: it stays at its start value."""
    sensors = [s for s in effect.sensors if s in diag.tables]
    if not sensors:
        return dict(vals)
    prob, cone = effect.params
    f = lambda v: diag.objective(effect, current, sensors, v)  # noqa: E731
    best, best_f = dict(vals), f(vals)
    for c in CONE_GRID:
        for p in CONE_GRID_PROBABILITIES:
            v = {**vals, prob.name: p, cone.name: float(np.clip(c, cone.lo, cone.hi))}
            s = f(v)
            if s < best_f:
                best, best_f = v, s
    group = [prob, cone]
    out = nelder_mead(f, best, group, [best[q.name] for q in group], best_f, maxfev=30)
    if out[prob.name] <= 0.0:
        out[cone.name] = vals[cone.name]
    return out
