"""The output directory of a sweep: one Parquet part per finished run (written atomically), resume,
the sweep.json fingerprint check, and reading the results table back.

- ``parts/run-XXXXX.parquet`` — one row per finished run, written atomically (temp file + rename)
  as soon as the run ends; ``resume=True`` runs only the runs whose part is missing.
- ``sweep.json`` — the design and its fingerprint (``resume`` refuses a directory of another sweep).
- ``results.parquet``, ``summary.csv``, ``summary.png`` — written when the sweep ends.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from .. import __version__
from ..atomic import write_atomic
from .parsing import SweepError
from .summary import plot_summary, summarize
from .tables import column_value

if TYPE_CHECKING:
    from .design import Sweep


def _part_path(parts: Path, run_id: int) -> Path:
    """The part file of run ``run_id`` in the folder ``parts``."""
    return parts / f"run-{run_id:05d}.parquet"


def write_part(parts: Path, row: Mapping[str, Any], schema) -> None:
    """Write the results ``row`` of one run (pyarrow ``schema``) as its part in the folder ``parts``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist([dict(row)], schema=schema)
    write_atomic(_part_path(parts, row["run_id"]), lambda p: pq.write_table(table, p))


def read_parts(parts: Path, sweep: Sweep, schema) -> dict[int, dict]:
    """Rows of the parts present in ``parts`` (unreadable or foreign parts are skipped with a warning)."""
    import pyarrow.parquet as pq

    rows: dict[int, dict] = {}
    if not parts.is_dir():
        return rows
    for path in sorted(parts.glob("run-*.parquet")):
        try:
            run_id = int(path.stem.split("-", 1)[1])
            table = pq.read_table(path)
            row = table.to_pylist()[0]
            if row["run_id"] != run_id or run_id >= sweep.n_runs or table.schema.names != schema.names:
                raise ValueError("it does not belong to this sweep")
        except Exception as exc:  # noqa: BLE001 (any unreadable part is run again, never trusted)
            warnings.warn(f"ignoring {path} ({exc}); its run will be run again", RuntimeWarning, stacklevel=3)
            continue
        rows[run_id] = row
    return rows


def prepare_out(out: Path, sweep: Sweep, resume: bool, overwrite: bool) -> None:
    """Make ``out`` ready for ``sweep``: refuse (SweepError) or clear results of another or a finished sweep as
    ``resume`` / ``overwrite`` say, remove stale temporary parts, write ``sweep.json``."""
    parts = out / "parts"
    meta = out / "sweep.json"
    existing = sorted(parts.glob("run-*.parquet")) if parts.is_dir() else []
    outputs = [out / n for n in ("results.parquet", "summary.csv", "summary.png")]
    fingerprint = sweep.fingerprint()
    if resume and (existing or meta.exists()):
        try:
            old = json.loads(meta.read_text())["fingerprint"]
        except (OSError, ValueError, KeyError, TypeError):
            old = None
        if old != fingerprint and not overwrite:
            raise SweepError(f"{out} holds results of a different sweep (its sweep.json does not match "
                             f"{sweep.source}); choose another --out or pass --overwrite to start again")
        if old != fingerprint:
            resume = False
    if not resume and (existing or any(p.exists() for p in outputs)):
        if not overwrite:
            raise SweepError(f"{out} already holds results of a sweep ({len(existing)} finished runs); pass --resume "
                             "to finish it, --overwrite to start again, or choose another --out")
        for p in existing + [p for p in outputs if p.exists()]:
            p.unlink()
    try:
        parts.mkdir(parents=True, exist_ok=True)
        for stale in parts.glob(".run-*.tmp-*"):
            stale.unlink()
        info = {"fingerprint": fingerprint, "finkensim": __version__, "source": sweep.source,
                "description": sweep.description, "design": sweep.design, "parameters": list(sweep.parameters),
                "variants": {f: {n: {k: column_value(v) for k, v in lv.items()} for n, lv in levels.items()}
                             for f, levels in sweep.variants.items()},
                "combinations": [{k: column_value(v) for k, v in c.items()} for c in sweep.combinations],
                "replicates": sweep.replicates, "seed": sweep.seed, "duration": sweep.duration,
                "metrics": list(sweep.metrics), "n_runs": sweep.n_runs, "sweep_toml": sweep.text,
                "base_config": sweep.base.to_dict()}
        write_atomic(meta, lambda p: p.write_text(json.dumps(info, indent=1, default=str)))
    except OSError as exc:
        raise SweepError(f"cannot write to output directory {str(out)!r}: {exc.strerror or exc}") from None


def write_outputs(out: Path, sweep: Sweep, table, results) -> None:
    """Write ``results.parquet`` (the pyarrow ``table``), then ``summary.csv`` and ``summary.png`` (from the
    same table as the DataFrame ``results``) into ``out``, each atomically."""
    import pyarrow.parquet as pq

    write_atomic(out / "results.parquet", lambda p: pq.write_table(table, p))
    summary = summarize(results, sweep.parameters, sweep.metrics)
    write_atomic(out / "summary.csv", lambda p: summary.to_csv(p, index=False))
    fig = plot_summary(summary, sweep.parameters, sweep.metrics)
    from ..viz import save_png  # a 256-colour palette PNG: the same picture at about a third of the size

    write_atomic(out / "summary.png", lambda p: save_png(fig, p, dpi=110))


def load_results(out: str | Path):
    """The results table of a finished sweep directory (``out/results.parquet``) as a DataFrame."""
    import pandas as pd

    return pd.read_parquet(Path(out) / "results.parquet")
