"""The learned correction flown for the ranging readings (``ranging.correction_file``): the kernel against its
plain-NumPy reference, the error model's median grid against the mixture's exact median, the simulator reproducing
the table's quantiles, the diagnosis drawing the same correction, and the named errors of a bad file."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from finkensim.config import load_config
from finkensim.sensors.correction_table import CorrectionFileError, CorrectionTable, write_correction
from finkensim.sensors.ranging import RangingModel, error_medians, ranging_readings
from finkensim.sensors.ranging_kernels import row_key
from finkensim.sensors.ranging_radio import radio_batch
from tests.naive.ranging_radio import naive_corrected, naive_radio_readings

radio_effects = st.fixed_dictionaries({
    "bias": st.floats(-0.5, 0.5),
    "scale": st.floats(0.8, 1.2),
    "node_delay": st.lists(st.floats(-0.3, 0.3), max_size=6).map(tuple),
    "nlos_bias": st.floats(-0.5, 1.0),
    "nlos_width": st.floats(0.05, 0.5),
    "nlos_tail_probability": st.floats(0.0, 1.0),
    "dropout_a": st.one_of(st.just(-100.0), st.floats(-6.0, 3.0)),
    "dropout_b": st.floats(-2.0, 2.0),
})


def _table(rng, G=3, Q=7):
    edges = np.concatenate([[-0.5], np.sort(rng.uniform(0.2, 2.5, G - 1)), [4.0]])
    levels = (np.arange(Q) + 0.5) / Q
    return CorrectionTable(edges, levels, np.sort(rng.normal(-0.1, 0.3, (G, Q)), axis=1))


@pytest.mark.parametrize("error", ["none", "gaussian", "mixture", "seed"])
@settings(max_examples=15, deadline=None)
@given(radio=radio_effects, seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31))
def test_corrected_readings_equal_the_reference(error, radio, seed, data_seed):
    rng = np.random.default_rng(data_seed)
    model = RangingModel(error, max_range=3.0, sigma=0.1, correction=_table(rng), **radio)
    pos = rng.uniform(0.0, 2.5, (2, 4, 2))
    beacons = rng.uniform(0.0, 2.5, (1, 2))
    env_ids = np.array([2, 9])
    got = ranging_readings(pos, beacons, seed, env_ids, 5, model)
    want = naive_radio_readings(pos, np.zeros((2, 4)), beacons, seed, env_ids, 5, model)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


@settings(max_examples=15, deadline=None)
@given(radio=radio_effects, seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31))
def test_the_diagnosis_draws_the_same_corrected_reading(radio, seed, data_seed):
    """radio_batch (the diagnosis's draws): draw (i, m) is the corrected reading of uniform i·M + m of its key."""
    rng = np.random.default_rng(data_seed)
    model = RangingModel("mixture", max_range=2.0, correction=_table(rng), **radio)
    n, M = 4, 3
    x = rng.uniform(0.0, 2.5, (n, M))
    a, b = rng.integers(0, 8, n), rng.integers(0, 8, n)
    clear = rng.uniform(0.0, 1.0, n)
    key, ckey = row_key(seed, 0, 0, 0), row_key(seed, 0, 0, 1)
    out = np.empty((n, M))
    radio_batch(np.full((n, M), np.nan), x, a, b, clear, key, ckey, 2.0, model.params, out)
    want = [[2.0 if x[i, m] > 2.0 else naive_corrected(x[i, m], a[i], b[i], clear[i], ckey, i * M + m, model)
             for m in range(M)] for i in range(n)]
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-12)


def test_the_median_grid_is_the_mixtures_median():
    """The mixture's median reading at the grid's nodes, to 1e-8 m (scipy's root finder on the analytic CDF)."""
    model = RangingModel("mixture", max_range=2.5)
    R = 33
    got = error_medians(model, R)
    for x, m in zip(np.linspace(0.0, 2.5, R), got):
        want = max(brentq(lambda y: model.mixture.conditional_cdf(y, x) - 0.5, -5.0, 8.0, xtol=1e-12), 0.0)
        assert m == pytest.approx(want, abs=1e-8)
    np.testing.assert_array_equal(error_medians(RangingModel("gaussian"), 5), np.linspace(0.0, 2.5, 5))


def _cfg(path, **more):
    return load_config().replace({"copters.n": 5, "behaviour.kind": "random_walk", "ranging.correction_file": str(path),
                                  **more})


def test_the_simulator_reproduces_the_tables_quantiles(tmp_path):
    """Readings in range minus the model's median reading follow the table's quantile function in each bin: the
    empirical CDF at every tabulated quantile is within the DKW bound at 1e-9 (n readings per bin, fixed seed)."""
    from finkensim.swarm import SwarmSim

    t = CorrectionTable(np.array([-1.0, 1.2, 9.0]), np.array([0.1, 0.3, 0.5, 0.7, 0.9]),
                        np.array([[-0.8, -0.1, 0.0, 0.05, 0.2], [-0.3, -0.2, 0.1, 0.3, 0.6]]))
    path = write_correction(tmp_path / "c.json", {"ranging": t})
    sim = SwarmSim(_cfg(path, **{"sonar.enabled": False, "imu.enabled": False}))
    _, rec = sim.rollout(sim.init(n_envs=4, seed=3), 150, record=("ranging", "pose"))
    _, py = sim.rollout(sim.init(n_envs=4, seed=3), 3, record=("ranging",), python=True)
    np.testing.assert_array_equal(rec.ranging[:3], py.ranging)  # the compiled and the Python path agree
    p = rec.pose[..., :2]
    x = np.linalg.norm(p[..., :, None, :] - p[..., None, :, :], axis=-1)
    model = sim.ranging
    ref = np.interp(x, np.linspace(0.0, model.max_range, model.params.median.size), model.params.median)
    ok = (x <= model.max_range) & ~np.eye(5, dtype=bool)
    for g in range(2):
        sel = ok & (ref >= t.edges[g]) & (ref < t.edges[g + 1])
        r = (rec.ranging - ref)[sel]
        eps = np.sqrt(np.log(2 / 1e-9) / (2 * r.size))
        assert r.size > 2000
        # each tabulated quantile q_k at level p_k: P(r <= q_k) = p_k; beyond the last level the last quantile (an
        # atom: P(r < q_last) = p_last); 1e-9 m: the rounding of reading - ref
        below = [np.mean(r <= q + 1e-9) for q in t.quantiles[g][:-1]] + [np.mean(r < t.quantiles[g][-1] - 1e-9)]
        np.testing.assert_array_less(np.abs(np.array(below) - t.levels), eps)


def test_a_file_without_a_ranging_table_is_named(tmp_path):
    t = CorrectionTable(np.array([0.0, 1.0]), np.array([0.5]), np.array([[0.1]]))
    path = write_correction(tmp_path / "c.json", {"ultrasonic": t})
    with pytest.raises(CorrectionFileError, match=r"ranging\.correction_file = .*c\.json.*no 'ranging' table"):
        RangingModel.from_config(_cfg(path).ranging)
    with pytest.raises(CorrectionFileError, match=r"ranging\.correction_file = .*nope\.json.*no such file"):
        RangingModel.from_config(_cfg(tmp_path / "nope.json").ranging)


def test_without_a_file_the_model_is_unchanged():
    model = RangingModel.from_config(load_config().ranging)
    assert model.correction is None and int(model.params.radio_on) == 0 and model.params.correction.size == 0
