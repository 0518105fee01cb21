"""finkensim.datasets: the three public recordings load with their documented conversions, are checked against
their SHA-256 sums, and import through ``finkensim import`` from the CSV files they write, without hand edits.

The recordings live outside the repository (``$FINKENSIM_DATA`` or ``../shared/realdata/``); without them every
test here that needs them is skipped with a message naming the folder.
"""
from __future__ import annotations

import shutil

import numpy as np
import pytest

from finkensim.datasets import LOADERS, DatasetError, data_home, load_murp, load_util
from finkensim.datasets.files import LISTED_SUMS, OWN_SHA256, expected_sum, listed_sums
from finkensim.datasets.record import yaw_from_quaternion
from finkensim.flightlog import load


def _home():
    try:
        return data_home()
    except DatasetError as exc:
        return exc


HOME = _home()
needs_data = pytest.mark.skipif(isinstance(HOME, Exception), reason=f"real data absent: {HOME}")


@pytest.fixture(scope="module")
def datasets():
    return {name: f() for name, f in LOADERS.items()}


def test_yaw_from_quaternion_is_the_heading():
    a = np.linspace(-3.1, 3.1, 13)
    assert np.allclose(yaw_from_quaternion(0 * a, 0 * a, np.sin(a / 2), np.cos(a / 2)), a)


def test_absent_folder_is_named(monkeypatch, tmp_path):
    monkeypatch.setenv("FINKENSIM_DATA", str(tmp_path / "nowhere"))
    with pytest.raises(DatasetError, match="real-data folder not found.*nowhere.*FINKENSIM_DATA"):
        load_murp()
    (tmp_path / "nowhere").mkdir()
    with pytest.raises(DatasetError, match="murp_trial16 does not exist"):
        load_murp()


@needs_data
def test_sums_come_from_the_folders_own_lists():
    """MILUV and MURP are checked against the sums their folders publish (nothing of theirs is copied into the
    code); UTIL's folder lists only its binary, so its decoded files are checked against finkensim's own sums."""
    for name in ("miluv_cirObstacles_3_random_0", "murp_trial16"):
        table = dict(reversed(line.split()) for line in (HOME / name / LISTED_SUMS).read_text().splitlines()
                     if line.strip())
        assert listed_sums(name) == table and name not in OWN_SHA256
        assert all(expected_sum(name, f) == h for f, h in table.items())
    assert listed_sums("util_twr_obs_log1") == {}
    assert expected_sum("util_twr_obs_log1", "anchor_0607.txt") == OWN_SHA256["util_twr_obs_log1"]["anchor_0607.txt"]


@needs_data
def test_a_malformed_or_silent_list_is_named(monkeypatch, tmp_path):
    shutil.copytree(HOME / "murp_trial16", tmp_path / "murp_trial16")
    monkeypatch.setenv("FINKENSIM_DATA", str(tmp_path))
    listed = tmp_path / "murp_trial16" / LISTED_SUMS
    listed.chmod(0o644)
    lines = listed.read_text().splitlines()
    listed.write_text("\n".join(lines[1:]) + "\n")
    with pytest.raises(DatasetError, match="no SHA-256 sum for file 16_base-1_targ-2"):
        load_murp()
    listed.write_text("not a sum\n")
    with pytest.raises(DatasetError, match="SHA256SUMS.uncompressed: line 1 reads 'not a sum'"):
        load_murp()


@needs_data
def test_corrupt_or_missing_file_is_named(monkeypatch, tmp_path):
    shutil.copytree(HOME / "util_twr_obs_log1", tmp_path / "util_twr_obs_log1")
    monkeypatch.setenv("FINKENSIM_DATA", str(tmp_path))
    load_util()
    anchors = tmp_path / "util_twr_obs_log1" / "anchor_0607.txt"
    anchors.write_text(anchors.read_text().replace("-3.1051", "-3.1052"))
    with pytest.raises(DatasetError, match="anchor_0607.txt has SHA-256 .* expected ab48e3fe"):
        load_util()
    anchors.unlink()
    with pytest.raises(DatasetError, match="anchor_0607.txt .* is missing"):
        load_util()


@needs_data
def test_what_each_dataset_holds(datasets):
    miluv, murp, util = (datasets[k] for k in LOADERS)
    assert len(miluv.recording.readings) == 123 and miluv.copters == ["ifo001", "ifo002", "ifo003"]
    assert len(murp.recording.readings) == 6 * 211
    assert len(util.recording.readings) == 5509 and util.fixed_nodes == tuple(f"anchor{k}" for k in range(8))
    for ds in datasets.values():
        tr = ds.recording.tracking
        assert tr["x"].min() > 0 and tr["y"].min() > 0
        assert tr["x"].max() < ds.arena[0] and tr["y"].max() < ds.arena[1]
        assert np.all(np.abs(tr["yaw"]) <= np.pi) and "z" in tr.columns
        assert len(ds.truth) == len(ds.recording.readings)
    z = murp.recording.tracking.groupby("copter")["z"].median()
    assert z["robot1"] == pytest.approx(1.75, abs=0.02) and z["robot2"] < 0.6 and z["robot3"] < 0.6


def _centre_distance(ds, log):
    """3-D centre-to-centre distance at each reading's sample, and the dataset's truth there."""
    rd = ds.truth
    k = np.searchsorted(log.t, rd["t"].to_numpy() + ds.clock_offset)
    k = np.clip(k, 0, log.t.size - 1)
    ids = list(log.copter_ids)
    a = np.array([ids.index(c) for c in rd["copter"]])
    b = np.array([ids.index(c.split("/", 1)[1]) for c in rd["channel"]])
    p = np.concatenate([log.pose[..., :2], log.extras["z"][..., None]], axis=-1)
    return np.linalg.norm(p[k, a] - p[k, b], axis=1), rd["truth"].to_numpy()


@needs_data
def test_conversions_agree_with_each_datasets_own_truth(datasets):
    """Frame, yaw, heights and time base: the tracked centres reproduce the truth each dataset publishes, up to
    what the tags' places on the bodies allow (MILUV: ±0.37 m at 5-95 %; MURP: the mean over 6 x 6 antennas)."""
    for name, tol in (("miluv_cirObstacles_3_random_0", 0.45), ("murp_trial16", 0.25), ("util_twr_obs_log1", 0.05)):
        ds = datasets[name]
        d, truth = _centre_distance(ds, ds.flight())
        assert np.quantile(np.abs(d - truth), 0.9) < tol, name


@needs_data
@pytest.mark.parametrize("name", list(LOADERS))
def test_written_csv_imports_without_edits(name, datasets, tmp_path):
    from finkensim.cli import main

    ds = datasets[name]
    args = ds.write_csv(tmp_path)
    assert main(["import", *args, "--out", str(tmp_path / "f.npz")]) == 0
    log = load(tmp_path / "f.npz")
    direct = ds.flight()
    assert np.array_equal(log.ranging, direct.ranging, equal_nan=True)
    assert np.allclose(log.pose, direct.pose) and np.allclose(log.extras["z"], direct.extras["z"])
    assert log.meta["import"]["readings_placed"]["ranging"] == len(ds.recording.readings)


def test_module_command_names_absent_data(monkeypatch, tmp_path, capsys):
    from finkensim.datasets.__main__ import main

    monkeypatch.setenv("FINKENSIM_DATA", str(tmp_path / "nowhere"))
    assert main([str(tmp_path / "out")]) == 2
    assert "real-data folder not found" in capsys.readouterr().err
    assert main([str(tmp_path / "out"), "nosuch"]) == 2


@needs_data
def test_module_command_writes_and_prints_the_truth(tmp_path, capsys):
    from finkensim.datasets.__main__ import main

    assert main([str(tmp_path), "murp_trial16"]) == 0
    out = capsys.readouterr().out
    assert "robot1->robot2 +0.186" in out and "finkensim import --tracking" in out
    assert (tmp_path / "murp_trial16" / "track.csv").exists()
