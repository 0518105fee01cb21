"""Gap diagnosis: scoring rules, statistics, replay kernels vs NumPy references, report and CLI."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from finkensim import flightlog
from finkensim.arena import Arena
from finkensim.cli import main
from finkensim.config import Config, ConfigError, config_from_dict
from finkensim.gap.model import replay as rp
from finkensim.gap import Diagnosis, GapReport, diagnose, run_diagnosis
from finkensim.gap.model.features import sonar_channel_names
from finkensim.gap.model.params import gaussian_draws, sonar_echo_errors, sonar_reading_draws
from finkensim.gap.model.replay import GapInputError
from finkensim.gap.report.write import SPEC_KEYS, spec_report
from finkensim.gap.model.scoring import (brier_gap, crps_ensemble, crps_normal, ensemble_terms, ensemble_terms_grouped,
                                   gap_ensemble)
from finkensim.gap.detect.stats import BlockBootstrap, fdr_significant, time_blocks
from finkensim.gap.validation.cases import CASES, generate
from finkensim.kernels.rng import STREAM_EFFECT, counter_key
from finkensim.sensors.sonar_kernels import measured_reading
from finkensim.sensors.sonar_model import (CROSSTALK_GEOMETRIC, CROSSTALK_OFF, SCHEDULE_SIMULTANEOUS, sonar_scalars,
                                           wall_geometry)
from finkensim.sensors.sonar import SonarModel, ideal_sonar
from finkensim.sensors.tracking import draw_poses
from tests.naive import gap as naive
from tests.stats import assert_above_se, assert_mean_within_se, assert_proportion_within_se, se_mean

SMALL = {"gap.draws": 12, "gap.max_samples_per_flight": 300, "gap.fit_max_readings": 5000, "gap.n_boot": 200}


# ----------------------------------------------------------------------------------- scoring

def test_crps_ensemble_matches_closed_form_normal():
    rng = np.random.default_rng(0)
    n, M = 4000, 400
    mu, sig = rng.normal(size=n), rng.uniform(0.5, 2.0, n)
    y = mu + sig * rng.normal(size=n)
    draws = mu[:, None] + sig[:, None] * rng.normal(size=(n, M))
    diff = crps_ensemble(draws, y) - crps_normal(mu, sig, y)
    # the fair estimator is unbiased: 5 SE of the sample ≈ 0.0033, ≈ 0.5 % of the mean CRPS (≈ 0.7)
    assert_mean_within_se(diff, 0.0, what="fair ensemble CRPS − closed-form CRPS")
    # its per-reading error has sd ~ sigma/sqrt(M)·O(1): an accuracy ceiling (≈ 0.029 here), not an estimate
    assert np.mean(np.abs(diff)) < 0.05


def test_crps_normal_known_values():
    # CRPS(N(0,1), 0) = 2φ(0) − 1/√π
    assert crps_normal(0.0, 1.0, 0.0) == pytest.approx(2 * stats.norm.pdf(0) - 1 / math.sqrt(math.pi))
    assert crps_normal(1.0, 2.0, 1.0) == pytest.approx(2 * crps_normal(0.0, 1.0, 0.0))


def test_gap_is_zero_mean_when_reality_matches_the_model_and_positive_otherwise():
    rng = np.random.default_rng(1)
    n, M = 20000, 24
    draws = rng.gamma(2.0, 1.0, size=(n, M))
    y = rng.gamma(2.0, 1.0, size=n)
    g = gap_ensemble(draws, y)
    assert_mean_within_se(g, 0.0, what="gap under the model")  # 5 SE ≈ 0.026, ≈ 1.8 % of E|X − X'| = 1.5
    g2 = gap_ensemble(draws, y * 1.5 + 1.0)  # ≈ 1.0, SE 0.013
    assert_above_se(g2.mean(), 0.3, se_mean(g2), what="gap of a stretched and shifted reality")


def test_ensemble_terms_match_brute_force():
    rng = np.random.default_rng(2)
    draws, y = rng.normal(size=(50, 16)), rng.normal(size=50)
    y[3] = np.nan
    a, b = ensemble_terms(draws, y)
    na, nb = naive.ensemble_terms(draws, y)
    np.testing.assert_allclose(a, na, rtol=1e-12, equal_nan=True)
    np.testing.assert_allclose(b, nb, rtol=1e-12, equal_nan=True)
    period = rng.integers(1, 20, size=50)
    a2, b2 = ensemble_terms_grouped(draws, y, period)
    na2, nb2 = naive.ensemble_terms(draws, y, period)
    np.testing.assert_allclose(a2, na2, rtol=1e-12, equal_nan=True)
    np.testing.assert_allclose(b2, nb2, rtol=1e-12, equal_nan=True)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 23), M=st.integers(2, 30), seed=st.integers(0, 2**32 - 1))
def test_grouped_terms_four_rows_at_once_equal_row_by_row(n, M, seed):
    """The four-row blocks of ensemble_terms_grouped give each row's numbers bit for bit (mixed periods, NaN)."""
    import finkensim.gap.model.scoring as scoring
    rng = np.random.default_rng(seed)
    draws, y = rng.normal(size=(n, M)), rng.normal(size=n)
    y[rng.random(n) < 0.1] = np.nan
    period = np.where(rng.random(n) < 0.8, min(M - 1, 8), rng.integers(1, M + 2, size=n)).astype(np.int64)
    a, b = ensemble_terms_grouped(draws, y, period)
    for i in range(n):
        if not np.isfinite(y[i]):
            assert np.isnan(a[i]) and np.isnan(b[i])
            continue
        if period[i] <= 1 or period[i] >= M:
            ra, rb = scoring._sorted_terms(np.sort(draws[i]), y[i])
        else:
            ra, rb = scoring._grouped_terms(draws[i], y[i], period[i])
        assert (a[i], b[i]) == (ra, rb)


def test_grouped_pair_term_is_unbiased_when_members_share_an_input():
    """Members m and m+G share a draw of a random input: all pairs underestimate E|X−X'|, independent pairs do not."""
    rng = np.random.default_rng(3)
    n, M, G = 20000, 24, 8
    shared = rng.normal(size=(n, G))[:, np.arange(M) % G]
    draws = shared + 0.2 * rng.normal(size=(n, M))
    true = 2 * math.sqrt(1.04) / math.sqrt(math.pi)  # E|X−X'| for X ~ N(0, 1.04)
    _, b_all = ensemble_terms(draws, np.zeros(n))
    _, b_ind = ensemble_terms_grouped(draws, np.zeros(n), np.full(n, G))
    # 2 of 23 pair partners share the input, E|0.2(e − e')| = 2·0.2/√π for them: 7.0 % low
    shared_low = (2 * 2 * 0.2 / math.sqrt(math.pi) + 21 * true) / 23
    assert shared_low < 0.95 * true
    # SE of each mean ≈ 0.002 (from the sample): 5 SE ≈ 0.9 % of E|X − X'|
    assert_mean_within_se(b_all, shared_low, what="pair term over all pairs (members share inputs)")
    assert_mean_within_se(b_ind, true, what="pair term over independent pairs")


def test_brier_gap_zero_mean():
    rng = np.random.default_rng(4)
    p = rng.uniform(0, 1, 50000)
    z = rng.random(50000) < p
    # 5 SE of the sample ≈ 0.004, 2.4 % of the mean Brier score E[p(1 − p)] = 1/6
    assert_mean_within_se(brier_gap(p, z), 0.0, what="Brier gap under the model")


# ----------------------------------------------------------------------------------- statistics

def test_block_bootstrap_ci_covers_the_mean_for_iid_data():
    """The 95 % percentile interval over 40 iid blocks covers like ±z_0.975·(plug-in SE) does for a t_39 statistic:
    P(|t_39| < 1.96·√(39/40)) = 0.940 (the 300-replicate quantile noise moves this by less than the SE). 2 000
    trials: SE √(p(1−p)/n) = 0.0053, 5 SE = 0.027 (2.8 % of 0.94), so an undercoverage of ≈ 3 % fails."""
    rng = np.random.default_rng(5)
    trials = 2000
    ids = time_blocks(np.zeros(2000, int), np.arange(2000), {0: 2000}, n_blocks_per_flight=40)
    covered = np.zeros(trials, dtype=bool)
    for k in range(trials):
        v = rng.normal(size=2000)
        s = BlockBootstrap(ids, n_boot=300, seed=k).stats(v)
        covered[k] = s.ci[0] <= 0 <= s.ci[1]
        assert s.n == 2000 and s.n_blocks == 40
    expected = 1 - 2 * stats.t.sf(stats.norm.ppf(0.975) * math.sqrt(39 / 40), 39)
    assert 0.93 < expected < 0.95
    assert_proportion_within_se(covered, expected, what="coverage of the 95 % block-bootstrap interval")


def test_fdr_control():
    assert list(fdr_significant([0.001, 0.2, np.nan, 0.01])) == [True, False, False, True]
    assert not fdr_significant([0.04] * 10 + [0.9] * 90).any()


# ----------------------------------------------------------------------------------- kernels vs references

def _scene(seed, n=5):
    rng = np.random.default_rng(seed)
    cfg = Config()
    arena = Arena.from_config(cfg.arena, cfg.walls)
    T = 6
    pos = np.stack([rng.uniform([0.2, 0.2], [2.8, 3.8], size=(n, 2)) for _ in range(T)])
    yaw = rng.uniform(-np.pi, np.pi, size=(T, n))
    theta = rng.uniform(0, 0.5, size=(T, arena.n_plates))
    return cfg, arena, pos, yaw, theta


def _sonar_buffers(K, N, S, G):
    """Output arrays of rp.sonar_draws: dist, kind, cross-talk path, each (K, N, S, G)."""
    return [np.empty((K, N, S, G)), np.empty((K, N, S, G), np.int8), np.empty((K, N, S, G))]


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10**6))
def test_sonar_draws_without_pose_noise_equal_the_simulator_and_the_crosstalk_reference(seed):
    cfg, arena, pos, yaw, theta = _scene(seed)
    sm = SonarModel.from_config(cfg)
    times = np.arange(pos.shape[0], dtype=np.int64)
    K, N, S = times.size, pos.shape[1], 4
    dist, kind, xt = _sonar_buffers(K, N, S, 1)
    sp = sm._replace(offset=0.0, max_range=3.0, schedule=SCHEDULE_SIMULTANEOUS, n_slots=1)
    rp.sonar_draws(rp.ReplayPoses(pos, yaw, theta, np.zeros_like(theta)), wall_geometry(arena), sp, 1.0, times,
                   rp.PoseNoise(0.0, 0.0, 0, 0), 1, np.ones((K, N, S), bool), dist, kind, xt)
    d_sim, k_sim, _ = ideal_sonar(pos, yaw, theta, arena, sm)
    np.testing.assert_array_equal(dist[..., 0], d_sim)
    np.testing.assert_array_equal(kind[..., 0], k_sim)
    for k in range(K):
        ref = naive.crosstalk_paths(pos[k], yaw[k], sm.mount_yaw, 0.0, 3.0, sm.cos_half_angle)
        np.testing.assert_allclose(xt[k, ..., 0], ref, rtol=1e-12)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10**6))
def test_sonar_draws_cast_only_the_needed_rays_and_those_exactly(seed):
    cfg, arena, pos, yaw, theta = _scene(seed)
    sp = SonarModel.from_config(cfg)
    times = np.arange(pos.shape[0], dtype=np.int64)
    K, N, S, G = times.size, pos.shape[1], 4, 3
    poses, noise = rp.ReplayPoses(pos, yaw, theta, np.zeros_like(theta)), rp.PoseNoise(0.01, 0.02, seed, 1)
    full, part = _sonar_buffers(K, N, S, G), _sonar_buffers(K, N, S, G)
    rp.sonar_draws(poses, wall_geometry(arena), sp, 1.0, times, noise, G, np.ones((K, N, S), bool), *full)
    need = np.random.default_rng(seed).random((K, N, S)) < 0.3
    rp.sonar_draws(poses, wall_geometry(arena), sp, 1.0, times, noise, G, need, *part)
    for a, b in zip(full, part):
        np.testing.assert_array_equal(b[need], a[need])
    assert np.isnan(part[0][~need]).all() and np.isinf(part[2][~need]).all()


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10**6), sx=st.sampled_from([0.0, 0.003]), sy=st.sampled_from([0.0, 0.02]))
def test_pose_draws_from_the_normal_table_equal_the_keyed_draws(seed, sx, sy):
    """The σ-free table of pose normals the sonar replay reuses gives draw_poses' poses bit for bit."""
    _, _, pos, yaw, _ = _scene(seed)
    times = np.arange(0, pos.shape[0], 2, dtype=np.int64)
    N, G = pos.shape[1], 5
    z = np.empty((times.size, G, N, 3))
    rp.pose_normal_table(times, N, G, seed, 3, z)
    noise = rp.PoseNoise(sx, sy, seed, 3)
    for ti, k in enumerate(times):
        for m in range(G):
            p1, w1, p2, w2 = np.empty((N, 2)), np.empty(N), np.empty((N, 2)), np.empty(N)
            draw_poses(pos, yaw, k, m, noise, p1, w1)
            rp.draw_poses_from(pos, yaw, k, z[ti, m], sx, sy, p2, w2)
            assert p1.tobytes() == p2.tobytes() and w1.tobytes() == w2.tobytes()


def test_sonar_draws_leave_the_crosstalk_paths_out_without_geometric_crosstalk():
    cfg, arena, pos, yaw, theta = _scene(7)
    sp = SonarModel.from_config(cfg)
    assert sp.crosstalk & CROSSTALK_GEOMETRIC
    times = np.arange(pos.shape[0], dtype=np.int64)
    K, N, S = times.size, pos.shape[1], 4
    poses, noise = rp.ReplayPoses(pos, yaw, theta, np.zeros_like(theta)), rp.PoseNoise(0.01, 0.02, 7, 0)
    geo, off = _sonar_buffers(K, N, S, 2), _sonar_buffers(K, N, S, 2)
    rp.sonar_draws(poses, wall_geometry(arena), sp, 1.0, times, noise, 2, np.ones((K, N, S), bool), *geo)
    rp.sonar_draws(poses, wall_geometry(arena), sp._replace(crosstalk=CROSSTALK_OFF), 1.0, times, noise, 2,
                   np.ones((K, N, S), bool), *off)
    assert np.isfinite(geo[2]).any() and np.isinf(off[2]).all()
    for a, b in zip(geo[:2], off[:2]):
        np.testing.assert_array_equal(a, b)


def test_sonar_wall_gain_shortens_wall_readings_by_the_displacement():
    cfg = Config()
    arena = Arena.from_config(cfg.arena, cfg.walls)
    pos = np.array([[[1.5, 1.875]]] * 2)  # one copter facing +x at the centre of an east-wall plate
    yaw = np.zeros((2, 1))
    theta = np.full((2, arena.n_plates), 0.3)
    out = {}
    sp = SonarModel.from_config(cfg)._replace(mount_yaw=np.zeros(1), offset=0.0, radius=0.15, max_range=3.0,
                                              cos_half_angle=0.7, schedule=SCHEDULE_SIMULTANEOUS, n_slots=1)

    def reading(gain, bulge):
        d, k, x = np.empty((2, 1, 1, 1)), np.empty((2, 1, 1, 1), np.int8), np.empty((2, 1, 1, 1))
        rp.sonar_draws(rp.ReplayPoses(pos, yaw, theta, bulge), wall_geometry(arena), sp, gain,
                       np.arange(2, dtype=np.int64), rp.PoseNoise(0.0, 0.0, 0, 0), 1, np.ones((2, 1, 1), bool),
                       d, k, x)
        return d[0, 0, 0, 0]

    for g in (0.0, 1.0, 2.0):
        out[g] = reading(g, np.zeros_like(theta))
    assert out[0.0] == pytest.approx(1.5)
    assert out[0.0] - out[1.0] == pytest.approx(arena.lever * np.sin(0.3))
    assert out[0.0] - out[2.0] == pytest.approx(2 * arena.lever * np.sin(0.3))
    # the wall_bulge effect's own displacement adds to the configured one, also on a rigid wall (gain 0)
    assert out[0.0] - reading(0.0, np.full_like(theta, 0.07)) == pytest.approx(0.07)
    assert out[1.0] - reading(1.0, np.full_like(theta, 0.07)) == pytest.approx(0.07)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 40), st.integers(1, 5), st.floats(0.01, 3.0), st.integers(0, 2**32 - 1))
def test_bulge_response_matches_the_exact_first_order_solution(T, S, tau, seed):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.005, 0.2, T))
    d = rng.uniform(0.0, 1.5, (T, S))
    got = rp.bulge_displacement(d, 0.2, 0.4, tau, t)
    np.testing.assert_allclose(got, naive.first_order_lag(0.2 * np.exp(-(d / 0.4) ** 2), t, tau), rtol=1e-12,
                               atol=1e-15)
    # the kernel runs in place on the target (one array of a long log): the same numbers as into a new array
    from finkensim.gap.model.bulge import first_order_lag
    target, alpha = 0.2 * np.exp(-(d / 0.4) ** 2), -np.expm1(-np.diff(t) / tau)
    apart = first_order_lag(target, alpha, np.empty_like(target))
    np.testing.assert_array_equal(first_order_lag(target, alpha, target), apart)


def test_bulge_response_to_a_step_is_one_minus_an_exponential():
    """A copter appears next to a plate at t = 0: the plate reaches A·(1 − e^(−t/τ)) — the known answer."""
    dt, tau, A = 0.02, 0.5, 0.15
    t = np.arange(101) * dt
    d = np.full((101, 1), 50.0)
    d[1:] = 0.0
    x = rp.bulge_displacement(d, A, 0.3, tau, t)[:, 0]
    np.testing.assert_allclose(x[1:], A * (1 - np.exp(-t[1:] / tau)), rtol=1e-12)
    assert x[0] == pytest.approx(A * math.exp(-(50.0 / 0.3) ** 2), abs=1e-300)
    with pytest.raises(ValueError, match="response"):
        rp.bulge_displacement(d, A, 0.3, -1.0, t)


def test_bulge_displacement_is_amplitude_times_a_gaussian_of_the_plate_distance():
    d = np.array([[0.0, 0.1, 0.3, 2.0]])
    np.testing.assert_allclose(rp.bulge_displacement(d, 0.12, 0.3), 0.12 * np.exp(-(d / 0.3) ** 2), rtol=1e-15)
    assert not rp.bulge_displacement(d, 0.0, 0.3).any()
    with pytest.raises(ValueError, match="reach"):
        rp.bulge_displacement(d, 0.1, 0.0)


@pytest.mark.parametrize("shape", [1.0, 2.0, 4.0, 9.5])
def test_bulge_shape_sets_how_sharply_the_bulge_ends(shape):
    d = np.linspace(0.0, 1.5, 31)[None, :]
    got = rp.bulge_displacement(d, 0.2, 0.6, 0.0, None, shape)
    np.testing.assert_allclose(got, 0.2 * np.exp(-(d / 0.6) ** shape), rtol=1e-14)
    assert got[0, 0] == 0.2 and got[0, 12] == pytest.approx(0.2 / math.e)  # d = reach: amplitude / e for any shape
    if shape > 2:  # flatter inside reach, smaller beyond it than the Gaussian
        gauss = rp.bulge_displacement(d, 0.2, 0.6)
        assert (got[0, 1:12] > gauss[0, 1:12]).all() and (got[0, 13:] < gauss[0, 13:]).all()
    with pytest.raises(ValueError, match="shape"):
        rp.bulge_displacement(d, 0.1, 0.6, 0.0, None, 0.0)


def test_ranging_draws_and_clearance_match_references():
    _, _, pos, yaw, _ = _scene(7, n=6)
    times = np.arange(pos.shape[0], dtype=np.int64)
    out = np.empty((times.size, 6, 6, 1))
    rp.ranging_draws(pos, np.zeros(pos.shape[:2]), yaw, times, rp.PoseNoise(0.0, 0.0, 0, 0), 1, out)
    ref = np.sqrt(((pos[:, :, None] - pos[:, None]) ** 2).sum(-1))
    np.testing.assert_allclose(out[..., 0], ref, rtol=1e-12, atol=1e-15)
    z = np.random.default_rng(3).uniform(0.2, 2.0, pos.shape[:2])  # heights: 3-D distances
    rp.ranging_draws(pos, z, yaw, times, rp.PoseNoise(0.0, 0.0, 0, 0), 1, out)
    p3 = np.concatenate([pos, z[..., None]], axis=-1)
    np.testing.assert_allclose(out[..., 0], np.sqrt(((p3[:, :, None] - p3[:, None]) ** 2).sum(-1)), rtol=1e-12,
                               atol=1e-15)
    clear = np.empty((times.size, 6, 6))
    rp.ranging_clearance(pos, times, clear)
    for k in times:
        r = naive.clearance(pos[k])
        np.fill_diagonal(r, np.inf)
        np.testing.assert_allclose(clear[k], r, rtol=1e-12)


@pytest.mark.parametrize("b", [1, 3])
def test_imu_window_draws_match_reference(b):
    rng = np.random.default_rng(8)
    T, N, h = 40, 3, 5
    t = np.cumsum(rng.uniform(0.04, 0.06, T))
    pos = np.cumsum(rng.normal(scale=0.02, size=(T, N, 2)), axis=0)
    yu = np.cumsum(rng.normal(scale=0.05, size=(T, N)), axis=0)
    times = np.array([10, 20, 39], dtype=np.int64)
    out = np.empty((3, N, 3, 1))
    rp.imu_window_draws(pos, yu, t, times, h, b, rp.PoseNoise(0.0, 0.0, 0, 0), 1, np.ones((3, N), bool), out)
    for i, k in enumerate(times):
        np.testing.assert_allclose(out[i, :, :, 0], naive.imu_windows(pos, yu, t, k, h, b), rtol=1e-10, atol=1e-12)
    # with pose noise, only the needed copters are computed, and those exactly as without the mask
    full, part = np.empty((3, N, 3, 4)), np.empty((3, N, 3, 4))
    need = np.array([[True, False, True], [False, False, True], [True, True, False]])
    rp.imu_window_draws(pos, yu, t, times, h, b, rp.PoseNoise(0.01, 0.02, 3, 1), 4, np.ones((3, N), bool), full)
    rp.imu_window_draws(pos, yu, t, times, h, b, rp.PoseNoise(0.01, 0.02, 3, 1), 4, need, part)
    np.testing.assert_array_equal(part[need], full[need])
    assert np.isnan(part[~need]).all()


@pytest.mark.parametrize("err,flags,p_const,q_hear,scale,bias", [(0, 0, 0.0, 1.0, 1.0, 0.0), (1, 0, 0.0, 1.0, 1.1, 0.05),
                                                            (2, 1, 0.3, 1.0, 1.0, 0.0), (3, 2, 0.0, 0.7, 0.9, 0.0),
                                                            (2, 3, 0.2, 0.5, 1.0, -0.1), (2, 2, 0.0, 1.0, 1.0, 0.0)])
def test_sonar_reading_draws_match_the_simulator_reference(err, flags, p_const, q_hear, scale, bias):
    rng = np.random.default_rng(9)
    n, M = 30, 6
    dist = rng.uniform(0.1, 3.0, (n, M))
    kind = rng.integers(0, 3, (n, M)).astype(np.int8)
    xt = np.where(rng.random((n, M)) < 0.5, rng.uniform(0.2, 6.0, (n, M)), np.inf)
    fl, ti, ch = rng.integers(0, 3, n), rng.integers(0, 100, n), rng.integers(0, 40, n)
    sp = SonarModel.from_config(Config())._replace(error=err, crosstalk=flags, crosstalk_probability=p_const,
                                                   crosstalk_hear_probability=q_hear, range_scale=scale, bias=bias)
    out = np.empty((n, M))
    errors = np.full((n, M), np.nan)  # drawn once (the diagnosis keeps them for every fit of other parameters)
    if err != 0:
        sonar_echo_errors(fl, ti, ch, 11, sp, errors)
    sonar_reading_draws(dist, kind, xt, fl, ti, ch, 11, sp, errors, out)
    np.testing.assert_allclose(out, naive.sonar_reading_draws(dist, kind, xt, fl, ti, ch, 11, sp), rtol=1e-12, atol=1e-15)
    # the reading with a pre-drawn error is the simulator's reading (which draws it itself), bit for bit
    sps = sonar_scalars(sp)
    for i in range(0, n, 7):
        key = np.uint64(counter_key(11, fl[i], ti[i], ch[i], STREAM_EFFECT))
        for m in range(M):
            assert out[i, m] == measured_reading(dist[i, m], kind[i, m] != 0, xt[i, m], key, m, sps)


def test_gaussian_draws_match_the_counter_based_reference():
    from finkensim.kernels.rng import STREAM_EFFECT
    from tests.naive.rng import normals_array

    rng = np.random.default_rng(4)
    n, M = 20, 7
    ideal = rng.normal(size=(n, M))
    fl, ti, ch = rng.integers(0, 3, n), rng.integers(0, 100, n), rng.integers(0, 12, n)
    sd, bias = rng.uniform(0, 0.3, n), rng.normal(size=n)
    out = np.empty((n, M))
    gaussian_draws(ideal, fl, ti, ch, 5, sd, bias, out)
    ref = np.array([ideal[i] + bias[i] + sd[i] * normals_array(5, fl[i], ti[i], ch[i], STREAM_EFFECT, M)
                    for i in range(n)])
    np.testing.assert_allclose(out, ref, rtol=1e-12, atol=1e-14)


def test_sonar_channel_names():
    assert sonar_channel_names(np.radians([0, 90, 180, -90])) == ["front", "left", "back", "right"]
    assert sonar_channel_names(np.radians([3, 45])) == ["front", "sonar1"]


# ----------------------------------------------------------------------------------- diagnosis end to end

@pytest.fixture(scope="module")
def null_logs():
    logs, cfg, _ = generate(CASES["null"], 11, n_flights=2, duration=30.0)
    return logs, cfg.replace(SMALL)


def test_null_case_reports_no_significant_gap_and_a_spec_report(null_logs):
    logs, cfg = null_logs
    rep = run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg))
    assert rep["verdict"]["significant_gap"] is False
    assert rep["verdict"]["effect"] is None
    js = spec_report(rep)
    assert tuple(js) == tuple(k for k in SPEC_KEYS if k != "correction")  # correction: only when unexplained
    json.dumps(js, allow_nan=False)
    assert js["format"] == "finkensim-gap-report/1"
    assert js["flights"] == {"train": ["a.npz"], "heldout": ["b.npz"]}
    gaps = [loc["gap"] for loc in js["locations"]]
    assert gaps == sorted(gaps, reverse=True)
    scores = [e["score_heldout"] for e in js["effects"]]
    assert scores == sorted(scores)
    for loc in js["locations"]:
        assert set(loc) == {"sensor", "channel", "feature", "low", "high", "gap", "ci", "n", "significant"}
        assert loc["significant"] is False  # no significant gap: no location may say otherwise (spec)
        assert loc["sensor"] in ("ultrasonic", "ranging", "imu")
        assert loc["channel"] in ("front", "left", "back", "right", "all")
    feats = {loc["feature"] for loc in js["locations"] if loc["sensor"] == "ultrasonic"}
    for required in ("true_range", "wall_distance", "neighbor_distance", "neighbor_in_beam", "speed", "range_rate",
                     "incidence", "hit_type", "hit_to_copter"):
        assert required in feats
    for e in js["effects"]:
        # stated / excess: the optional additions of docs/formats/gap-report.md, on pose_noise only
        optional = {"stated", "excess"} if e["name"] == "pose_noise" else set()
        assert set(e) - optional == {"name", "params", "score_heldout", "gap_after_train", "gap_after_heldout",
                                     "shrink_heldout"}
    assert isinstance(rep, GapReport) and js == rep.to_spec() and json.loads(rep.to_json()) == js
    with pytest.raises(KeyError, match="details"):
        rep["per_sensor"]
    assert set(rep.details.per_sensor) == set(rep.details.sensors)


def test_report_writes_the_spec_json_markdown_and_figures(null_logs, tmp_path):
    logs, cfg = null_logs
    rep = diagnose(logs, ["a.npz", "b.npz"], cfg, effect_names=["sonar_bias"])
    paths = rep.write(tmp_path / "r")
    assert json.loads(paths["json"].read_text()) == rep.to_spec()
    assert "# Sim-to-real gap report" in paths["md"].read_text()
    assert paths["gap"].stat().st_size > 1000


def test_single_flight_holds_out_its_second_half(null_logs):
    logs, cfg = null_logs
    d = Diagnosis(logs[:1], ["one.npz"], cfg)
    assert d.train_names == ["one.npz"] and d.heldout_names == ["one.npz"]  # spec: file names
    for s, tab in d.tables.items():
        half = 0.5 * (logs[0].t[-1] - logs[0].t[0])
        assert np.all(tab.seconds[d.rows_fit[s]] < half) and np.all(tab.seconds[d.rows_ho[s]] >= half)


def test_bad_inputs_give_named_errors(null_logs, tmp_path):
    logs, cfg = null_logs
    with pytest.raises(GapInputError, match="--heldout names"):
        Diagnosis(logs, ["a.npz", "b.npz"], cfg, heldout=["c.npz"])
    with pytest.raises(GapInputError, match="every flight"):
        Diagnosis(logs, ["a.npz", "b.npz"], cfg, heldout=["a.npz", "b.npz"])
    bare = flightlog.FlightLog(t=logs[0].t, arena=logs[0].arena, pose=logs[0].pose, copter_ids=logs[0].copter_ids,
                               meta=logs[0].meta)
    with pytest.raises(GapInputError, match="no sensor readings"):
        Diagnosis([bare], ["bare.npz"], cfg)
    with pytest.raises(ConfigError, match=r"unknown key gap\.draw "):
        config_from_dict({"gap": {"draw": 3}})
    with pytest.raises(ConfigError, match=r"gap\.draws = 2"):
        config_from_dict({"gap": {"draws": 2}})
    with pytest.raises(GapInputError, match="unknown effects"):
        run_diagnosis(Diagnosis(logs, ["a.npz", "b.npz"], cfg), ["wall_bulg"])


def test_cli_gap_end_to_end_and_errors(null_logs, tmp_path, capsys):
    logs, cfg = null_logs
    paths = []
    for i, log in enumerate(logs):
        p = tmp_path / f"flight{i}.npz"
        flightlog.save(log, p)
        paths.append(str(p))
    conf = tmp_path / "sim.toml"
    conf.write_text('[walls]\nbending = false\n[sonar]\ncrosstalk = "off"\n[gap]\ndraws = 12\n'
                    'max_samples_per_flight = 300\nfit_max_readings = 5000\nn_boot = 200\neffects = ["sonar_bias", "imu_bias"]\n')
    out = tmp_path / "gap"
    assert main(["gap", *paths, "--config", str(conf), "--out", str(out), "--no-progress"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["verdict"]["significant_gap"] is False
    assert {e["name"] for e in rep["effects"]} == {"sonar_bias", "imu_bias"}
    assert (out / "report.md").exists() and (out / "gap_by_condition.png").exists()
    # malformed log: the flight-log validator's message, exit code 2
    bad = tmp_path / "bad.npz"
    np.savez(bad, format=np.array("finkensim-flightlog/1"), t=np.array([0.0, 0.0]))
    capsys.readouterr()
    assert main(["gap", str(bad), "--out", str(out)]) == 2
    assert "finkensim gap: error:" in capsys.readouterr().err
    assert main(["gap", str(tmp_path / "missing.npz")]) == 2
    bad_conf = tmp_path / "bad.toml"
    bad_conf.write_text("[gap]\ndraws = 2\n")
    capsys.readouterr()
    assert main(["gap", *paths, "--config", str(bad_conf)]) == 2
    assert "gap.draws = 2" in capsys.readouterr().err
    assert main(["gap", *paths, "--config", str(conf), "--heldout", "nope.npz", "--out", str(out)]) == 2



def test_gap_command_lets_idle_openmp_threads_sleep_unless_the_user_chose(tmp_path, monkeypatch):
    """`finkensim gap` asks OpenMP for the passive wait policy (idle threads sleep instead of spinning: the same
    speed on a quiet machine, much faster on a shared one) before its first parallel kernel; a user's own setting
    stays. (The policy changes no result: every parallel loop of the diagnosis is per element.)"""
    missing = str(tmp_path / "missing.npz")
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    assert main(["gap", missing]) == 2
    assert os.environ["OMP_WAIT_POLICY"] == "passive"
    monkeypatch.setenv("OMP_WAIT_POLICY", "active")
    assert main(["gap", missing]) == 2
    assert os.environ["OMP_WAIT_POLICY"] == "active"

def test_every_model_parameter_belongs_to_exactly_one_sensor_for_score_caching():
    from dataclasses import fields

    from finkensim.gap.model.params import SENSOR_FIELDS, SHARED_FIELDS, ModelParams

    for f in fields(ModelParams):
        owners = [s for s, names in SENSOR_FIELDS.items() if f.name in names]
        assert (f.name in SHARED_FIELDS) != (len(owners) == 1), f"ModelParams.{f.name} maps to {owners}"
    base = ModelParams.from_config(Config())
    for sensor in SENSOR_FIELDS:
        hash(base.sensor_key(sensor))
        assert base.sensor_key(sensor) == ModelParams.from_config(Config()).sensor_key(sensor) or sensor == "ranging"
    assert base.with_sonar(bias=0.1).sensor_key("ultrasonic") != base.sensor_key("ultrasonic")
    assert base.with_sonar(bias=0.1).sensor_key("imu") == base.sensor_key("imu")


@pytest.mark.parametrize("baseline", [0.0, 0.2])
def test_imu_table_equals_the_pose_derived_ideal_on_a_noise_free_flight(baseline):
    """With no IMU noise and no tracking noise, each window integral of the logged IMU (trapezoid weights
    for the accelerometer) equals the Δ of mean velocities over the baseline computed from the poses: the two
    sides of the IMU comparison describe the same quantity, whatever the baseline."""
    from finkensim.config import load_config
    from finkensim.gap.diagnosis import Diagnosis
    from finkensim.scenario import simulate_flight
    cfg = load_config().replace({"copters.n": 3, "imu.acc_noise_density": 0.0, "imu.acc_bias_walk": 0.0,
                                 "imu.gyro_noise_density": 0.0, "imu.gyro_bias_walk": 0.0,
                                 "gap.imu_velocity_baseline": baseline, "gap.draws": 4,
                                 "gap.max_samples_per_flight": 200})
    logs = [simulate_flight(cfg, duration=8.0, seed=s)[0] for s in (3, 4)]
    diag = Diagnosis(logs, ["a.npz", "b.npz"], cfg)
    tab = diag.tables["imu"]
    assert tab.baseline == (1 if baseline == 0 else round(baseline / cfg.simulation.dt))
    rows = np.arange(tab.n)
    D, _ = tab.draws(diag.flights, diag.base.with_(sigma_xy=0.0, sigma_yaw=0.0), rows, diag.seed, 4)
    ok = np.isfinite(tab.y)
    assert ok.mean() > 0.99
    np.testing.assert_allclose(D[ok], np.broadcast_to(tab.y[ok, None], D[ok].shape), atol=1e-9)


class _FixedOverall:
    """A stand-in for Diagnosis.overall returning a preset (mean, ci, one-sided p) per sensor."""

    def __init__(self, values):
        self.values = values

    def overall(self, values, rows):
        (s,) = values
        return self.values[s]


def test_a_remaining_gap_is_significant_on_either_side_and_when_its_power_is_unknown():
    from finkensim.gap.detect.significance import sensor_gaps

    cfg = Config().gap
    diag = _FixedOverall({
        "ultrasonic": (0.2, (0.1, 0.3), 1e-6),        # clearly left over
        "ranging": (0.01, (-0.02, 0.04), 0.3),         # cannot be told from zero
        "imu": (-0.2, (-0.3, -0.1), 1.0 - 1e-6),       # predictive too wide: not an explanation either
        "other": (0.2, (math.nan, math.nan), math.nan),  # too few blocks to tell
    })
    out = sensor_gaps(diag, {s: None for s in diag.values}, {s: None for s in diag.values},
                       list(diag.values), 4, cfg, remainder=True)
    assert out["ultrasonic"]["significant"] and out["imu"]["significant"] and out["other"]["significant"]
    assert not out["ranging"]["significant"]
    assert out["ranging"]["p"] == pytest.approx(0.6)
    assert out["imu"]["p"] == pytest.approx(2e-6)


def test_the_configured_models_gap_is_tested_one_sided_and_unknown_power_is_no_gap():
    from finkensim.gap.detect.significance import sensor_gaps

    cfg = Config().gap
    diag = _FixedOverall({"ultrasonic": (0.2, (0.1, 0.3), 1e-6), "imu": (-0.2, (-0.3, -0.1), 1.0 - 1e-6),
                          "other": (0.2, (math.nan, math.nan), math.nan)})
    out = sensor_gaps(diag, {s: None for s in diag.values}, {s: None for s in diag.values}, list(diag.values), 3, cfg)
    assert out["ultrasonic"]["significant"]
    assert not out["imu"]["significant"] and not out["other"]["significant"]
    assert out["imu"]["p"] == 1.0 - 1e-6


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 6), st.integers(1, 4), st.integers(1, 5), st.integers(1, 8), st.integers(1, 24), st.integers(0, 10**6))
def test_gather_draws_equals_fancy_indexing(K, N, X, G, M, seed):
    from finkensim.gap.model.predictive import gather_draws

    rng = np.random.default_rng(seed)
    a = rng.normal(size=(K, N, X, G))
    n_rows = int(rng.integers(1, 30))
    sel = np.sort(rng.choice(n_rows, size=int(rng.integers(1, n_rows + 1)), replace=False)).astype(np.int64)
    pos, cop, ch = (rng.integers(0, k, size=sel.size).astype(np.int64) for k in (K, N, X))
    out = np.full((n_rows, M), np.nan)
    gather_draws(a, sel, pos, cop, ch, out)
    ref = np.full((n_rows, M), np.nan)
    ref[sel] = a[pos, cop, ch][:, np.arange(M) % G]
    np.testing.assert_array_equal(out, ref)
    kinds = rng.integers(0, 3, size=(K, N, X, G)).astype(np.int8)
    out8 = np.zeros((n_rows, M), np.int8)
    gather_draws(kinds, sel, pos, cop, ch, out8)
    np.testing.assert_array_equal(out8[sel], kinds[pos, cop, ch][:, np.arange(M) % G])
