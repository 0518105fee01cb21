"""Convert Parlow's virtual-ranging mixture from cm / cm² to m / m².

Usage (from the repository root)::

    python finkensim/data/convert_vranging_gmm.py ../shared/data/vranging_gmm.json \
        [-o finkensim/data/vranging_gmm_m.json]

The input is the decoded table file described in ``../shared/data/README.md`` (one object per
Lua table, ``values`` in cm and cm²). The output holds the same five arrays as plain JSON lists in
metres (distances divided by 100, variances by 10 000), together with the source information and
the units. The decimal point is shifted exactly (``decimal.Decimal``), so every converted number is
the original digit string scaled by a power of ten, with no binary rounding noise added.
"""
from __future__ import annotations

import argparse
import json
from decimal import Decimal
from pathlib import Path

ARRAYS = {
    # name: (power of ten to divide by, description)
    "weights": (0, "prior mixing weight of each component (dimensionless); sums to 1 within 1e-12"),
    "mean": (2, "mean of the TRUE distance X of each component, m"),
    "covar": (4, "variance of the TRUE distance X of each component, m^2"),
    "cond_mean": (2, "mean of the MEASURED distance of each component, m (no slope: diagonal covariances)"),
    "cond_covar": (4, "variance of the MEASURED distance given X of each component, m^2 "
                      "(8 entries are 1e-7 m^2 = 0.001 cm^2: near-degenerate components)"),
}


def _scale(value: float, power: int) -> float:
    """``value / 10**power`` by shifting the decimal point of its shortest repr (exact in decimal)."""
    return float(Decimal(repr(float(value))).scaleb(-power))


def convert(src: dict) -> dict:
    """The metre version of the decoded cm mixture ``src`` (the parsed shared JSON)."""
    units = src.get("units", {})
    if units.get("distance") != "cm" or units.get("variance") not in ("cm^2", "cm²"):
        raise ValueError(f"expected units cm / cm^2 in the input, got {units!r}")
    k = int(src["n_components"])
    out: dict = {
        "format": "finkensim ranging mixture v1",
        "source": dict(src["source"]),
        "converted_from": "shared/data/vranging_gmm.json (decoded from the scene; units cm, cm^2)",
        "conversion": "distances / 100, variances / 10000, weights unchanged; "
                      "made by finkensim/data/convert_vranging_gmm.py",
        "n_components": k,
        "covariance_type": "diag",
        "units": {"distance": "m", "variance": "m^2"},
        "arrays": {name: desc for name, (_, desc) in ARRAYS.items()},
    }
    for name, (power, _) in ARRAYS.items():
        values = src[name]["values"] if isinstance(src[name], dict) else src[name]
        if len(values) != k:
            raise ValueError(f"{name}: expected {k} values, got {len(values)}")
        out[name] = [_scale(v, power) for v in values]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", type=Path, help="shared/data/vranging_gmm.json (cm, cm^2)")
    ap.add_argument("-o", "--output", type=Path, default=Path(__file__).with_name("vranging_gmm_m.json"))
    args = ap.parse_args(argv)
    data = convert(json.loads(args.source.read_text()))
    args.output.write_text(json.dumps(data, indent=1) + "\n")
    print(f"wrote {args.output} ({data['n_components']} components, m / m^2)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
