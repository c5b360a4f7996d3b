"""Speed of standard maneuvers (`sysid.maneuvers`): a 600 s maneuver at dt 0.1 s (6000
closed-loop RK4 steps) of a trained model, compiled and eager, in one run.

Prints, for each maneuver (35 deg turning, 10/10 zig-zag, crash stop) of the model:

1. the one-time cost of the compiled loop: compiling it (an empty cache) or loading it from
   the disk cache (`sysid.fast.compiled.cache_dir`), once per model and integration rule;
2. the median wall time of the whole 600 s maneuver through the compiled loop (every call
   of the loop, the controller's orders inside it, the indices and the kNN gate's share
   along the run included: what `simulate_maneuvers(..., compiled=True)` costs);
3. the eager loop's time per step (one maneuver, a 20 s run) and what 600 s would take.

    python benchmarks/maneuver_speed.py --run runs/hybrid_D2 [--threads 1] [--repeats 5] [--cold]

Without --run the Esso Osaka's MMG is timed (no trained model at hand). Compare within one
run: the machine is shared and its speed drifts.
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", type=Path, help="run directory of a trained model (default: the Esso Osaka's MMG)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--duration", type=float, default=600.0, help="[s]")
    parser.add_argument("--dt", type=float, default=0.1, help="[s]")
    parser.add_argument("--cold", action="store_true", help="compile into an empty cache (the one-time cost)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.cold:
        os.environ["SYSID_CACHE"] = tempfile.mkdtemp(prefix="sysid-cache-")

    from sysid.maneuvers import (CrashStop, TurningCircle, ZigZag, default_conditions, load_maneuver_model,
                                 simulate_maneuvers)
    from sysid.maneuvers.simulate import ahead_only

    subject = load_maneuver_model(args.run if args.run else "esso_osaka")
    conditions, sources = default_conditions(subject.model, subject.ship, dt=args.dt, duration=args.duration)
    maneuvers = [TurningCircle(35.0), ZigZag(10.0, 10.0)] + ([] if ahead_only(subject.model) else [CrashStop()])
    print(f"model {subject.label} ({subject.kind}), U0 {conditions.speed:g} m/s, n {conditions.rps:.4g} rps "
          f"({sources['rps']}), {conditions.duration:g} s at dt {conditions.dt:g} s = {conditions.steps} RK4 steps, "
          f"{args.threads} thread(s), torch {torch.__version__}")

    from sysid.maneuvers.closed_loop import compiled_loop
    start = time.perf_counter()
    if compiled_loop(subject.model, conditions.method) is None:
        raise SystemExit("the compiled loop is unavailable (SYSID_COMPILE=0, or no C++ compiler): nothing to time")
    simulate_maneuvers(subject.model, maneuvers[:1], conditions, compiled=True)
    print(f"compiled loop {'compiled' if args.cold else 'compiled or loaded from the cache'} and first maneuver: "
          f"{time.perf_counter() - start:.1f} s (once per model and rule)")

    print(f"{'maneuver':24s} {'compiled, 600 s':>16s} {'eager per step':>15s} {'eager, 600 s':>13s} "
          f"{'compiled vs eager':>18s} {'gate off':>9s}")
    short = type(conditions)(conditions.speed, conditions.rps, conditions.rudder_rate, conditions.dt, 20.0,
                             method=conditions.method)
    for maneuver in maneuvers:
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            result = simulate_maneuvers(subject.model, [maneuver], conditions, compiled=True)[0]
            times.append(time.perf_counter() - start)
        compiled = statistics.median(times)
        start = time.perf_counter()
        simulate_maneuvers(subject.model, [maneuver], short, compiled=False)
        per_step = (time.perf_counter() - start) / short.steps
        gate = "-" if result.gate_off_share is None else f"{100 * result.gate_off_share:.0f} %"
        print(f"{maneuver.name:24s} {compiled:14.3f} s {1e3 * per_step:12.2f} ms {per_step * conditions.steps:11.1f} s "
              f"{per_step * conditions.steps / compiled:17.0f}x {gate:>9s}")


if __name__ == "__main__":
    main()
