"""``python -m benchmarks.run --quick`` runs end to end (no timing assertions), and the two
implementations of the comparison workload agree."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def test_bench_quick_runs(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, "-m", "benchmarks.run", "--quick", "--out", str(tmp_path)], cwd=ROOT,
                       env=env, capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    md = (tmp_path / "bench.md").read_text()
    assert "(a) Comparison workload" in md and "Scaling at fixed density" in md
    res = json.loads((tmp_path / "bench.json").read_text())
    assert res["meta"]["quick"] is True
    assert {(r["N"], r["B"]) for r in res["compare"]} == {(4, 1), (4, 64), (10, 1), (10, 64)}
    for r in res["compare"]:
        for impl in ("finkensim", "numpy"):
            assert r[impl]["env_steps_per_s"] > 0 and r[impl]["peak_bytes_per_env"] > 0
    assert [r["N"] for r in res["scaling"]["rows"]] == [10, 100]
    assert (tmp_path / "scaling.png").exists()
    assert "finkensim / NumPy" in p.stdout


def test_comparison_workload_numba_equals_numpy():
    from benchmarks.workloads import CompareWorkload

    for n, b in ((1, 2), (4, 3), (10, 5)):
        a, c = CompareWorkload(n, b, "finkensim", seed=7), CompareWorkload(n, b, "numpy", seed=7)
        for _ in range(5):
            a.run(3)
            c.run(3)
            np.testing.assert_allclose(a.pos, c.pos, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.sonar, c.sonar, rtol=0, atol=1e-9)
            np.testing.assert_allclose(a.dist, c.dist, rtol=0, atol=1e-9)
        assert np.all(a.sonar <= 3.0) and np.all(a.sonar >= 0.0)
