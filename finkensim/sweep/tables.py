"""The results table: its fixed columns, its Arrow schema and one row per run.

Columns: ``run_id, combination, <parameters>, replicate, seed, <metrics>, status ("ok" / "error"),
error (exception text), elapsed (s)``.
"""
from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any, Mapping

from .parsing import is_number
from .keys import Run

if TYPE_CHECKING:
    from .design import Sweep

RESULT_COLUMNS = ("run_id", "combination", "replicate", "seed", "status", "error", "elapsed")
"""The columns every results table has besides the parameters and the metrics."""


def arrow_schema(sweep: Sweep):
    """The pyarrow schema of the results table of ``sweep``: ``run_id, combination, <parameters>, replicate,
    seed, <metrics>, status, error, elapsed``; a parameter column is bool, int64, float64 or string."""
    import pyarrow as pa

    fields = [pa.field("run_id", pa.int64()), pa.field("combination", pa.int64())]
    for key in sweep.parameters:
        vals = [c[key] for c in sweep.combinations]
        if all(isinstance(v, bool) for v in vals):
            t = pa.bool_()
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
            t = pa.int64()
        elif all(is_number(v) for v in vals):
            t = pa.float64()
        else:
            t = pa.string()
        fields.append(pa.field(key, t))
    fields += [pa.field("replicate", pa.int64()), pa.field("seed", pa.int64())]
    fields += [pa.field(m, pa.float64()) for m in sweep.metrics]
    fields += [pa.field("status", pa.string()), pa.field("error", pa.string()), pa.field("elapsed", pa.float64())]
    return pa.schema(fields)


def column_value(v):
    """A parameter value as a results column holds it (a tuple as its JSON list text)."""
    return json.dumps(list(v)) if isinstance(v, tuple) else v


def result_row(run: Run, result: Mapping[str, Any], sweep: Sweep) -> dict[str, Any]:
    """The results row of ``run`` from its worker ``result`` (metrics, status, error, elapsed)."""
    row = {"run_id": run.run_id, "combination": run.combination}
    row.update({k: column_value(run.params[k]) for k in sweep.parameters})
    row.update({"replicate": run.replicate, "seed": run.seed})
    row.update({m: result[m] for m in sweep.metrics})
    row.update({"status": result["status"], "error": result["error"], "elapsed": result["elapsed"]})
    return row

