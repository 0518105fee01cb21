"""joint_fit: two effects that trade off on one sensor, fitted together, reach the floor of the valley that fitting
one on top of the other stops partway along (the sonar_bias + sound_speed pair of the gap validation)."""
from __future__ import annotations

import pytest

from finkensim.gap.attribute.effects import Effect, Param
from finkensim.gap.attribute.fits import joint_fit


def _effect(name, params):
    def apply(p, v):
        return {**p, **{f"{name}.{k}": x for k, x in v.items()}}
    return Effect(name, ("ultrasonic",), params, apply)


def _valley(p):
    """Readings y = c·d + b against truth c = 1.06, b = −0.08 at distances 0.5–2 m: a long, narrow valley."""
    c, b, k = p.get("scale.c", 1.0), p.get("bias.b", 0.0), p.get("scale.k", 0)
    return sum((c * d + b - (1.06 * d - 0.08)) ** 2 for d in (0.5, 1.0, 1.5, 2.0)) + 0.01 * k * k


class _Diag:
    base: dict = {}
    tables = {"ultrasonic": None}
    flights: list = []  # no log states a tracking noise

    def __init__(self):
        self.calls = 0

    def objective(self, effect, current, sensors, values):
        self.calls += 1
        assert sensors == ["ultrasonic"]
        return _valley(effect.apply(current, values))


SCALE = _effect("scale", (Param("c", 0.8, 1.25), Param("k", 0, 3, integer=True)))
BIAS = _effect("bias", (Param("b", -0.5, 0.5),))


def test_joint_fit_reaches_the_floor_that_one_on_top_of_the_other_misses():
    d = _Diag()
    # the greedy path: the scale alone, then the bias on top (both exact 1-D minima)
    c1 = 1.06 - 0.08 * (0.5 + 1.0 + 1.5 + 2.0) / (0.25 + 1 + 2.25 + 4)     # least squares of c with b = 0
    b1 = sum(1.06 * x - 0.08 - c1 * x for x in (0.5, 1.0, 1.5, 2.0)) / 4   # then b with c fixed
    greedy = _valley({"scale.c": c1, "bias.b": b1})
    vs, vb = joint_fit(d, [SCALE, BIAS], [{"c": c1, "k": 2}, {"b": b1}], maxfev=80)
    joint = _valley({"scale.c": vs["c"], "bias.b": vb["b"], "scale.k": 0})
    assert joint < 0.05 * greedy
    assert vs["c"] == pytest.approx(1.06, abs=0.01) and vb["b"] == pytest.approx(-0.08, abs=0.015)
    assert vs["k"] == 2  # integer parameters stay as given
    assert d.calls <= 82


def test_joint_fit_never_returns_worse_than_its_start():
    d = _Diag()
    start = [{"c": 1.06, "k": 0}, {"b": -0.08}]   # already the optimum
    vs, vb = joint_fit(d, [SCALE, BIAS], start, maxfev=10)
    assert _valley({"scale.c": vs["c"], "bias.b": vb["b"]}) <= _valley({"scale.c": 1.06, "bias.b": -0.08})


def _solve_bias(diag, effect, current, vals):
    """The bias's closed form on top of the model ``current``: the mean residual against the valley's truth."""
    diag.solves += 1
    c = current.get("scale.c", 1.0)
    return {"b": sum(1.06 * d - 0.08 - c * d for d in (0.5, 1.0, 1.5, 2.0)) / 4}


PROFILED_BIAS = Effect("bias", ("ultrasonic",), (Param("b", -0.5, 0.5),),
                       lambda p, v: {**p, **{f"bias.{k}": x for k, x in v.items()}}, fit=_solve_bias, profiled=True)


@pytest.mark.parametrize("order", [0, 1])
def test_a_profiled_effect_is_solved_on_top_of_the_searched_ones_at_every_step(order):
    # the node delays beside a range scale: the delays' own fit, redone at each trial scale, leaves a 1-D search
    d = _Diag()
    d.solves = 0
    effects, start = [SCALE, PROFILED_BIAS], [{"c": 1.0, "k": 1}, {"b": 0.0}]
    if order:
        effects, start = effects[::-1], start[::-1]
    out = dict(zip((e.name for e in effects), joint_fit(d, effects, start, maxfev=40)))
    assert out["scale"]["c"] == pytest.approx(1.06, abs=0.005)
    assert out["bias"]["b"] == pytest.approx(-0.08, abs=0.008)
    assert out["scale"]["k"] == 1
    assert d.solves == d.calls + 1  # one solve per objective call, and one for the values returned
