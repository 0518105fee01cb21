"""The numbers the sensor page (``docs/user-guide/sensors.md``) marks `[S]` and `[R]` are what
`examples/sensor_stats.py` and `examples/ranging_stats.py` print now (issue 16: text and code cannot drift apart).
Each figure below is looked up in the script's output and on the page; the ranging table is compared value by value
(the page rounds the analytic column to mm)."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGE_PATH = "docs/user-guide/sensors.md"
PAGE = (ROOT / PAGE_PATH).read_text(encoding="utf-8")


def run(script: str) -> str:
    p = subprocess.run([sys.executable, str(ROOT / "examples" / script)], capture_output=True, text=True, cwd=ROOT,
                       timeout=900)
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout


@pytest.fixture(scope="module")
def sensor_stats():
    return run("sensor_stats.py")


@pytest.fixture(scope="module")
def ranging_stats():
    return run("ranging_stats.py")


# figures printed by sensor_stats.py in the same form as the page prints them
SENSOR_FIGURES = ["0.6551σ", "0.5982σ", "0.306", "0.6780", "0.0300 m", "0.0326 m", "0.500 m", "0.850 m", "11.8 %",
                  "0.0179 m/s²", "0.00387 m/s²", "4.02e-04 rad/s", "1.55e-04 rad/s", "0.00392 m/s²/√Hz",
                  "8.73e-05 rad/s/√Hz", "0.655 m"]
RANGING_FIGURES = ["6.5", "285.6", "292.1", "≈ 7.4", "0.027", "1640 nodes", "h = 1.53 mm",
                   "2.0 MB", "9.07e-05", "X = 0.295 m", "0.1709"]


@pytest.mark.parametrize("figure", SENSOR_FIGURES)
def test_sensor_stats_figures(sensor_stats, figure):
    assert figure in sensor_stats, f"examples/sensor_stats.py no longer prints {figure!r}"
    assert figure in PAGE, f"{PAGE_PATH} no longer quotes {figure!r}"


def test_echo_error_table(sensor_stats):
    """The echo-error table: mean and std at σ = 0.05 m for the rayleigh, seed and gaussian models."""
    for model, page_row in (("rayleigh (sign -1)", "−0.0299 m, 0.0328 m"), ("seed", "+0.0299 m, 0.0328 m"),
                              ("gaussian", "0, 0.0500 m")):
        line = next(x for x in sensor_stats.splitlines() if x.strip().startswith(model) and " 0.05 " in x)
        mean, std = map(float, re.search(r"([+-]\d\.\d{4}) ± (\d\.\d{4})", line).groups())
        assert page_row in PAGE, f"{PAGE_PATH} no longer has the row {page_row!r}"
        want_mean = 0.0 if page_row.startswith("0,") else float(page_row.split(" m")[0].replace("−", "-"))
        assert abs(mean - want_mean) < 5e-5 and f"{std:.4f} m" in page_row


@pytest.mark.parametrize("figure", RANGING_FIGURES)
def test_ranging_stats_figures(ranging_stats, figure):
    assert figure in ranging_stats, f"examples/ranging_stats.py no longer prints {figure!r}"
    assert figure in PAGE, f"{PAGE_PATH} no longer quotes {figure!r}"


def test_ranging_table(ranging_stats):
    """Each page row `| X m | mean ± std m | mean ± std m | ratio |` within rounding of the analytic output."""
    out = {}
    for line in ranging_stats.splitlines():
        m = re.match(r"\s*(\d\.\d\d) \|\s+(\d\.\d{4}) ± (\d\.\d{4}).*\|\s+(\d\.\d{4}) ± (\d\.\d{4}).*\|\s+(\d\.\d\d) \|",
                     line)
        if m:
            out[float(m.group(1))] = [float(v) for v in m.groups()[1:]]
    rows = re.findall(r"^\| (\d\.\d) m \| (\d\.\d{3}) ± (\d\.\d{3}) m \| (\d\.\d{3}) ± (\d\.\d{3}) m \| (\d\.\d\d) \|$",
                      PAGE, flags=re.M)
    assert len(rows) == 5 and set(out) == {float(r[0]) for r in rows}
    for r in rows:
        got = out[float(r[0])]
        for quoted, printed in zip(map(float, r[1:5]), got[:4]):
            assert abs(quoted - printed) <= 0.0005 + 1e-9
        assert float(r[5]) == got[4]
