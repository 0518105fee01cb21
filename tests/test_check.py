"""``finkensim check FILE ...``: named errors for bad files (exit 2), a summary line for good ones."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from finkensim.checkfiles import check_file, file_kind
from finkensim.cli import main
from finkensim.flightlog import FlightLog, save

SWEEP = "replicates = 2\nduration = 1.0\n[grid]\n\"copters.n\" = [2, 3]\n"


def _log(T=50, N=3) -> FlightLog:
    rng = np.random.default_rng(0)
    pose = np.stack([rng.uniform(0.5, 2.5, (T, N)), rng.uniform(0.5, 3.5, (T, N)), np.zeros((T, N))], axis=-1)
    rg = rng.uniform(0.2, 2.0, (T, N, N))
    rg[:, np.arange(N), np.arange(N)] = 0.0
    return FlightLog(t=0.02 * np.arange(T), arena=np.array([3.0, 4.0]), pose=pose,
                     copter_ids=np.array([f"cf{i}" for i in range(N)]), ranging=rg)


@pytest.fixture
def files(tmp_path):
    good = {}
    save(_log(), tmp_path / "flight.npz")
    good["flight.npz"] = "flight log, T = 50 samples over 0.98 s (dt 0.02 s), N = 3 copters, sensors: ranging; arena 3 x 4 m"
    (tmp_path / "track.csv").write_text("t,copter,x,y,yaw\n0,a,1,1,0\n0.1,a,1.1,1,0\n")
    good["track.csv"] = "flight log, T = 2 samples over 0.1 s (dt 0.1 s), N = 1 copter, sensors: none; arena 3 x 4 m"
    (tmp_path / "scen.toml").write_text("[copters]\nn = 4\n[simulation]\nduration = 10.0\n")
    good["scen.toml"] = "scenario, T = 201 samples over 10 s (dt 0.05 s), N = 4 copters (random_walk), sensors: sonar, ranging, imu; arena 3 x 4 m"
    (tmp_path / "sweep.toml").write_text(SWEEP)
    good["sweep.toml"] = "sweep, 4 runs (2 combinations x 2 replicates) of 1 s, grid over copters.n"
    return tmp_path, good


def test_good_files_get_a_summary_and_exit_0(files, capsys):
    d, good = files
    assert main(["check"] + [str(d / name) for name in good]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == len(good)
    for line, (name, summary) in zip(out, good.items()):
        assert line.startswith(f"{d / name}: {summary}"), line


def _bad(d):
    log = _log()
    arrays = {"format": np.array("finkensim-flightlog/1"), "t": log.t, "arena": log.arena,
              "pose": np.round(log.pose).astype(np.int64), "copter_ids": log.copter_ids}
    with open(d / "intpose.npz", "wb") as f:
        np.savez(f, **arrays)
    arrays.update(pose=log.pose, t=log.t * 1000.0)
    with open(d / "ms.npz", "wb") as f:
        np.savez(f, **arrays)
    with open(d / "pickle.npz", "wb") as f:
        np.savez(f, **{**arrays, "t": np.array([{"a": 1}], dtype=object)})
    (d / "pickled.npz").write_bytes(pickle.dumps({"t": [1, 2]}))
    (d / "noise.bin").write_bytes(bytes(range(256)))
    (d / "badkey.toml").write_text("[copters]\nnn = 3\n")
    (d / "badsweep.toml").write_text("replicates = 0\n[grid]\n\"copters.n\" = [2]\n")
    (d / "crowd.toml").write_text("[copters]\nn = 500\n")
    return {
        "intpose.npz": "pose has integer dtype int64",
        "ms.npz": "milliseconds",
        "pickle.npz": "object (pickled) array",
        "pickled.npz": "cannot be read as a NumPy .npz archive",
        "noise.bin": "not a text (TOML) file",
        "badkey.toml": "copters.nn",
        "badsweep.toml": "replicates",
        "crowd.toml": "copters.n = 500",
        "missing.npz": "does not exist",
    }


def test_bad_files_get_one_named_error_each_and_exit_2(files, capsys):
    d, good = files
    bad = _bad(d)
    argv = ["check", str(d / "flight.npz")] + [str(d / name) for name in bad]
    assert main(argv) == 2
    cap = capsys.readouterr()
    assert cap.out.strip().startswith(f"{d / 'flight.npz'}: flight log")
    errors = cap.err.strip().splitlines()
    assert "Traceback" not in cap.err and len(errors) == len(bad), cap.err
    for line, (name, words) in zip(errors, bad.items()):
        assert line.startswith("finkensim check: error: ") and name in line and words in line, line


def test_file_kind_and_csv_arena(files, tmp_path):
    d, _ = files
    assert [file_kind(d / n) for n in ("flight.npz", "track.csv", "scen.toml", "sweep.toml")] == \
        ["log", "csv", "scenario", "sweep"]
    (d / "renamed").write_bytes((d / "flight.npz").read_bytes())
    assert file_kind(d / "renamed") == "log"
    assert "arena 10 x 20 m" in check_file(d / "track.csv", arena=(10.0, 20.0))
