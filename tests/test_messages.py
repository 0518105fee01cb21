"""Small user-facing messages of issue 13 item 7: grammar, help text, element errors, a UTF-8 BOM,
``--out ''`` for every command, one-line warnings, pluralisation, the IMU window named."""
from __future__ import annotations

import numpy as np
import pytest

from finkensim.cli import main
from finkensim.config import ConfigError, config_from_dict, load_config
from finkensim.flightlog import FlightLog
from finkensim.sweep import Sweep


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def test_expected_an_integer_not_a_integer():
    with pytest.raises(ConfigError) as info:
        config_from_dict({"copters": {"n": "six"}})
    assert "expected an integer" in str(info.value) and "a integer" not in str(info.value)
    with pytest.raises(ConfigError, match="expected a number"):
        config_from_dict({"copters": {"radius": "big"}})


def test_sweep_help_shows_a_single_percent_sign(capsys):
    assert main(["sweep", "--help"]) == 0
    out = capsys.readouterr().out
    assert "95% CI" in " ".join(out.split()) and "%%" not in out


def test_a_bad_list_element_is_named_before_the_length():
    with pytest.raises(ConfigError) as info:
        config_from_dict({"sonar": {"yaw_deg": [0, 90, "x"]}})
    msg = str(info.value)
    assert "sonar.yaw_deg[2] = 'x'" in msg and "expected a number" in msg
    with pytest.raises(ConfigError, match="expected a list of 4 numbers, got 3"):
        config_from_dict({"sonar": {"yaw_deg": [0, 90, 180]}})


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes("\ufeff[copters]\nn = 3\n".encode("utf-8"))
    assert load_config(p).copters.n == 3
    s = tmp_path / "sweep.toml"
    s.write_bytes("\ufeffreplicates = 1\nduration = 1.0\n[grid]\n\"copters.n\" = [2, 3]\n".encode("utf-8"))
    assert Sweep.from_toml(s).n_runs == 2


@pytest.mark.parametrize("argv", [
    ["run", "--out", ""],
    ["sweep", "SWEEP", "--out", " "],
    ["gap", "LOG", "--out", ""],
    ["gap-validate", "--out", ""],
    ["tune", "SWEEP", "--out", ""],
])
def test_empty_out_is_a_named_error_for_every_command(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    sweep = tmp_path / "s.toml"
    sweep.write_text("replicates = 1\nduration = 1.0\n[grid]\n\"copters.n\" = [2]\n")
    argv = [str(sweep) if a == "SWEEP" else str(tmp_path / "nolog.npz") if a == "LOG" else a for a in argv]
    assert main(argv) == 2
    assert "--out '': expected a directory name" in _error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]  # nothing written into the current directory


def test_warnings_are_one_line_without_python_source(tmp_path, capsys):
    scen = tmp_path / "crowded.toml"
    scen.write_text("[copters]\nn = 12\nmin_separation = 1.5\n[simulation]\nduration = 0.05\n")
    assert main(["run", str(scen), "--out", str(tmp_path / "o"), "--no-gif"]) == 0
    err = capsys.readouterr().err
    warn = [line for line in err.splitlines() if "min_separation" in line]
    assert warn and warn[0].startswith("finkensim run: warning: copters.min_separation = 1.5 m could not be met")
    assert "warnings.warn" not in err and "RuntimeWarning" not in err and "Traceback" not in err


def _log(T: int, dt: float = 0.01, imu: bool = True) -> FlightLog:
    t = dt * np.arange(T)
    pose = np.zeros((T, 2, 3))
    pose[:, 0, :2] = (1.0, 1.0)
    pose[:, 1, :2] = (2.0, 3.0)
    kw = dict(imu_acc=np.zeros((T, 2, 2)), imu_gyro=np.zeros((T, 2))) if imu else {}
    return FlightLog(t=t, arena=np.array([3.0, 4.0]), pose=pose, copter_ids=np.array(["a", "b"]), **kw)


def test_sample_counts_are_pluralised():
    from finkensim.gap.model.replay import GapInputError, prepare_flights

    cfg = load_config(None)
    with pytest.raises(GapInputError) as info:
        prepare_flights([_log(1)], ["one.npz"], cfg)
    assert "the log has 1 sample;" in str(info.value)
    with pytest.raises(GapInputError, match="the log has 3 samples;"):
        prepare_flights([_log(3)], ["three.npz"], cfg)


def test_a_log_shorter_than_the_imu_window_names_gap_imu_window():
    from finkensim.gap import Diagnosis
    from finkensim.gap.model.replay import GapInputError

    cfg = load_config(None)
    with pytest.raises(GapInputError) as info:
        Diagnosis([_log(200, dt=0.01)], ["short.npz"], cfg)  # 2 s, held-out half 1 s = gap.imu_window
    msg = str(info.value)
    assert msg.startswith("imu: no readings in the") and "gap.imu_window = 1 s" in msg
