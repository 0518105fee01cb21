"""The learned correction as a sensor model (finkensim.sensors.correction_table): the compiled quantile lookup
against its NumPy reference, the versioned file format and its named errors, the simulator and the diagnosis
applying the same table, and the table a diagnosis exports."""
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import load_config
from finkensim.gap.quantify.correction import residual_table
from finkensim.sensors.correction_table import (CorrectionFileError, CorrectionTable, correction_quantile,
                                                corrected_reference, read_correction, write_correction)


def _table(rng, G, Q):
    edges = np.cumsum(rng.uniform(0.05, 1.0, G + 1))
    levels = (np.arange(Q) + 0.5) / Q
    q = np.sort(rng.normal(0.0, 0.1, (G, Q)), axis=1)
    return CorrectionTable(edges, levels, q)


@settings(max_examples=80, deadline=None)
@given(G=st.integers(1, 6), Q=st.integers(1, 9), seed=st.integers(0, 2**31))
def test_quantile_kernel_matches_reference(G, Q, seed):
    rng = np.random.default_rng(seed)
    t = _table(rng, G, Q)
    packed = t.packed()
    ref = rng.uniform(t.edges[0] - 1.0, t.edges[-1] + 1.0, 40)
    u = rng.uniform(0.0, 1.0, 40)
    got = np.array([r + correction_quantile(packed, r, v) for r, v in zip(ref, u)])
    np.testing.assert_allclose(got, corrected_reference(ref, u, t), rtol=0, atol=1e-12)


def test_file_round_trip(tmp_path):
    t = _table(np.random.default_rng(0), 3, 5)
    path = write_correction(tmp_path / "c.json", {"ultrasonic": t}, {"flights": ["a"]})
    back = read_correction(path, "ultrasonic")
    for a, b in zip(t, back):
        np.testing.assert_array_equal(a, b)
    assert json.loads(path.read_text())["version"] == 1  # no per-channel entry: older readers still read it


def test_channel_tables_round_trip_as_version_2(tmp_path):
    from finkensim.sensors.correction_table import ChannelTables

    rng = np.random.default_rng(3)
    entry = ChannelTables({"a": _table(rng, 2, 4)._replace(unit="m/s"), "b": _table(rng, 3, 4)._replace(unit="rad")},
                          0.75)
    path = write_correction(tmp_path / "c.json", {"imu": entry, "ultrasonic": _table(rng, 1, 4)})
    assert json.loads(path.read_text())["version"] == 2
    back = read_correction(path, "imu", channels=("b", "a"))
    assert back.window == 0.75 and back.channels["a"].unit == "m/s" and back.channels["b"].unit == "rad"
    np.testing.assert_array_equal(back.channels["b"].quantiles, entry.channels["b"].quantiles)


@pytest.mark.parametrize("change,match", [
    (lambda d: d.update(version=3), "version = 3: expected one of 1, 2"),
    (lambda d: d.update(format="x"), "format = 'x'"),
    (lambda d: d["sensors"]["ultrasonic"].update(edges=[0.0]), "edges"),
    (lambda d: d["sensors"]["ultrasonic"].update(levels=[0.5, 0.2, 0.9]), "levels"),
    (lambda d: d["sensors"]["ultrasonic"].update(quantiles=[[0.0, 0.1]]), "quantiles has shape"),
    (lambda d: d["sensors"]["ultrasonic"]["quantiles"][0].reverse(), "a row decreases"),
    (lambda d: d["sensors"]["ultrasonic"].pop("levels"), "'levels' is missing"),
    (lambda d: d.update(sensors={"ranging": d["sensors"]["ultrasonic"]}), "no 'ultrasonic' table"),
])
def test_bad_files_are_named_errors(tmp_path, change, match):
    t = CorrectionTable(np.array([0.0, 1.0, 2.0]), np.array([0.25, 0.5, 0.75]),
                        np.array([[-0.1, 0.0, 0.1], [-0.2, 0.0, 0.2]]))
    path = write_correction(tmp_path / "c.json", {"ultrasonic": t})
    d = json.loads(path.read_text())
    change(d)
    path.write_text(json.dumps(d))
    with pytest.raises(CorrectionFileError, match=match):
        read_correction(path, "ultrasonic")


def test_a_missing_file_names_the_key(tmp_path):
    from finkensim.sensors.sonar_model import SonarModel

    with pytest.raises(CorrectionFileError, match=r"sonar\.correction_file = .*missing\.json.*no such file"):
        SonarModel.from_config(load_config().replace({"sonar.correction_file": str(tmp_path / "missing.json")}))


def _shift_table(tmp_path, shift=0.1):
    t = CorrectionTable(np.array([0.0, 10.0]), np.array([0.1, 0.9]), np.array([[shift, shift]]))
    return write_correction(tmp_path / "shift.json", {"ultrasonic": t})


def test_the_simulator_flies_the_correction(tmp_path):
    """A table that moves every echo 0.1 m out: each reading with an echo is its error-free distance + 0.1 m."""
    from finkensim.swarm import SwarmSim

    cfg = load_config().replace({"copters.n": 3, "behaviour.kind": "random_walk", "sonar.crosstalk": "off",
                                 "sonar.correction_file": str(_shift_table(tmp_path))})
    sim = SwarmSim(cfg)
    _, rec = sim.rollout(sim.init(n_envs=2, seed=0), 20, record=("sonar", "sonar_ideal", "sonar_hit"))
    _, py = sim.rollout(sim.init(n_envs=2, seed=0), 20, record=("sonar",), python=True)
    echo = (rec.sonar_hit != 0) & (rec.sonar_ideal < cfg.sonar.max_range)
    assert echo.any()
    want = np.clip(rec.sonar_ideal + 0.1, cfg.sonar.min_range, cfg.sonar.max_range)
    np.testing.assert_allclose(rec.sonar[echo], want[echo], atol=1e-12)
    np.testing.assert_array_equal(rec.sonar, py.sonar)


def test_the_diagnosis_draws_the_same_correction(tmp_path):
    from finkensim.gap.model.params import ModelParams, sonar_echo_errors, sonar_reading_draws
    from finkensim.kernels.raycast import HIT_WALL

    cfg = load_config().replace({"sonar.correction_file": str(_shift_table(tmp_path))})
    sp = ModelParams.from_config(cfg).sonar
    n, M = 5, 4
    dist = np.linspace(0.3, 1.5, n * M).reshape(n, M)
    kind = np.full((n, M), HIT_WALL, dtype=np.int64)
    idx = np.arange(n, dtype=np.int64)
    err = np.zeros((n, M))
    sonar_echo_errors(idx, idx, idx, 0, sp, err)
    out = np.empty((n, M))
    sonar_reading_draws(dist, kind, np.full((n, M), np.inf), idx, idx, idx, 0, sp, err, out)
    np.testing.assert_allclose(out, dist + 0.1, atol=1e-12)


def test_residual_table_holds_the_binned_quantiles():
    rng = np.random.default_rng(1)
    med = rng.uniform(0.0, 2.0, 4000)
    r = np.where(med < 1.0, 0.0, 0.2) + rng.normal(0.0, 0.01, med.size)
    levels = (np.arange(9) + 0.5) / 9
    t = residual_table(med, r, levels)
    assert t.quantiles.shape == (t.edges.size - 1, 9) and 2 <= t.quantiles.shape[0] <= 12
    lo = corrected_reference(np.array([0.2]), np.array([0.5]), t)[0] - 0.2
    hi = corrected_reference(np.array([1.8]), np.array([0.5]), t)[0] - 1.8
    assert abs(lo) < 0.01 and abs(hi - 0.2) < 0.01


def test_the_imu_correction_is_exported_per_channel():
    """The IMU's channels have their own units and scales: one table each (dv_x, dv_y m/s, dyaw rad), with the
    window; none when a channel has no training reading."""
    from finkensim.gap.quantify.correction import channel_tables

    rng = np.random.default_rng(2)
    channel = rng.integers(0, 3, 6000)
    med = rng.normal(0.0, 1.0, channel.size)
    r = np.where(channel == 2, 0.01, 0.5) * rng.normal(0.0, 1.0, channel.size)
    levels = (np.arange(9) + 0.5) / 9
    t = channel_tables(med, r, channel, 1.0, levels)
    assert list(t.channels) == ["dv_x", "dv_y", "dyaw"] and t.window == 1.0
    assert [c.unit for c in t.channels.values()] == ["m/s", "m/s", "rad"]
    spread = {k: c.quantiles[:, -1].mean() - c.quantiles[:, 0].mean() for k, c in t.channels.items()}
    assert spread["dyaw"] < 0.1 < spread["dv_x"]
    assert channel_tables(med[channel < 2], r[channel < 2], channel[channel < 2], 1.0, levels) is None
