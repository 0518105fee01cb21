"""The polynomial sine of the hinge and plate kernels: its coefficients re-derived, its stated error bound on |x| ≤ π/2,
and the bound's consequence for the curtain model and the plates the sonars see (far below anything a sensor resolves)."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.polynomial import chebyshev as C
from numpy.polynomial import polynomial as P

from finkensim.arena import Arena, walls_step
from finkensim.config import Config
from finkensim.kernels.trig import SIN_COEFFS, SIN_HALF_PI_MAX_ERROR, sin_fast, sin_fast_array, sin_half_pi
from finkensim.sensors.sonar_kernels import shifted_plates_env

from tests.naive import world as naive

HALF_PI = 0.5 * np.pi


def test_coefficients_are_the_chebyshev_fit_of_sin_x_over_x():
    """The derivation the module names: least-squares Chebyshev fit of degree 7 of sin(x)/x in t = x² on
    [0, (π/2)²], converted to the power basis of t."""
    T = HALF_PI ** 2
    t = np.linspace(0.0, T, 20001)
    x = np.sqrt(t)
    y = np.ones_like(t)
    y[1:] = np.sin(x[1:]) / x[1:]
    cheb = C.chebfit(2.0 * t / T - 1.0, y, 7)       # in s = 2t/T − 1
    power = C.cheb2poly(cheb)
    coeffs, lin, acc = np.array([1.0]), np.array([-1.0, 2.0 / T]), np.zeros(1)
    for c in power:                                  # substitute s(t)
        acc = P.polyadd(acc, c * coeffs)
        coeffs = P.polymul(coeffs, lin)
    # the fit is the same function to rounding (values ~1: within 10 ulp on the grid; 4 measured), while its highest power-basis
    # coefficients depend on the LAPACK build at 2e-4 relative (numpy 2.4.6 here: 1.9e-4), being ill-conditioned
    np.testing.assert_allclose(P.polyval(t, SIN_COEFFS), P.polyval(t, acc), rtol=0, atol=2.2e-15)
    np.testing.assert_allclose(SIN_COEFFS, acc, rtol=1e-3, atol=0)


def test_error_bound_on_the_whole_domain():
    xs = np.concatenate([np.linspace(-HALF_PI, HALF_PI, 1_000_001), [HALF_PI, -HALF_PI, 0.0, 1e-300, 5e-324]])
    err = np.array([abs(sin_half_pi(x) - np.sin(x)) for x in xs[::3]] + [abs(sin_half_pi(x) - np.sin(x))
                                                                        for x in xs[-5:]])
    assert err.max() <= SIN_HALF_PI_MAX_ERROR, err.max()


@settings(max_examples=300, deadline=None)
@given(st.floats(-HALF_PI, HALF_PI))
def test_odd_bounded_and_exact_at_zero(x):
    s = sin_half_pi(x)
    assert sin_half_pi(-x) == -s
    assert abs(s) <= 1.0
    assert abs(s - np.sin(x)) <= SIN_HALF_PI_MAX_ERROR
    assert sin_half_pi(0.0) == 0.0 and np.copysign(1.0, sin_half_pi(0.0)) == 1.0  # the at-rest skip relies on +0


def test_hinge_with_the_polynomial_sine_stays_within_a_picoradian_of_the_exact_sine():
    """The consequence of the bound: 2000 world steps (100 s) of plates driven by copters passing by, the kernel
    (polynomial sine) against the NumPy reference (libm sine). The angles differ by < 1e-12 rad (measured: 5e-15), i.e. the surface at
    flight height by < 1e-12 · lever ≈ 0.4 pm — nine orders below the sonar's millimetre resolution."""
    cfg = Config()
    a = Arena.from_config(cfg.arena, cfg.walls)
    p = naive.params(cfg)
    dt = cfg.simulation.dt
    B, S = 3, a.seg_a.shape[0]
    th, om, ig = np.zeros((B, S)), np.zeros((B, S)), np.zeros((B, S))
    nth, nom, nig = th.copy(), om.copy(), ig.copy()
    rng = np.random.default_rng(5)
    phase = rng.uniform(0, 2 * np.pi, (B, S))
    worst = 0.0
    for k in range(2000):
        dist = 0.6 + 0.6 * np.sin(0.01 * k + phase)          # copters coming and going, 0–1.2 m
        walls_step(th, om, ig, dist, a.hinge, a.lever, dt)
        nth, nom, nig = naive.hinge_step(nth, nom, nig, dist, p)
        worst = max(worst, float(np.abs(th - nth).max()))
    assert np.abs(nth).max() > 0.1  # the plates did swing
    assert worst < 1e-12, worst


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.floats(-HALF_PI, HALF_PI), st.floats(-1e6, 1e6), st.sampled_from([np.nan, np.inf, -np.inf, 2.0,
                                                                                       np.nextafter(HALF_PI, 2.0)])))
def test_sin_fast_is_the_polynomial_within_half_pi_and_libm_beyond(x):
    s = sin_fast(x)
    if abs(x) <= HALF_PI:
        assert s == sin_half_pi(x)
    else:
        with np.errstate(invalid="ignore"):  # NaN and ±inf give NaN, as libm
            np.testing.assert_array_equal(s, np.sin(x))
    np.testing.assert_array_equal(sin_fast_array(np.array([[x, -x]])), [[sin_fast(x), sin_fast(-x)]])


@settings(max_examples=100, deadline=None)
@given(st.lists(st.one_of(st.floats(-HALF_PI, HALF_PI), st.floats(-4.0, 4.0)), min_size=1, max_size=64),
       st.floats(0.0, 3.0), st.floats(0.0, 3.0))
def test_plate_shift_within_the_stated_bound_of_the_libm_sine(thetas, lever, gain):
    """The sonars' plate surfaces (shifted_plates_env, sin_fast) against lever·gain·sin θ with libm's sine: within
    SIN_HALF_PI_MAX_ERROR · lever · gain (plus the rounding of the products) where the hinge keeps the plates
    (|θ| ≤ π/2), equal beyond; a femtometre at most for the 0.4 m lever of the default scene."""
    th = np.array(thetas)
    S = th.size
    rng = np.random.default_rng(S)
    a, b = rng.uniform(0, 4, (S, 2)), rng.uniform(0, 4, (S, 2))
    nrm = rng.normal(size=(S, 2))
    nrm /= np.hypot(nrm[:, 0], nrm[:, 1])[:, None]
    pa, pb = np.empty((S, 2)), np.empty((S, 2))
    shifted_plates_env(th, a, b, nrm, lever, gain, pa, pb)
    sh = np.minimum(lever * gain * np.sin(th), lever)
    bound = np.where(np.abs(th) <= HALF_PI, SIN_HALF_PI_MAX_ERROR * lever * gain, 0.0) + 4e-16 * (1 + lever * gain)
    for got, ref in ((pa, a + sh[:, None] * nrm), (pb, b + sh[:, None] * nrm)):
        assert np.all(np.abs(got - ref) <= bound[:, None] + 8e-16 * np.abs(ref)), np.abs(got - ref).max()
    outside = np.abs(th) > HALF_PI
    np.testing.assert_array_equal(pa[outside], (a + sh[:, None] * nrm)[outside])
    # the NumPy side of the model (Arena.displacement) uses the same sine
    arena = Arena.from_config(Config().arena, Config().walls)
    th64 = np.resize(th, arena.n_plates)
    np.testing.assert_array_equal(arena.displacement(th64), arena.lever * np.array([sin_fast(x) for x in th64]))
