"""``python -m finkensim.datasets OUT_DIR [NAME ...]``: write each public recording as the importer's CSV pair.

For every dataset (default: all three) it writes ``OUT_DIR/<name>/track.csv`` and ``read.csv``, prints a summary
line, the truth the dataset gives per reading (median and 5-95 % of reading − truth, and the median per link), and the ``finkensim import``
command that reads the files unchanged. Exit code 2 with a one-line message when the data are absent or corrupt.
"""
from __future__ import annotations

import shlex
import sys
from pathlib import Path

import numpy as np

from . import LOADERS, DatasetError


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return 0 if argv else 2
    out, names = Path(argv[0]), argv[1:] or list(LOADERS)
    unknown = [n for n in names if n not in LOADERS]
    if unknown:
        print(f"finkensim.datasets: error: unknown dataset {unknown[0]!r}; known: {', '.join(LOADERS)}", file=sys.stderr)
        return 2
    for name in names:
        try:
            ds = LOADERS[name]()
        except DatasetError as exc:
            print(f"finkensim.datasets: error: {exc}", file=sys.stderr)
            return 2
        args = ds.write_csv(out / name)
        err = (ds.truth["value"] - ds.truth["truth"]).to_numpy()
        q5, q50, q95 = np.quantile(err, [0.05, 0.5, 0.95])
        print(ds.summary())
        print(f"  reading - truth: median {q50:+.3f} m, 5-95 % {q5:+.3f} ... {q95:+.3f} m")
        per = ds.truth.assign(err=err).groupby(["copter", "channel"])["err"].median()
        print("  per link, median reading - truth (m): " + ", ".join(
            f"{c}->{ch.split('/', 1)[1]} {v:+.3f}" for (c, ch), v in per.items()))
        print("  finkensim import " + " ".join(shlex.quote(a) for a in args)
              + f" --out {shlex.quote(str(out / name / 'flight.npz'))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
