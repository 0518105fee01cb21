"""Virtual ranging sensor: rules, numba == NumPy reference, statistics of the mixture sampler."""
from __future__ import annotations

import json
from pathlib import Path

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats

from finkensim.config import ConfigError, RangingConfig
from finkensim.sensors.mixture import Mixture, MixtureError
from finkensim.sensors.ranging import RangingModel, ideal_ranges, ranging_readings
from finkensim.sensors.ranging_table import ResponsibilityTable
from finkensim.sensors.ranging_kernels import ranging_env, row_key
from finkensim.sensors.ranging_table import build_alias
from tests.stats import (
    assert_mean_within_se,
    assert_proportion_within_se,
    assert_std_within_se,
    assert_within_se,
    se_std_normal,
)
from tests.naive.ranging import (
    naive_build_alias,
    naive_pick_components,
    naive_ranging_readings,
    naive_sample,
)

SHARED_JSON = Path(__file__).resolve().parents[2] / "shared" / "data" / "vranging_gmm.json"
MODES = ("mixture", "seed", "gaussian", "none")


@pytest.fixture(scope="module")
def models():
    return {mode: RangingModel(mode) for mode in MODES}


@pytest.fixture(scope="module")
def mix():
    return Mixture.default()


def _random_positions(rng, b, n, size=3.0):
    return rng.uniform(0.0, size, (b, n, 2))


# ---------------------------------------------------------------- rules: shapes, self, out of range


@pytest.mark.parametrize("mode", MODES)
def test_shapes_self_and_beacon_columns(models, mode):
    rng = np.random.default_rng(1)
    pos = _random_positions(rng, 3, 4, size=1.5)
    beacons = np.array([[0.2, 0.3], [1.0, 1.4]])
    out = ranging_readings(pos, beacons, 7, np.arange(3), 5, models[mode])
    assert out.shape == (3, 4, 6) and out.dtype == np.float64
    for b in range(3):
        assert np.all(np.diag(out[b, :, :4]) == 0.0)
    assert np.all(out >= 0.0)
    true = ideal_ranges(pos, beacons, 2.5)
    assert true.shape == (3, 4, 6)
    expect = np.sqrt(((pos[:, :, None, :] - beacons[None, None]) ** 2).sum(-1))
    np.testing.assert_allclose(true[:, :, 4:], np.minimum(expect, 2.5), rtol=0, atol=1e-15)
    if mode == "none":
        np.testing.assert_array_equal(out, true)
    else:  # each in-range reading scatters around its model mean: standardised errors average 0 within 5 SE, over
        # 2 000 environments (≈ 20 000 readings between 0.5 and 2 m, clear of the clips at 0 and 2.5 m): 5 SE ≈ 0.035,
        # so a bias of 3.5 % of the reading's standard deviation (≈ 6 mm for the mixture) fails
        pos = _random_positions(rng, 2000, 4, size=1.5)
        true = ideal_ranges(pos, beacons, 2.5)
        out = ranging_readings(pos, beacons, 7, np.arange(2000), 5, models[mode])
        x = true[(true > 0.5) & (true < 2.0)]
        y = out[(true > 0.5) & (true < 2.0)]
        if mode == "gaussian":
            m, sd = x, np.full(x.size, models[mode].sigma)
        elif mode == "mixture":
            m, sd = Mixture.default().conditional_mean_std(x)
        else:
            m, sd = Mixture.default().seed_mean_std(x, 10.0)
        z = (y - m) / sd  # standardised: SE of the mean 1/√n (a 0.3 m bias is ≈ 1.8 per reading)
        assert_mean_within_se(z, 0.0, se=1 / np.sqrt(z.size), what=f"{mode}: mean standardised ranging error")


@pytest.mark.parametrize("mode", MODES)
def test_out_of_range_reads_exactly_max_range(models, mode):
    # copters on a 3 m grid: every pair is > 2.5 m apart; one beacon far away, one near copter 0
    pos = np.array([[[0.0, 0.0], [3.0, 0.0], [0.0, 3.0], [3.0, 3.0]]])
    beacons = np.array([[10.0, 10.0], [0.4, 0.0]])
    out = ranging_readings(pos, beacons, 3, np.array([0]), 0, models[mode])
    mask = ~np.eye(4, 6, dtype=bool)
    mask[0, 5] = False  # copter 0 -> near beacon is in range
    assert np.all(out[0][mask] == 2.5)
    assert out[0, 0, 5] != 2.5 or mode == "none"
    # custom max_range
    model = RangingModel(mode, max_range=1.2)
    pos2 = np.array([[[0.0, 0.0], [1.3, 0.0], [0.0, 1.0]]])
    out2 = ranging_readings(pos2, (), 3, np.array([0]), 0, model)
    assert out2[0, 0, 1] == 1.2 and out2[0, 1, 0] == 1.2 and out2[0, 1, 2] == 1.2


def test_negative_draws_are_clipped_to_zero():
    model = RangingModel("gaussian", sigma=1.0)
    y = model.sample(np.full(10_000, 0.1), seed=2)
    assert np.all(y >= 0.0)
    p = stats.norm.cdf(0.0, loc=0.1, scale=1.0)  # P(N(0.1, 1) < 0) = 0.4602
    # SE √(p(1−p)/n) = 0.005, 5 SE = 0.025 (5.4 % of p): a bias of about 5 % in the clip share fails
    assert_proportion_within_se(y == 0.0, p, what="share of draws clipped to 0")


def test_ideal_flag_and_symmetry(models):
    rng = np.random.default_rng(2)
    pos = _random_positions(rng, 2, 5)
    ideal = ranging_readings(pos, [[1.0, 1.0]], 0, np.arange(2), 0, models["mixture"], ideal=True)
    np.testing.assert_array_equal(ideal, ideal_ranges(pos, [[1.0, 1.0]]))
    np.testing.assert_array_equal(ideal[:, :, :5], np.swapaxes(ideal[:, :, :5], 1, 2))
    assert ideal.max() <= 2.5


def test_i_to_j_and_j_to_i_are_independent(models):
    n = 20_000
    pos = np.tile(np.array([[[0.0, 0.0], [1.0, 0.0]]]), (n, 1, 1))
    out = ranging_readings(pos, (), 11, np.arange(n), 3, models["mixture"])
    a, b = out[:, 0, 1], out[:, 1, 0]
    assert np.mean(a == b) < 0.01  # a guard against one shared draw (it would give 1), not an estimate
    # under independence the sample correlation has SE 1/√n = 0.007: 5 SE = 0.035 catches a correlation of 0.035
    assert_within_se(np.corrcoef(a, b)[0, 1], 0.0, 1 / np.sqrt(n), what="correlation of i→j and j→i readings")


def test_input_errors(models):
    with pytest.raises(ValueError, match="positions"):
        ranging_readings(np.zeros((2, 3)), (), 0, [0], 0, models["none"])
    with pytest.raises(ValueError, match="env_ids"):
        ranging_readings(np.zeros((2, 3, 2)), (), 0, [0], 0, models["none"])
    with pytest.raises(ValueError, match="beacons"):
        ranging_readings(np.zeros((1, 3, 2)), [1.0, 2.0, 3.0], 0, [0], 0, models["none"])
    with pytest.raises(ValueError, match="ranging.error"):
        RangingModel("gauss")
    # the array checks of finkensim.arrays: ConfigError (a ValueError) naming the array
    with pytest.raises(ConfigError, match=r"positions\[0, 1, 0\] = .*nan"):
        ranging_readings(np.array([[[0.0, 0.0], [np.nan, 0.0]]]), (), 0, [0], 0, models["none"])
    with pytest.raises(ConfigError, match=r"out is a float64 array of shape \(1, 3, 2\): expected .* \(1, 3, 3\)"):
        ranging_readings(np.zeros((1, 3, 2)), (), 0, [0], 0, models["none"], out=np.empty((1, 3, 2)))
    with pytest.raises(ConfigError, match=r"env_ids = \[0.5\]: expected integers"):
        ranging_readings(np.zeros((1, 3, 2)), (), 0, [0.5], 0, models["none"])
    with pytest.raises(ConfigError, match=r"x \(flattened\)\[1\] = -0.1"):
        models["none"].sample([0.5, -0.1])


# ---------------------------------------------------------------- numba == NumPy reference


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    mode=st.sampled_from(MODES),
    b=st.integers(1, 3),
    n=st.integers(1, 5),
    m=st.integers(0, 2),
    seed=st.integers(0, 2**63 - 1),
    step=st.integers(0, 10**6),
    env0=st.integers(0, 10**6),
    data_seed=st.integers(0, 2**32 - 1),
)
def test_kernel_equals_numpy_reference(models, mode, b, n, m, seed, step, env0, data_seed):
    rng = np.random.default_rng(data_seed)
    pos = rng.uniform(-0.5, 3.0, (b, n, 2))
    beacons = rng.uniform(-0.5, 3.0, (m, 2))
    env_ids = env0 + np.arange(b) * 7
    got = ranging_readings(pos, beacons, seed, env_ids, step, models[mode])
    want = naive_ranging_readings(pos, beacons, seed, env_ids, step, models[mode])
    if mode == "seed":  # exp/log of the reference may differ from the kernel's by an ulp
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    else:
        np.testing.assert_array_equal(got, want)
    ideal = ranging_readings(pos, beacons, seed, env_ids, step, models[mode], ideal=True)
    np.testing.assert_array_equal(ideal, naive_ranging_readings(pos, beacons, seed, env_ids, step,
                                                                models[mode], ideal=True))


@pytest.mark.parametrize("mode", MODES)
def test_sample_equals_reference_at_grid_edges(models, mode):
    model = models[mode]
    h = model.table.h if model.table is not None else 0.01
    xs = np.concatenate([
        np.arange(0, 50) * h,                    # exactly on nodes
        (np.arange(0, 50) + 0.5) * h,            # midway
        [0.0, 1e-12, 2.5 - 1e-12, 2.5, 2.5 + 1e-12, 3.0],
        np.random.default_rng(3).uniform(0, 2.6, 200),
    ])
    got = model.sample(xs, seed=99, env=4, step=5, copter=2)
    want = naive_sample(model, xs, seed=99, env=4, step=5, copter=2)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.all(got[xs > 2.5] == 2.5)


@pytest.mark.parametrize("mode", MODES)
def test_ranging_env_equals_reference(models, mode):
    """The per-environment kernel called on its own (the batched kernel and compiled loops inline it)."""
    rng = np.random.default_rng(12)
    pos = rng.uniform(-0.5, 3.0, (1, 5, 2))
    beacons = rng.uniform(0.0, 3.0, (2, 2))
    out = np.full((5, 7), np.nan)
    ranging_env(pos[0], np.zeros(5), beacons, np.int64(21), np.int64(9), np.int64(4), models[mode].params, out)
    want = naive_ranging_readings(pos, beacons, 21, [9], 4, models[mode])[0]
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-12 if mode == "seed" else 0)


def test_build_alias_equals_reference(models):
    table = models["mixture"].table
    rows = np.linspace(0.0, 2.5, 37)
    p = models["mixture"].mixture.responsibilities(rows)
    rng = np.random.default_rng(13)
    q = rng.dirichlet(np.full(7, 0.3), 50)
    q[0] = 0.0
    q[0, 3] = 1.0  # a point mass
    q[1] = 1.0 / 7  # uniform: every column is its own alias
    for dist in (p, q):
        prob = np.empty(dist.shape)
        alias = np.empty(dist.shape, dtype=np.int32)
        build_alias(dist, prob, alias)
        want_prob, want_alias = naive_build_alias(dist)
        np.testing.assert_array_equal(prob, want_prob)
        np.testing.assert_array_equal(alias, want_alias)
    # the model's table holds exactly these tables at its nodes
    want_prob, want_alias = naive_build_alias(table.mixture.responsibilities(np.linspace(0.0, 2.5, table.n_nodes)))
    np.testing.assert_array_equal(table.prob, want_prob)
    np.testing.assert_array_equal(table.alias, want_alias)


def test_pick_components_equals_reference(models):
    table = models["mixture"].table
    xs = np.concatenate([np.arange(40) * table.h, (np.arange(40) + 0.5) * table.h, [2.5 - 1e-12, 2.5],
                         np.random.default_rng(14).uniform(0.0, 2.5, 300)])
    got = table.sample_components(xs, seed=5, env=6, step=7, copter=8)
    np.testing.assert_array_equal(got, naive_pick_components(table, xs, seed=5, env=6, step=7, copter=8))
    assert row_key(5, 6, 7, 8) != row_key(5, 6, 7, 9)
    for bad in ([0.5, -0.5], [0.5, np.nan], [0.5, 2.6]):
        with pytest.raises(ConfigError, match=r"x\[1\] = .*expected true distances in \[0, 2.5\] m"):
            table.sample_components(bad)


# ---------------------------------------------------------------- reproducibility


@pytest.mark.parametrize("mode", ["mixture", "seed"])
def test_batch_equals_single_environment_runs(models, mode):
    rng = np.random.default_rng(4)
    pos = _random_positions(rng, 64, 6)
    beacons = np.array([[0.5, 0.5], [2.0, 2.5]])
    env_ids = 1000 + np.arange(64)
    batch = ranging_readings(pos, beacons, 123, env_ids, 17, models[mode])
    for k in (0, 1, 17, 40, 63):
        single = ranging_readings(pos[k:k + 1], beacons, 123, np.array([1000 + k]), 17, models[mode])
        np.testing.assert_array_equal(single[0], batch[k])
    # and not on the thread count
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        serial = ranging_readings(pos, beacons, 123, env_ids, 17, models[mode])
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(serial, batch)
    # different step or seed -> different readings
    other = ranging_readings(pos, beacons, 123, env_ids, 18, models[mode])
    assert np.mean(other != batch) > 0.5


# ---------------------------------------------------------------- statistics of the samplers


@pytest.mark.parametrize("x", [0.3, 1.0, 1.7, 2.3])
def test_mixture_samples_match_analytic_conditional_cdf(models, mix, x):
    y = models["mixture"].sample(np.full(20_000, x), seed=int(x * 1000))
    res = stats.kstest(y, lambda v: mix.conditional_cdf(v, x, clip_at_zero=True))
    assert res.pvalue > 1e-3, (x, res)
    # the near-atoms of the 8 degenerate components are there (e.g. 1.70 m -> atoms at 1.52/1.54 m): the share of
    # draws within 2 mm of them is the conditional law's mass there, 0.149; with 200 000 draws its SE is 0.0008,
    # 5 SE = 0.004 (2.7 % of it): a few-percent bias in the atoms' weight fails
    if x == 1.7:
        atoms = np.array([1.48, 1.52, 1.54, 2.12, 2.16])
        p = sum(mix.conditional_cdf(np.array([a + 0.002]), x, clip_at_zero=True)[0]
                - mix.conditional_cdf(np.array([a - 0.002]), x, clip_at_zero=True)[0] for a in atoms)
        assert p > 0.08
        y2 = models["mixture"].sample(np.full(200_000, x), seed=17)
        near_atom = np.abs(y2[:, None] - atoms).min(axis=1) < 0.002
        assert_proportion_within_se(near_atom, p, what="share of draws within 2 mm of the atoms at 1.7 m")


def test_mixture_mean_std_at_one_metre(models, mix):
    """400 000 draws: SE of the mean 0.00027 m, of the std 0.0003 m (from the sample); 5 SE is 0.13 % of the mean
    and ≈ 0.8 % of the std (plus the table's 1e-3 m error bound on the std)."""
    y = models["mixture"].sample(np.full(400_000, 1.0), seed=5)
    am, asd = mix.conditional_mean_std(1.0)
    assert_mean_within_se(y, am, what="mixture reading mean at 1 m")
    assert_std_within_se(y, asd, ddof=0, slack=1e-3, what="mixture reading std at 1 m")  # slack: table error bound
    assert abs(am - 1.011) < 0.001 and abs(asd - 0.170) < 0.002  # DESIGN.md: 1.011 +- 0.170 m
    # against the documented three-decimal figures: 5 SE, plus their rounding (0.0005 m) and for the std the table
    # error bound (1e-3 m)
    assert_mean_within_se(y, 1.011, slack=0.0005, what="mixture reading mean at 1 m vs DESIGN.md's 1.011 m")
    assert_std_within_se(y, 0.170, ddof=0, slack=0.0015, what="mixture reading std at 1 m vs DESIGN.md's 0.170 m")


def test_seed_mode_mean_std_at_one_metre(models, mix):
    """200 000 draws: SE of the mean 0.0002 m, of the std 0.00014 m (from the sample); 5 SE is 0.1 % of the mean
    and 0.8 % of the std."""
    y = models["seed"].sample(np.full(200_000, 1.0), seed=6)
    am, asd = mix.seed_mean_std(1.0, 10.0)
    assert_mean_within_se(y, am, what="seed-mode reading mean at 1 m")
    se_s = assert_std_within_se(y, asd, ddof=0, what="seed-mode reading std at 1 m")
    assert abs(am - 1.011) < 0.001 and abs(asd - 0.084) < 0.001  # shared/data/README.md
    # the script's averaging is narrower than the correct mixture: by more than 5 SE of the sample std
    assert y.std() < 0.6 * mix.conditional_mean_std(1.0)[1] - 5 * se_s


def test_gaussian_mode_statistics():
    """100 000 draws of N(1.2, 0.05²): SE of the mean σ/√n = 0.00016 m, of the std σ/√(2(n−1)) = 0.00011 m; 5 SE
    is 0.07 % of the mean and 1.1 % of σ."""
    y = RangingModel("gaussian", sigma=0.05).sample(np.full(100_000, 1.2), seed=7)
    assert_mean_within_se(y, 1.2, se=0.05 / np.sqrt(y.size), what="gaussian-mode reading mean")
    assert_std_within_se(y, 0.05, se=se_std_normal(0.05, y.size), what="gaussian-mode reading std")


# ---------------------------------------------------------------- the responsibility table


def test_table_error_bound(models, mix):
    table = models["mixture"].table
    assert table.max_tv_error < 1e-4 < 1e-3
    assert table.tv_check_points >= 16 * (table.n_nodes - 1)
    xs = np.random.default_rng(8).uniform(0.0, 2.5, 20_000)
    assert table.tv_error(xs).max() <= table.max_tv_error * 1.2
    # at the nodes the table is exact up to the alias tables' rounding
    nodes = np.arange(table.n_nodes) * table.h
    assert table.tv_error(nodes).max() < 1e-12
    # a coarser tolerance gives a coarser grid, still within its bound
    coarse = ResponsibilityTable.build(mix, 2.5, tol=1e-3)
    assert coarse.n_nodes < table.n_nodes and coarse.max_tv_error <= 1e-3


@pytest.mark.parametrize("x", [0.2947, 1.0, 2.2])
def test_table_component_draws_follow_responsibilities(models, mix, x):
    table = models["mixture"].table
    n = 200_000
    comp = table.sample_components(np.full(n, x), seed=9)
    counts = np.bincount(comp, minlength=mix.n_components)
    p = mix.responsibilities(x)
    assert counts[p == 0].sum() == 0
    big = p * n >= 5  # chi-square over the well-populated components, the rest lumped together
    obs = np.append(counts[big], counts[~big].sum()).astype(float)
    exp = np.append(p[big], p[~big].sum()) * n
    if exp[-1] < 5:  # too rare to lump: test the conditional law of the populated components
        obs, exp = obs[:-1], exp[:-1]
    res = stats.chisquare(obs, exp * obs.sum() / exp.sum())
    assert res.pvalue > 1e-3, res
    assert 0.5 * np.abs(table.component_distribution(x) - p).sum() <= table.max_tv_error


# ---------------------------------------------------------------- Mixture: files, fit, full covariance


def test_default_mixture_is_parlows_model_in_metres(mix):
    assert mix.n_components == 100 and mix.is_diagonal
    assert abs(mix.weights.sum() - 1) < 1e-9
    assert np.sum(np.isclose(mix.cond_covar, 1e-7, rtol=1e-6)) == 8
    assert 0.22 < mix.mean.min() < 0.23 and 3.31 < mix.mean.max() < 3.32
    assert mix.source["blob"] == "e5905cc0e75ae2b3730a725038f66ca75f82e27e"
    if SHARED_JSON.exists():  # the cm file converts to the same numbers
        cm = Mixture.load(SHARED_JSON)
        for name in ("weights", "mean", "covar", "cond_mean", "cond_covar"):
            np.testing.assert_allclose(getattr(cm, name), getattr(mix, name), rtol=1e-14)


def _write(tmp_path, data, name="m.json"):
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def _good_dict():
    return {"weights": [0.5, 0.5], "mean": [1.0, 2.0], "covar": [0.01, 0.02],
            "cond_mean": [1.0, 2.1], "cond_covar": [0.001, 0.002]}


@pytest.mark.parametrize("change, name", [
    ({"cond_mean": [1.0, 2.0, 3.0]}, "cond_mean"),
    ({"covar": [[0.01, 0.02]]}, "covar"),
    ({"covar": [0.01, -0.02]}, "covar"),
    ({"cond_covar": [0.0, 0.01]}, "cond_covar"),
    ({"weights": [0.5, 0.6]}, "weights"),
    ({"weights": [1.5, -0.5]}, "weights"),
    ({"mean": [1.0, float("nan")]}, "mean"),
    ({"cond_mean": None}, "cond_mean"),
])
def test_load_errors_name_the_array(tmp_path, change, name):
    data = _good_dict()
    for key, value in change.items():
        if value is None:
            del data[key]
        else:
            data[key] = value
    with pytest.raises(MixtureError, match=f"'{name}'"):
        Mixture.load(_write(tmp_path, data))


def test_load_errors_files(tmp_path):
    with pytest.raises(MixtureError, match="does not exist"):
        Mixture.load(tmp_path / "nope.json")
    bad = tmp_path / "m.txt"
    bad.write_text("x")
    with pytest.raises(MixtureError, match="unknown format"):
        Mixture.load(bad)
    (tmp_path / "b.json").write_text("{not json")
    with pytest.raises(MixtureError, match="invalid JSON"):
        Mixture.load(tmp_path / "b.json")
    npz = tmp_path / "m.npz"
    np.savez(npz, weights=[1.0], mean=[1.0], covar=[0.1], cond_mean=[1.0])
    with pytest.raises(MixtureError, match="'cond_covar' is missing"):
        Mixture.load(npz)


def test_save_load_roundtrip_and_units(tmp_path, mix):
    for suffix in (".json", ".npz"):
        path = tmp_path / f"mix{suffix}"
        mix.save(path)
        back = Mixture.load(path)
        for name in ("weights", "mean", "covar", "cond_mean", "cond_covar", "slope"):
            np.testing.assert_array_equal(getattr(back, name), getattr(mix, name))
    data = _good_dict()
    data["units"] = {"distance": "cm", "variance": "cm^2"}
    cm = Mixture.load(_write(tmp_path, data))
    np.testing.assert_allclose(cm.mean, [0.01, 0.02])
    np.testing.assert_allclose(cm.covar, [1e-6, 2e-6])


def test_mixture_file_from_config(tmp_path):
    data = _good_dict()
    path = _write(tmp_path, data)
    cfg = RangingConfig(error="mixture", mixture_file=str(path), beacons=((1.0, 2.0),))
    model = RangingModel.from_config(cfg)
    assert model.mixture.n_components == 2 and model.beacons.shape == (1, 2)
    y = model.sample(np.full(20_000, 1.0), seed=1)  # SE of the mean ≈ 0.0003 m (from the sample): 5 SE ≈ 0.15 %
    assert_mean_within_se(y, model.mixture.conditional_mean_std(1.0)[0], what="reading mean of a file's mixture")
    seed_model = RangingModel.from_config(RangingConfig(error="seed"))
    assert seed_model.error == "seed" and seed_model.table is None
    # a RangingConfig is accepted as params
    pos = np.array([[[0.0, 0.0], [1.0, 0.0]]])
    out = ranging_readings(pos, (), 0, [0], 0, RangingConfig(error="none"))
    np.testing.assert_array_equal(out[0], [[0.0, 1.0], [1.0, 0.0]])


def test_fit_recovers_two_components():
    """Two well-separated components (≥ 6 σ apart), so the fit's estimates have the SEs of the per-component
    sample statistics: weight √(p(1−p)/n), mean σ/√n_k, std σ/√(2 n_k). With n = 60 000, 5 SE is 3.1 % of the
    0.3 weight, ≤ 1 % of a mean and ≤ 4.6 % of a std: a few-percent bias in any parameter fails."""
    rng = np.random.default_rng(10)
    n = 60_000
    comp = rng.random(n) < 0.3
    x = np.where(comp, rng.normal(0.5, 0.1, n), rng.normal(1.8, 0.2, n))
    y = np.where(comp, rng.normal(0.6, 0.05, n), rng.normal(1.7, 0.1, n))
    fit = Mixture.fit(x, y, 2, "diag", seed=0)
    order = np.argsort(fit.mean)
    n_k = np.array([comp.sum(), (~comp).sum()])
    for k, (w, mx, sx, my, sy) in enumerate([(0.3, 0.5, 0.1, 0.6, 0.05), (0.7, 1.8, 0.2, 1.7, 0.1)]):
        j = order[k]
        assert_within_se(fit.weights[j], w, np.sqrt(w * (1 - w) / n), what=f"fitted weight {k}")
        assert_within_se(fit.mean[j], mx, sx / np.sqrt(n_k[k]), what=f"fitted mean of x, component {k}")
        assert_within_se(fit.cond_mean[j], my, sy / np.sqrt(n_k[k]), what=f"fitted mean of y, component {k}")
        assert_within_se(np.sqrt(fit.covar[j]), sx, se_std_normal(sx, n_k[k]),
                         what=f"fitted std of x, component {k}")
        assert_within_se(np.sqrt(fit.cond_covar[j]), sy, se_std_normal(sy, n_k[k]),
                         what=f"fitted std of y, component {k}")
    assert fit.is_diagonal
    with pytest.raises(ValueError, match="covariance_type"):
        Mixture.fit(x, y, 2, "tied")


def test_full_covariance_conditional_mean_depends_on_x():
    cov = np.array([[[0.04, 0.03], [0.03, 0.05]]])
    one = Mixture.from_joint([1.0], [[1.0, 1.1]], cov)
    np.testing.assert_allclose(one.slope, [0.75])
    np.testing.assert_allclose(one.cond_covar, [0.05 - 0.03**2 / 0.04])
    xs = np.array([0.5, 1.0, 1.5])
    m, s = one.conditional_mean_std(xs)
    np.testing.assert_allclose(m, 1.1 + 0.75 * (xs - 1.0))
    np.testing.assert_allclose(s, np.sqrt(0.0275))
    model = RangingModel("mixture", mixture=one)
    for x in xs:  # SE of the mean √(0.0275/n) = 0.0012 m: 5 SE is ≤ 0.8 % of the conditional mean
        y = model.sample(np.full(20_000, x), seed=3)
        assert_mean_within_se(y, 1.1 + 0.75 * (x - 1.0), se=np.sqrt(0.0275 / y.size),
                              what=f"reading mean at x = {x} (full covariance)")
    # two components: E[Y | X] = sum_i r_i(X) (m_i + s_i (X - mu_i))
    two = Mixture.from_joint([0.4, 0.6], [[0.8, 0.9], [1.6, 1.5]],
                             [[[0.02, 0.01], [0.01, 0.02]], [[0.05, -0.02], [-0.02, 0.03]]])
    r = two.responsibilities(xs)
    want = (r * (two.cond_mean + two.slope * (xs[:, None] - two.mean))).sum(axis=1)
    np.testing.assert_allclose(two.conditional_mean_std(xs)[0], want)
    np.testing.assert_allclose(two.slope, [0.5, -0.4])
    # a full fit on correlated data recovers the slope: SE of a regression slope √(σ²_res / (n σ²_x)) = 0.0037 for
    # n = 50 000, 5 SE = 0.019 (2.5 % of 0.75)
    rng = np.random.default_rng(11)
    n = 50_000
    xy = rng.multivariate_normal([1.0, 1.1], cov[0], n)
    fit = Mixture.fit(xy[:, 0], xy[:, 1], 1, "full")
    assert_within_se(fit.slope[0], 0.75, np.sqrt(0.0275 / (n * 0.04)), what="fitted slope of y on x")
    with pytest.raises(MixtureError, match="positive definite"):
        Mixture.from_joint([1.0], [[1.0, 1.0]], [[[0.01, 0.02], [0.02, 0.01]]])


def test_conditional_pdf_integrates_to_cdf(mix):
    ys = np.linspace(-0.5, 4.0, 60_001)
    for x in (0.5, 1.7):
        pdf = mix.conditional_pdf(ys, x)
        cdf = mix.conditional_cdf(ys, x)
        integral = np.concatenate([[0.0], np.cumsum(0.5 * (pdf[1:] + pdf[:-1]) * np.diff(ys))])
        assert abs(integral[-1] - 1.0) < 1e-3
        assert np.abs(integral - cdf).max() < 2e-3
    r = mix.responsibilities(np.array([[0.3, 1.0], [1.5, 2.4]]))
    assert r.shape == (2, 2, 100)
    np.testing.assert_allclose(r.sum(-1), 1.0)


# ---------------------------------------------------------------- known answers straight from the data file

def _conditional_from_json(x):
    """(weights (K,), means (K,), stds (K,)) of the reading given true distance x (m), computed with scipy straight
    from finkensim/data/vranging_gmm_m.json — not through Mixture: component k's weight is w_k·N(x; mean_k, covar_k)
    normalised, and the reading within it is N(cond_mean_k, cond_covar_k) (diagonal covariances: no slope)."""
    import json
    from pathlib import Path

    import finkensim

    d = json.loads((Path(finkensim.__file__).parent / "data" / "vranging_gmm_m.json").read_text())
    w = np.asarray(d["weights"]) * stats.norm.pdf(x, np.asarray(d["mean"]), np.sqrt(np.asarray(d["covar"])))
    return w / w.sum(), np.asarray(d["cond_mean"]), np.sqrt(np.asarray(d["cond_covar"]))


@pytest.mark.parametrize("x", [0.5, 1.2, 2.0])
def test_sampler_matches_the_mixture_computed_from_the_json(models, x):
    """KS of the kernel's draws against the conditional CDF Σ r_k Φ((y − μ_k)/σ_k) (clipped at 0) from the JSON with
    scipy, and its mean/std against the closed-form moments within 5 standard errors."""
    r, mu, sd = _conditional_from_json(x)
    y = models["mixture"].sample(np.full(40_000, x), seed=11 + int(100 * x))

    def cdf(v):
        v = np.atleast_1d(v)
        c = (r * stats.norm.cdf((v[:, None] - mu) / sd)).sum(axis=1)
        return np.where(v < 0, 0.0, c)

    assert stats.kstest(y, cdf).pvalue > 1e-3
    mean = float((r * mu).sum())
    var = float((r * (sd**2 + mu**2)).sum() - mean**2)
    if np.mean(y == 0.0) < 1e-4:  # the clip at 0 is negligible here: the closed-form moments apply
        c = mu - mean
        m4 = float((r * (c**4 + 6 * c**2 * sd**2 + 3 * sd**4)).sum())  # fourth central moment of the mixture
        se_m = np.sqrt(var / y.size)
        se_s = np.sqrt((m4 - var**2) / (4 * var * y.size))  # delta method for the sample std
        assert_mean_within_se(y, mean, se=se_m, what=f"reading mean at x = {x} vs the JSON's closed form")
        assert_std_within_se(y, np.sqrt(var), se=se_s, ddof=0,
                             what=f"reading std at x = {x} vs the JSON's closed form")
