"""How precisely two short flights pin the tracking noise: the ``pose_noise`` case's σ_xy fitted on its training
readings and on all readings, with more or fewer predictive draws per reading.

    python examples/pose_noise_precision.py 104 --draws 8 32
    python examples/pose_noise_precision.py 104 --draws 24 --grid 19 27 17    # the objective on a grid (mm)

If the best σ_xy moves with the number of draws, the Monte-Carlo objective limits the fit; if it stays, the flights
themselves say that value (docs/calibration.md, ``pose_noise``). σ_yaw is held at the value the case's logs state.
"""
from __future__ import annotations

import argparse

from scipy import optimize

from finkensim.gap.attribute import effects as fx
from finkensim.gap.diagnosis import Diagnosis
from finkensim.gap.validation.cases import generate, get_case


def objective(seed: int, draws: int, rows: str, duration: float = 30.0):
    """(f, true σ_xy m): f(σ_xy m) the training score of the ``pose_noise`` case at ``seed`` (two flights of
    ``duration`` s, default conventions) on the ``rows`` ("fit" or "all"), ``draws`` predictive draws per reading,
    σ_yaw at the value the logs state."""
    logs, cfg, truth = generate(get_case("pose_noise"), seed, n_flights=2, duration=duration)
    diag = Diagnosis(logs, ["a.npz", "b.npz"], cfg.replace({"gap.draws": draws}))
    effect = fx.REGISTRY["pose_noise"]
    sensors = [s for s in effect.sensors if s in diag.tables]
    if rows == "all":
        diag.rows_fit = diag.rows_all  # the objective scores the training rows: make them all rows
    sigma_yaw = float(diag.flights[0].sigma_yaw)
    return (lambda x: diag.objective(effect, diag.base, sensors, {"sigma_xy": float(x), "sigma_yaw": sigma_yaw}),
            float(truth["sigma_xy"]))


def best_sigma_xy(seed: int, draws: int, rows: str, duration: float = 30.0) -> tuple[float, float]:
    """(fitted σ_xy m, true σ_xy m): :func:`objective` minimised over σ_xy ∈ [0.5, 2]·truth (bounded Brent)."""
    f, true = objective(seed, draws, rows, duration)
    res = optimize.minimize_scalar(f, bounds=(0.5 * true, 2.0 * true), method="bounded", options={"xatol": 2e-5})
    return float(res.x), true


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seeds", type=int, nargs="+", help="seeds of the pose_noise case")
    ap.add_argument("--draws", type=int, nargs="+", default=[8, 32], help="predictive draws per reading")
    ap.add_argument("--grid", type=float, nargs=3, metavar=("LO", "HI", "N"),
                    help="print the objective at N values of sigma_xy from LO to HI mm instead of fitting")
    args = ap.parse_args()
    if args.grid:
        import numpy as np

        for seed in args.seeds:
            for draws in args.draws:
                f, true = objective(seed, draws, "fit")
                for x in np.linspace(args.grid[0], args.grid[1], int(args.grid[2])):
                    print(f"seed {seed}, {draws} draws, fit rows: sigma_xy {x:.2f} mm: {f(x / 1000):.6f} "
                          f"(truth {true * 1000:.2f} mm)", flush=True)
        return
    for seed in args.seeds:
        for draws in args.draws:
            for rows in ("fit", "all"):
                got, true = best_sigma_xy(seed, draws, rows)
                print(f"seed {seed}, {draws} draws, {rows} rows: sigma_xy {got * 1000:.2f} mm "
                      f"(truth {true * 1000:.2f} mm, {100 * (got / true - 1):+.1f} %)", flush=True)


if __name__ == "__main__":
    main()
