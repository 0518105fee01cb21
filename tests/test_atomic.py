"""Atomic outputs (issue 13): a writer that fails midway leaves nothing under the final name, and no
temporary file either; a successful write replaces the old file whole."""
from __future__ import annotations

import os

import numpy as np
import pytest

from finkensim.atomic import atomic_path, temp_beside, write_atomic


class Boom(RuntimeError):
    pass


def _half_then_raise(path, *args, **kwargs):
    with open(path, "wb") as fh:
        fh.write(b"PARTIAL" * 100)
    raise Boom("disk full")


def test_write_atomic_leaves_nothing_when_the_writer_fails(tmp_path):
    target = tmp_path / "data.csv"
    with pytest.raises(Boom):
        write_atomic(target, _half_then_raise)
    assert list(tmp_path.iterdir()) == []
    target.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("new, half")
            raise KeyboardInterrupt
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["data.csv"]
    write_atomic(target, lambda p: p.write_text("new"))
    assert target.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["data.csv"]
    tmp = temp_beside(tmp_path / "a.png")
    assert tmp.parent == tmp_path and tmp.suffix == ".png" and tmp.name.startswith(".a.")


def test_flight_log_save_is_atomic(tmp_path, monkeypatch):
    from finkensim import flightlog

    T, N = 5, 2
    log = flightlog.FlightLog(t=0.1 * np.arange(T), arena=np.array([3.0, 4.0]), pose=np.full((T, N, 3), 1.0),
                              copter_ids=np.array(["a", "b"]))
    monkeypatch.setattr(np, "savez_compressed", lambda f, **kw: (f.write(b"PK\x03\x04half"), _raise()))
    with pytest.raises(Boom):
        flightlog.save(log, tmp_path / "flight.npz")
    assert list(tmp_path.iterdir()) == []


def _raise():
    raise Boom("killed midway")


@pytest.mark.parametrize("colors", [None, 256])
def test_png_is_atomic(tmp_path, monkeypatch, colors):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from finkensim.viz import save_png

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    if colors is None:
        monkeypatch.setattr(fig, "savefig", _half_then_raise)
    else:
        real_save = Image.Image.save
        monkeypatch.setattr(Image.Image, "save", lambda self, fp, *a, **k: _half_then_raise(fp)
                            if isinstance(fp, (str, os.PathLike)) else real_save(self, fp, *a, **k))
    with pytest.raises(Boom):
        save_png(fig, tmp_path / "fig.png", colors=colors)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    assert save_png(fig, tmp_path / "fig.png", colors=colors).is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]
    plt.close(fig)


def test_sweep_outputs_are_atomic(tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    from finkensim.sweep import run_sweep

    sweep = "replicates = 1\nduration = 0.2\n[base.copters]\nn = 2\n[grid]\n\"behaviour.speed\" = [0.2]\n"
    calls = []

    def write_table(table, where, *a, **k):
        calls.append(where)
        if len(calls) == 2:  # the part is written, results.parquet fails midway
            _half_then_raise(where)
        return real(table, where, *a, **k)

    real = pq.write_table
    monkeypatch.setattr(pq, "write_table", write_table)
    with pytest.raises(Boom):
        run_sweep(sweep, tmp_path / "out", executor="serial", progress=False)
    names = sorted(p.name for p in (tmp_path / "out").rglob("*"))
    assert "results.parquet" not in names and not [n for n in names if ".tmp" in n]
    assert "run-00000.parquet" in names  # the finished run's part is kept (whole)


def test_gap_validate_trial_log_is_rewritten_whole_and_resumes(tmp_path, monkeypatch):
    import json

    import finkensim.gap.validation.sweep as vs

    calls = []

    def fake_run_case(case, seed, n_flights=2, duration=60.0, conventions=None):
        calls.append((case, seed))
        if len(calls) == 4:
            raise Boom("killed during the fourth trial")
        return {"case": case, "seed": seed, "named": case}

    monkeypatch.setattr(vs, "run_case", fake_run_case)
    log = tmp_path / "trials.jsonl"
    args = (["null", "foreign"], 2, 0, 2, 60.0, "default", tmp_path)
    with pytest.raises(Boom):
        vs.run_trials(*args)
    assert [json.loads(line)["seed"] for line in log.read_text().splitlines()] == [0, 0, 1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["provenance.jsonl", "trials.jsonl"]  # no temporary file left
    rows = vs.run_trials(*args)
    assert [(r["case"], r["seed"]) for r in rows] == [("null", 0), ("foreign", 0), ("null", 1), ("foreign", 1)]
    assert calls[4:] == [("foreign", 1)]  # only the missing trial ran again
