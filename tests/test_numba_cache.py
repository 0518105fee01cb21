"""One kernel cache for every entry point (finkensim.numba_cache), and the progress bar's compiling notice."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from finkensim.numba_cache import HASH_CHARS, prune, source_hash

ROOT = Path(__file__).resolve().parents[1]


def _python(code: str, env_updates: dict, drop=("NUMBA_CACHE_DIR",)) -> dict:
    """Run ``code`` in a fresh interpreter with the repository first on the path; its last stdout line as JSON."""
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env.update(PYTHONPATH=str(ROOT), **env_updates)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_source_hash_follows_every_file(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "notes.txt").write_text("not a source")
    first = source_hash(tmp_path)
    assert source_hash(tmp_path) == first
    (tmp_path / "notes.txt").write_text("changed, still not a source")
    assert source_hash(tmp_path) == first
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")  # a callee in another module changes
    assert source_hash(tmp_path) != first


def test_prune_deletes_only_stale_version_directories(tmp_path):
    day = 86400.0
    now = 1_000 * day
    keep, fresh, stale = (tmp_path / (c * HASH_CHARS) for c in "abc")
    other = tmp_path / "not-a-version"  # a name that is no source hash: never touched
    for path in (fresh, stale, other):
        path.mkdir()
        (path / "kernel.nbi").write_text("x")
    os.utime(fresh, (now - 29 * day, now - 29 * day))
    os.utime(stale, (now - 31 * day, now - 31 * day))
    os.utime(other, (now - 99 * day, now - 99 * day))
    assert prune(keep, max_age_days=30, now=now) == [stale]
    assert keep.is_dir() and keep.stat().st_mtime == now  # chosen = marked used
    assert fresh.is_dir() and other.is_dir() and not stale.exists()


_WHERE = ("import json, os, sys; import finkensim; from finkensim.numba_cache import source_hash; "
          "print(json.dumps(dict(dir=os.environ['NUMBA_CACHE_DIR'], numba='numba' in sys.modules, "
          "hash=source_hash())))")


def test_import_chooses_the_cache_without_importing_numba(tmp_path):
    got = _python(_WHERE, {"XDG_CACHE_HOME": str(tmp_path)})
    assert not got["numba"], "import finkensim imported numba"
    assert got["dir"] == str(tmp_path / "finkensim" / "numba" / got["hash"])


def test_the_users_cache_dir_wins(tmp_path):
    got = _python(_WHERE, {"NUMBA_CACHE_DIR": str(tmp_path / "mine")}, drop=())
    assert got["dir"] == str(tmp_path / "mine")


def test_numba_imported_first_gets_the_cache_too(tmp_path):
    got = _python("import json, numba; import finkensim; from numba.core import config; "
                  "print(json.dumps(dict(dir=str(config.CACHE_DIR))))", {"XDG_CACHE_HOME": str(tmp_path)})
    assert got["dir"].startswith(str(tmp_path / "finkensim" / "numba"))


_FIRST_CALL = """
import json
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

def first_call():
    from finkensim.compiletime import compile_timer
    from finkensim.kernels.rng import uniforms_array
    with compile_timer() as jit:
        uniforms_array(1, 0, 0, 0, 0, 3)
    return jit.kernels

if __name__ == "__main__":
    from finkensim.sweep.executors import dask_client

    here = first_call()
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        worker = pool.submit(first_call).result()
    client, cluster = dask_client(1, None)  # a LocalCluster of one worker process, as a Dask sweep starts it
    try:
        dask_worker = client.submit(first_call, pure=False).result()
    finally:
        client.close()
        cluster.close()
    print(json.dumps(dict(here=here, worker=worker, dask_worker=dask_worker)))
"""


def test_every_process_loads_what_one_compiled(tmp_path):
    """A fresh cache: the first process compiles; the next process, a spawned pool worker and a Dask worker only
    load (counted by numba's compile events, :func:`finkensim.compiletime.compile_timer`, not by the clock)."""
    script = tmp_path / "first_call.py"
    script.write_text(_FIRST_CALL)
    code = f"import runpy; runpy.run_path({str(script)!r}, run_name='__main__')"
    first = _python(code, {"XDG_CACHE_HOME": str(tmp_path / "cache")})
    assert first["here"] >= 1 and first["worker"] == 0 and first["dask_worker"] == 0
    again = _python(code, {"XDG_CACHE_HOME": str(tmp_path / "cache")})
    assert again == {"here": 0, "worker": 0, "dask_worker": 0}


class _Bar:
    """The parts of a tqdm bar that compiling_notice uses."""

    def __init__(self):
        self.desc, self.shown, self.unpaused = "flight", [], 0

    def set_description_str(self, desc, refresh=True):
        self.desc = desc
        self.shown.append(desc)

    def unpause(self):
        self.unpaused += 1


def test_progress_bar_says_compiling_instead_of_an_eta():
    from numba import njit

    from finkensim.compiletime import COMPILING, compiling_notice

    @njit  # not cached: compiles at its first call
    def add(a, b):
        return a + b

    bar = _Bar()
    with compiling_notice(bar):
        add(1, 2)
        add(3, 4)  # compiled already: no notice
    assert bar.shown == [COMPILING, "flight"] and bar.unpaused == 1
    assert COMPILING == "compiling (first run only)…"


#: the default scenario with a small diagnosis (one candidate effect, CI-sized draws): the compile command's gap job
#: runs the same code as with the whole catalogue, at a fraction of the fitting
SMALL_GAP_SCENARIO = """
[gap]
effects = ["sonar_bias"]
draws = 12
max_samples_per_flight = 300
fit_max_readings = 5000
n_boot = 200
"""


def test_compile_command_runs_its_jobs(capsys, tmp_path):
    """finkensim compile --gap on one worker process (the suite's cache; compiling in the test process itself would
    leave freshly compiled LLVM modules that later tests of the process see): one line per job or kernel, exit 0."""
    from finkensim.cli import main
    from finkensim.default_scenario import DEFAULT_SCENARIO_TOML

    scenario = tmp_path / "small_gap.toml"
    scenario.write_text(DEFAULT_SCENARIO_TOML + SMALL_GAP_SCENARIO)
    assert main(["compile", str(scenario), "--workers", "1", "--gap"]) == 0
    out = capsys.readouterr().out
    assert "3 jobs (closed loop, flight log and figures, gap diagnosis)" in out and "kernels compiled in" in out
    assert main(["compile", "--workers", "-1"]) == 2
    assert "--workers -1: expected 0 (this process) or a positive number" in capsys.readouterr().err


def test_a_job_that_needs_another_ones_kernels_runs_after_it():
    """``compile_kernels(after=...)``: a job that calls another's kernels too (the diagnosis's warm-up flies the
    closed loop) starts once that one has finished, so that two processes never compile the same kernel side by side;
    in this process (workers=0) it runs after it whatever the jobs' order."""
    from finkensim.config import load_config
    from finkensim.precompile import compile_kernels

    ran = []
    jobs = {"second": lambda cfg: ran.append("second"), "first": lambda cfg: ran.append("first"),
            "alone": lambda cfg: ran.append("alone")}
    results = list(compile_kernels(load_config(), workers=0, jobs=jobs, setup=None, after={"second": "first"}))
    assert ran == ["first", "alone", "second"] == [r.job for r in results]
    ran.clear()
    list(compile_kernels(load_config(), workers=0, jobs=jobs, setup=None, after={"second": "missing"}))
    assert ran == ["second", "first", "alone"]  # a prerequisite that is not a job is ignored
