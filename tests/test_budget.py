"""Memory checked before it is spent and physically impossible crowding refused (issue 13 item 6)."""
from __future__ import annotations

import numpy as np
import pytest

from finkensim.budget import MEMORY_ENV, MemoryBudgetError, available_bytes, check_memory, flight_arrays, format_bytes
from finkensim.cli import main
from finkensim.config import ConfigError, config_from_dict, load_config
from finkensim.flightlog import FlightLog


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("n", [154, 1000, 100000])
def test_more_copters_than_the_arena_can_hold_is_a_named_error(n):
    with pytest.raises(ConfigError) as info:
        config_from_dict({"copters": {"n": n}})
    msg = str(info.value)
    assert f"copters.n = {n}" in msg and "expected copters.n <= 153" in msg and "3.0 x 4.0 m arena" in msg


def test_crowding_limit_follows_the_arena_and_radius():
    assert config_from_dict({"copters": {"n": 153}}).copters.n == 153
    assert config_from_dict({"copters": {"n": 1000}, "arena": {"width": 30.0, "length": 40.0}}).copters.n == 1000
    cfg = load_config(None)
    with pytest.raises(ConfigError, match="copters.n = 6"):
        cfg.replace({"copters.radius": 1.5})


def test_available_memory_override_and_format(monkeypatch):
    monkeypatch.setenv(MEMORY_ENV, "2e9")
    assert available_bytes() == 2_000_000_000
    monkeypatch.setenv(MEMORY_ENV, "lots")
    with pytest.raises(ConfigError, match=MEMORY_ENV):
        available_bytes()
    monkeypatch.delenv(MEMORY_ENV)
    assert available_bytes() is None or available_bytes() > 0
    assert format_bytes(1.5 * 2**40) == "1.5 TiB" and format_bytes(12) == "12 B"


def test_flight_estimate_grows_with_n_squared_for_ranging():
    small = flight_arrays(config_from_dict({"copters": {"n": 10}}))
    large = flight_arrays(config_from_dict({"copters": {"n": 100}}))
    assert large["ranging (T, N, N)"] == pytest.approx(100 * small["ranging (T, N, N)"])
    off = flight_arrays(config_from_dict({"copters": {"n": 100}, "ranging": {"enabled": False}}))
    assert "ranging (T, N, N)" not in off
    assert check_memory({"x": 10.0}, "a run", available=100) == 10.0
    with pytest.raises(MemoryBudgetError, match=r"a run would hold about 1000 B of arrays \(x 1000 B\)"):
        check_memory({"x": 1000.0}, "a run", available=100)


def test_run_refuses_before_allocating(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv(MEMORY_ENV, "1e4")
    assert main(["run", "--duration", "1", "--out", str(tmp_path / "o"), "--no-gif"]) == 2
    line = _error_line(capsys)
    assert "a flight of 1 s of 6 copters would hold about" in line and "more than the 9.77 KiB" in line
    assert not (tmp_path / "o" / "flight.npz").exists()


def test_huge_swarm_is_refused_at_once_not_after_the_sonar_stage(tmp_path, capsys):
    scen = tmp_path / "big.toml"
    scen.write_text("[copters]\nn = 100000\nradius = 0.01\n[arena]\nwidth = 1000.0\nlength = 1000.0\n")
    assert main(["run", str(scen), "--out", str(tmp_path / "o")]) == 2
    line = _error_line(capsys)
    assert "ranging (T, N, N)" in line and "TiB" in line and "ranging.enabled = false" in line


def test_gap_validate_duration_1e7_is_a_named_memory_error(tmp_path, capsys):
    assert main(["gap-validate", "--duration", "1e7", "--out", str(tmp_path / "gv")]) == 2
    line = _error_line(capsys)
    assert "--duration 1e+07 s would hold about" in line and "lower --duration" in line
    assert not (tmp_path / "gv").exists()


def test_sweep_refuses_before_any_run(monkeypatch, tmp_path, capsys):
    s = tmp_path / "s.toml"
    s.write_text("replicates = 1\nduration = 1.0\n[grid]\n\"copters.n\" = [2]\n")
    monkeypatch.setenv(MEMORY_ENV, "100")
    assert main(["sweep", str(s), "--out", str(tmp_path / "o"), "--executor", "serial", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "would hold about" in err and "Traceback" not in err  # the design's size or an episode (issue 40)
    assert not (tmp_path / "o" / "parts").exists()


def test_gap_refuses_before_building_ensembles(monkeypatch):
    from finkensim.gap import Diagnosis

    T = 400
    pose = np.zeros((T, 2, 3))
    pose[:, 0, :2], pose[:, 1, :2] = (1.0, 1.0), (2.0, 3.0)
    log = FlightLog(t=0.01 * np.arange(T), arena=np.array([3.0, 4.0]), pose=pose, copter_ids=np.array(["a", "b"]),
                    imu_acc=np.zeros((T, 2, 2)), imu_gyro=np.zeros((T, 2)))
    monkeypatch.setenv(MEMORY_ENV, "1000")
    with pytest.raises(MemoryBudgetError, match=r"the diagnosis of 1 flight\(s\) would hold about .*gap.draws"):
        Diagnosis([log], ["a.npz"], load_config(None))


def test_start_spacing_warning_holds_above_200_copters():
    from finkensim.world import World

    cfg = config_from_dict({"copters": {"n": 300, "min_separation": 1.0, "radius": 0.05},
                            "arena": {"width": 6.0, "length": 8.0}})
    with pytest.warns(RuntimeWarning, match="copters.min_separation = 1.0 m could not be met for 300 copters"):
        World(cfg).init(seed=0)


def test_a_flight_log_larger_than_memory_is_refused_from_its_headers(tmp_path, monkeypatch, capsys):
    from finkensim.flightlog import FlightLogError, load, save

    T = 400
    pose = np.zeros((T, 2, 3))
    pose[:, 0, :2], pose[:, 1, :2] = (1.0, 1.0), (2.0, 3.0)
    rg = np.ones((T, 2, 2))
    rg[:, [0, 1], [0, 1]] = 0.0
    save(FlightLog(t=0.01 * np.arange(T), arena=np.array([3.0, 4.0]), pose=pose, copter_ids=np.array(["a", "b"]),
                   ranging=rg), tmp_path / "f.npz")
    monkeypatch.setenv(MEMORY_ENV, "20000")
    with pytest.raises(FlightLogError, match=r"f.npz'?: reading the flight log would hold about 34.5 KiB of arrays "
                                             r"\(pose 18.8 KiB, ranging 12.5 KiB, t 3.12 KiB\)"):
        load(tmp_path / "f.npz")
    assert main(["check", str(tmp_path / "f.npz")]) == 2
    assert "reading the flight log" in _error_line(capsys)
