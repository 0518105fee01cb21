"""Sweep workers end with the sweep process, by any signal; SIGTERM is handled like Ctrl-C (issue 13 item 5).

Real subprocesses: ``finkensim sweep`` is started, its worker processes are found in /proc, the sweep
is killed, and every process it started must be gone within a bounded polling wait (no speed assertion).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

WAIT_S = 120.0  # bound on every polling wait (cold numba caches on a shared 2-core machine are slow)
SWEEP = """\
replicates = {reps}
duration = {duration}
seed = 3
[base.copters]
n = 3
[base.behaviour]
kind = "random_walk"
[grid]
"behaviour.speed" = [0.2, 0.3]
"""


def _children(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (from /proc)."""
    parent_of = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if fields[0] != "Z":
                parent_of[int(entry)] = int(fields[1])
    out, frontier = set(), {pid}
    while frontier:
        frontier = {c for c, p in parent_of.items() if p in frontier} - out
        out |= frontier
    return out


def _alive(pids) -> set[int]:
    alive = set()
    for p in pids:
        try:
            state = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.add(p)
    return alive


def _wait(cond, what: str):
    t0 = time.monotonic()
    while time.monotonic() - t0 < WAIT_S:
        value = cond()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"gave up waiting ({WAIT_S:.0f} s) for {what}")


def _start(tmp_path: Path, executor: str, reps: int, duration: float, extra=()):
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP.format(reps=reps, duration=duration))
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "finkensim.cli", "sweep", str(sweep), "--out", str(out), "--executor", executor,
            "--workers", "2" if executor == "process" else "1", "--no-progress", *extra]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, argv, out


@pytest.mark.parametrize("executor, n_workers", [("process", 2), ("dask", 1)])
def test_sigkill_of_the_sweep_ends_its_workers(tmp_path, executor, n_workers):
    proc, _, _ = _start(tmp_path, executor, reps=50, duration=20.0)
    kids: set[int] = set()
    try:
        kids = _wait(lambda: len(_children(proc.pid)) >= n_workers + 1,
                     f"{n_workers} workers of the {executor} sweep")
        time.sleep(1.0)  # let the workers finish starting (initializer / client.run)
        kids = _children(proc.pid)
        proc.kill()
        proc.wait(10)
        _wait(lambda: not _alive(kids), f"the workers {sorted(_alive(kids))} to end after SIGKILL of the sweep")
    finally:
        if proc.poll() is None:
            proc.kill()
        for p in _alive(kids | _children(proc.pid)):  # never leave orphans behind, even when the test fails
            os.kill(p, signal.SIGKILL)


def test_sigterm_keeps_finished_parts_exits_nonzero_and_resume_finishes(tmp_path):
    proc, argv, out = _start(tmp_path, "process", reps=40, duration=1.0)
    try:
        _wait(lambda: list((out / "parts").glob("run-*.parquet")) if (out / "parts").is_dir() else None,
              "the first finished run")
        kids = _children(proc.pid)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=WAIT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "terminated (SIGTERM); finished runs are kept" in stderr and "Traceback" not in stderr
    _wait(lambda: not _alive(kids), "the workers to end after SIGTERM")
    parts = list((out / "parts").glob("run-*.parquet"))
    assert parts and not list((out / "parts").glob("*.tmp"))
    n_kept = len(parts)
    done = subprocess.run(argv + ["--resume"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert f"({n_kept} already done)" in done.stdout or n_kept == 80
    df = pd.read_parquet(out / "results.parquet")
    assert len(df) == 80 and (df["status"] == "ok").all()
