"""The learned correction flown for the IMU (``imu.correction_file``, finkensim.sensors.imu_correction): the
compiled kernels against their plain-NumPy references, the simulator's block integrals reproducing the table's
quantiles, the diagnosis drawing the same correction, and the named errors of a bad file."""
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from finkensim.config import load_config
from finkensim.gap.model.params import ModelParams
from finkensim.kernels.rng import STREAM_CORRECTION_IMU, counter_key, uniform
from finkensim.sensors.correction_table import ChannelTables, CorrectionFileError, CorrectionTable, write_correction
from finkensim.sensors.imu import ImuModel, imu_step
from finkensim.sensors.imu_correction import IMU_CHANNELS, corrected_window_draws, pack_channels
from tests.naive.imu import corrected_imu_ref


def _tables(rng, window=0.5, Q=5):
    levels = (np.arange(Q) + 0.5) / Q
    out = {}
    for name in IMU_CHANNELS:
        G = int(rng.integers(1, 4))
        edges = np.concatenate([[-3.0], np.sort(rng.uniform(-1.0, 1.0, G - 1)), [3.0]])
        out[name] = CorrectionTable(edges, levels, np.sort(rng.normal(0.0, 0.2, (G, Q)), axis=1))
    return ChannelTables(out, window)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31), step=st.integers(0, 400),
       bias=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.1, 0.1)))
def test_corrected_imu_equals_the_reference(seed, data_seed, step, bias):
    rng = np.random.default_rng(data_seed)
    tables = _tables(rng, window=float(rng.uniform(0.05, 2.0)))
    model = ImuModel.from_densities(0.004, 0.0005, 0.00009, 0.00002, 0.05)._replace(
        acc_bias_x=bias[0], acc_bias_y=bias[1], gyro_bias=bias[2], correction=pack_channels(tables),
        correction_window=tables.window)
    acc_world = rng.normal(0.0, 1.0, (2, 4, 2))
    yaw = rng.uniform(-np.pi, np.pi, (2, 4))
    rate = rng.normal(0.0, 1.0, (2, 4))
    walk = np.zeros((2, 4, 3))
    acc, gyro = imu_step(acc_world, yaw, rate, walk, model, seed, np.array([1, 6]), step)
    for b, env in enumerate((1, 6)):
        want_acc, want_gyro = corrected_imu_ref(acc_world[b], yaw[b], rate[b], [tables.channels[c] for c in IMU_CHANNELS],
                                                tables.window, 0.05, bias[:2], bias[2], seed, env, step)
        np.testing.assert_allclose(acc[b], want_acc, rtol=0, atol=1e-9)
        np.testing.assert_allclose(gyro[b], want_gyro, rtol=0, atol=1e-9)
    # the bias random walk still advances as without the correction (its own normals)
    plain = np.zeros((2, 4, 3))
    imu_step(acc_world, yaw, rate, plain, model._replace(correction=np.zeros((0, 0, 0))), seed, np.array([1, 6]), step)
    np.testing.assert_array_equal(walk, plain)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31), data_seed=st.integers(0, 2**31))
def test_the_diagnosis_draws_equal_the_reference(seed, data_seed):
    rng = np.random.default_rng(data_seed)
    tables = _tables(rng)
    n, M = 6, 4
    ideal = rng.normal(0.0, 1.0, (n, M))
    bias = rng.normal(0.0, 0.1, n)
    channel = rng.integers(0, 3, n)
    flight, tidx, chan = rng.integers(0, 3, n), rng.integers(0, 500, n), rng.integers(0, 40, n)
    out = np.empty((n, M))
    corrected_window_draws(ideal, bias, channel, flight, tidx, chan, seed, pack_channels(tables), out)
    for i in range(n):
        t = tables.channels[IMU_CHANNELS[channel[i]]]
        key = np.uint64(counter_key(*map(np.int64, (seed, flight[i], tidx[i], chan[i], STREAM_CORRECTION_IMU))))
        for m in range(M):
            ref = ideal[i, m] + bias[i]
            g = int(np.clip(np.searchsorted(t.edges, ref, side="right") - 1, 0, t.quantiles.shape[0] - 1))
            assert out[i, m] == pytest.approx(ref + np.interp(uniform(key, m), t.levels, t.quantiles[g]), abs=1e-12)


def _file(tmp_path, tables):
    return write_correction(tmp_path / "c.json", {"imu": tables})


def test_the_simulator_reproduces_the_tables_quantiles(tmp_path):
    """A window that is one block integrates to its ideal value plus a draw of the table: over every block of every
    copter, the empirical CDF at each tabulated quantile is within the DKW bound at 1e-9 (fixed seed)."""
    from finkensim.swarm import SwarmSim

    levels = np.array([0.1, 0.3, 0.5, 0.7, 0.9])
    one = lambda q, unit: CorrectionTable(np.array([-50.0, 50.0]), levels, np.array([q]), unit)  # noqa: E731
    tables = ChannelTables({"dv_x": one([-0.3, -0.1, 0.0, 0.1, 0.5], "m/s"), "dv_y": one([-0.2, -0.05, 0.0, 0.15, 0.2],
                                                                                          "m/s"),
                            "dyaw": one([-0.05, -0.01, 0.02, 0.03, 0.08], "rad")}, 0.25)
    cfg = load_config().replace({"copters.n": 6, "behaviour.kind": "random_walk", "sonar.enabled": False,
                                 "ranging.enabled": False, "imu.correction_file": str(_file(tmp_path, tables))})
    sim = SwarmSim(cfg)
    h = int(round(0.25 / cfg.simulation.dt))
    _, rec = sim.rollout(sim.init(n_envs=4, seed=5), 100 * h, record=("imu_acc", "imu_gyro", "acc", "yaw_rate", "pose"))
    _, py = sim.rollout(sim.init(n_envs=4, seed=5), 2 * h, record=("imu_acc", "imu_gyro"), python=True)
    np.testing.assert_array_equal(rec.imu_acc[:2 * h], py.imu_acc)  # the compiled and the Python path agree
    np.testing.assert_array_equal(rec.imu_gyro[:2 * h], py.imu_gyro)
    c, s = np.cos(rec.pose[..., 2]), np.sin(rec.pose[..., 2])
    ax, ay = rec.imu_acc[..., 0], rec.imu_acc[..., 1]
    residual = np.stack([c * ax - s * ay - rec.acc[..., 0], s * ax + c * ay - rec.acc[..., 1],
                         rec.imu_gyro - rec.yaw_rate], axis=-1)  # world-frame rates minus the ideal ones
    dt = cfg.simulation.dt
    T = residual.shape[0] // h * h
    blocks = residual[:T].reshape(T // h, h, *residual.shape[1:]).sum(axis=1) * dt  # (blocks, B, N, 3) integrals
    for ch, name in enumerate(IMU_CHANNELS):
        r = blocks[..., ch].ravel()
        eps = np.sqrt(np.log(2 / 1e-9) / (2 * r.size))
        q = tables.channels[name].quantiles[0]
        below = [np.mean(r <= v + 1e-9) for v in q[:-1]] + [np.mean(r < q[-1] - 1e-9)]
        np.testing.assert_array_less(np.abs(np.array(below) - levels), eps, err_msg=name)


def test_a_calibrated_config_is_diagnosed_with_the_correction(tmp_path):
    """ModelParams.from_config reads the file: the diagnosis's IMU record carries the packed tables (its draws then
    take corrected_window_draws, tested above), and the scores' cache key sees them."""
    tables = _tables(np.random.default_rng(0))
    cfg = load_config().replace({"imu.correction_file": str(_file(tmp_path, tables))})
    p, plain = ModelParams.from_config(cfg), ModelParams.from_config(load_config())
    np.testing.assert_array_equal(p.imu.correction, pack_channels(tables))
    assert p.imu.correction_window == 0.5 and plain.imu.correction.shape == (0, 0, 0)
    assert p.sensor_key("imu") != plain.sensor_key("imu")


@pytest.mark.parametrize("change,match", [
    (lambda d: d["sensors"].pop("imu"), "no 'imu' table"),
    (lambda d: d["sensors"]["imu"]["channels"].pop("dyaw"), "expected a table for each of dv_x, dv_y, dyaw"),
    (lambda d: d["sensors"]["imu"].update(window=0.0), r"sensors\.imu\.window = 0\.0: expected the window"),
    (lambda d: d["sensors"]["imu"].update(window="1 s"), r"window = '1 s': expected a finite number"),
    (lambda d: d["sensors"].update(imu=d["sensors"]["imu"]["channels"]["dv_x"]), "expected a table for each of"),
    (lambda d: d["sensors"]["imu"]["channels"]["dv_y"].update(levels=[0.2, 0.4, 0.6, 0.8, 0.9]),
     r"channels\.dv_y\.levels = .*expected the levels of channel dv_x"),
    (lambda d: d.update(version=1), "version = 1 with a table per channel: expected version 2"),
])
def test_bad_imu_files_are_named_errors(tmp_path, change, match):
    path = write_correction(tmp_path / "c.json", {"imu": _tables(np.random.default_rng(1)),
                                                  "ranging": CorrectionTable(np.array([0.0, 1.0]), np.array([0.5]),
                                                                             np.array([[0.0]]))})
    d = json.loads(path.read_text())
    assert d["version"] == 2
    change(d)
    path.write_text(json.dumps(d))
    with pytest.raises(CorrectionFileError, match=match):
        ImuModel.from_config(load_config().replace({"imu.correction_file": str(path)}).imu, 0.05)


def test_a_ranging_reader_refuses_a_channel_entry(tmp_path):
    path = write_correction(tmp_path / "c.json", {"ranging": _tables(np.random.default_rng(2))})
    from finkensim.sensors.ranging import RangingModel

    with pytest.raises(CorrectionFileError, match="holds a table per channel .*expected one table"):
        RangingModel.from_config(load_config().replace({"ranging.correction_file": str(path)}).ranging)
