"""How well do the Esso Osaka data determine the hull coefficients mmg_identified_D2 moves?

Identifies the coefficients of configs/experiments/mmg_identified_D2.toml (X'vr, Y'v, Y'r,
N'v, N'r) on the D2 training files by Levenberg-Marquardt on the multi-step loss (Euler,
1 Hz, T-step windows, velocity weights 1/variance, as in training, but with disjoint
windows so that the sandwich sigma is valid), starting from the ship file's values, and
prints estimate +- 2 sigma beside the prior, the correlations and the weak directions.

    python benchmarks/esso_identified_uncertainty.py [--steps 5] [--data DIR]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import torch

from sysid import MMG, load_ship
from sysid.data.recordings import duplicate_runs, read_run, sliding_windows, stack_windows, window_touches
from sysid.data.datasets import training_files
from sysid.identify.uncertainty import coefficient_uncertainty, velocity_weights

sys.path.insert(0, str(Path(__file__).resolve().parent))
from identification_kvlcc2 import identify  # noqa: E402

NAMES = ["X_vr", "Y_v", "Y_r", "N_v", "N_r"]


def d2_windows(steps: int, data: str | None = None) -> SimpleNamespace:
    """Disjoint windows of steps+1 samples from the D2 files (copies and frozen-GNSS
    stretches left out): states (steps+1, W, 6), inputs (steps+1, W, 4), dt = 1 s."""
    runs = [read_run(p) for p in training_files("D2", data)]
    copies = {b for _, b in duplicate_runs(runs)}
    states, inputs = [], []
    for run in runs:
        if run.name in copies:
            continue
        starts = sliding_windows(len(run), steps + 1, steps + 1)
        starts = starts[~window_touches(run, starts, steps + 1)]
        s, i = stack_windows(run, starts, steps + 1)
        states.append(s)
        inputs.append(i)
    return SimpleNamespace(states=torch.cat(states, 1), inputs=torch.cat(inputs, 1), dt=1.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5, help="window length T [s] (training: 5)")
    parser.add_argument("--data", default=None, help="FRT-DS-ESSO directory (default: SYSID_DATA / ../shared)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    ship = load_ship("esso_osaka")
    windows = d2_windows(args.steps, args.data)
    weights = velocity_weights(windows.states)
    prior = {n: ship[n] for n in NAMES}
    estimate, iterations = identify(ship, windows, NAMES, prior, weights, method="euler")
    fitted = MMG(ship)
    fitted.coefficients.assign(estimate)
    print(f"D2, {windows.states.shape[1]} disjoint {args.steps}-s windows, {iterations} LM iterations")
    for form in ("sandwich", "gauss_newton"):
        res = coefficient_uncertainty(fitted, windows, NAMES, weights, "euler", covariance=form)
        print(f"\n{form}:")
        print(res.table(prior))
    print("\ncorrelations (sandwich):")
    res = coefficient_uncertainty(fitted, windows, NAMES, weights, "euler")
    print("       " + " ".join(f"{n:>6}" for n in NAMES))
    for i, n in enumerate(NAMES):
        print(f"{n:>6} " + " ".join(f"{res.correlation[i, j]:6.2f}" for j in range(len(NAMES))))
    print("weak directions:", res.weak_directions)
    print("relative sigma:", dict(zip(NAMES, np.round(res.std_error / np.abs(res.estimate), 3))))


if __name__ == "__main__":
    main()
