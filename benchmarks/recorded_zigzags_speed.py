"""The recorded zig-zags' closed-loop runs of trained models (what `sysid reproduce` and
``maneuver_indices.csv`` compute for each model): one row at a time, each zig-zag its own
rollout (`simulate_maneuvers` per run, as before session 16), against all of a model's
zig-zags as rows of one batched rollout (`simulate_rows`), side by side in one run, with
the largest difference of their indices.

    python benchmarks/recorded_zigzags_speed.py /tmp/repro5/runs/hybrid_D2/seed0 /tmp/repro5/runs/hybrid_ensemble_D2

Each model: `--repeats` timings of each way, alternating, the median printed; one torch
thread. A mean-of-seeds ensemble of hybrids of one MMG steps through the mean of its
members' native rates (`SeedEnsemble.no_grad_rate`) in both ways; its batched rollout
through the equations of motion over `SeedEnsemble.forward` (as before session 16) is
timed beside, in the last column.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import statistics
import time
from pathlib import Path

import torch

from sysid.device import compute_threads
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.maneuvers.any_model import load_maneuver_model
from sysid.maneuvers.recorded import CLOSED_LOOP_DT, approach_conditions, recorded_maneuver, recorded_test_runs
from sysid.maneuvers.simulate import simulate_maneuvers, simulate_rows


@contextlib.contextmanager
def through_forward():
    """`SeedEnsemble.no_grad_rate` hidden: the eager steps over `forward`, as before."""
    kept = SeedEnsemble.no_grad_rate
    SeedEnsemble.no_grad_rate = lambda self, like: None  # type: ignore[method-assign]
    try:
        yield
    finally:
        SeedEnsemble.no_grad_rate = kept  # type: ignore[method-assign]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("models", nargs="+", type=Path, help="run directories (or ensembles) of trained models")
    parser.add_argument("--data", default=None, help="dataset root (default: as sysid finds it)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    runs = recorded_test_runs(args.data)
    zigzags = []
    for scenario, run in runs.items():
        maneuver, execute = recorded_maneuver(run, scenario)
        if maneuver.kind == "zigzag":
            zigzags.append((maneuver, approach_conditions(run, execute, CLOSED_LOOP_DT)))
    steps = [c.steps for _, c in zigzags]
    print(f"{len(zigzags)} recorded zig-zags, {steps} RK4 steps of {CLOSED_LOOP_DT:g} s; one torch thread")
    print(f"{'model':45s} {'row at a time':>14s} {'batched':>10s} {'ratio':>7s}  max |diff| of indices"
          "   ensemble over forward, batched")
    for path in args.models:
        model = load_maneuver_model(path).model
        alone_t, rows_t, forward_t = [], [], []
        ensemble = isinstance(model, SeedEnsemble) and \
            model.no_grad_rate(torch.zeros(1, 6, dtype=torch.float64)) is not None
        with compute_threads(1):
            for _ in range(args.repeats):
                if ensemble:
                    with through_forward():
                        started = time.perf_counter()
                        simulate_rows(model, [m for m, _ in zigzags], [c for _, c in zigzags])
                        forward_t.append(time.perf_counter() - started)
                started = time.perf_counter()
                alone = [simulate_maneuvers(model, [m], c)[0] for m, c in zigzags]
                alone_t.append(time.perf_counter() - started)
                started = time.perf_counter()
                rows = simulate_rows(model, [m for m, _ in zigzags], [c for _, c in zigzags])
                rows_t.append(time.perf_counter() - started)
        worst = 0.0
        for a, b in zip(alone, rows):
            for k, v in a.indices.as_dict().items():
                w = b.indices.as_dict()[k]
                if not (math.isnan(v) and math.isnan(w)):
                    worst = max(worst, abs(v - w))
        t_alone, t_rows = statistics.median(alone_t), statistics.median(rows_t)
        extra = f"   {statistics.median(forward_t):.2f} s" if forward_t else ""
        print(f"{str(path)[-45:]:45s} {t_alone:12.2f} s {t_rows:8.2f} s {t_alone / t_rows:6.2f}x  {worst:.3g}{extra}")


if __name__ == "__main__":
    main()
