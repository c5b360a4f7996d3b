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

Side by side with an older checkout (``--against``): the whole command ``sysid maneuver MODEL
--turning 35 --zigzag 20/20 --side starboard`` (one turning circle and one zig-zag, the
default duration 80 L/U0, indices, tables, report) of this code with its default settings
and of the older code with ``--eager`` (its eager path), each in a fresh process with a
fresh empty compile cache (``SYSID_CACHE``, ``TORCHINDUCTOR_CACHE_DIR``, and ``SYSID_CACHE_DIR``: the native
MMG kernel is built again, cold caches), in
turn, ``--repeats`` times; wall times (with the load average before and after each) and
their ratio:

    python benchmarks/maneuver_speed.py --run runs/hybrid_D2 --against /path/to/old/checkout [--duration 690]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
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
    parser.add_argument("--duration", type=float, default=None,
                        help="[s] (default: 600 s; with --against the command's default, 80 L/U0)")
    parser.add_argument("--dt", type=float, default=0.1, help="[s]")
    parser.add_argument("--cold", action="store_true", help="compile into an empty cache (the one-time cost)")
    parser.add_argument("--against", type=Path, help="an older checkout: time `sysid maneuver` side by side")
    args = parser.parse_args()
    if args.against:
        return side_by_side(args)
    torch.set_num_threads(args.threads)
    if args.cold:
        os.environ["SYSID_CACHE"] = tempfile.mkdtemp(prefix="sysid-cache-")

    from sysid.maneuvers import (CrashStop, TurningCircle, ZigZag, default_conditions, load_maneuver_model,
                                 simulate_maneuvers)
    from sysid.maneuvers.simulate import ahead_only

    subject = load_maneuver_model(args.run if args.run else "esso_osaka")
    conditions, sources = default_conditions(subject.model, subject.ship, dt=args.dt, duration=args.duration or 600.0)
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


def timed_command(root: Path, extra: list[str], model: str, duration: float | None, threads: int
                  ) -> tuple[float, float, str]:
    """(wall time [s], the child's CPU time [s], the output's lines) of ``sysid maneuver``
    from `root` in a fresh process with empty caches; a turning circle and a zig-zag to
    starboard. On a loaded machine the CPU time compares two codes better than the wall."""
    with tempfile.TemporaryDirectory(prefix="maneuver-speed-") as tmp:
        env = dict(os.environ, PYTHONPATH=str(root), SYSID_CACHE=str(Path(tmp) / "sysid"),
                   SYSID_CACHE_DIR=str(Path(tmp) / "native"), TORCHINDUCTOR_CACHE_DIR=str(Path(tmp) / "inductor"),
                   OMP_NUM_THREADS=str(threads))
        command = [sys.executable, "-m", "sysid", "maneuver", model, "-o", str(Path(tmp) / "out"), "--turning", "35",
                   "--zigzag", "20/20", "--side", "starboard", *extra]
        if duration is not None:
            command += ["--duration", f"{duration:g}"]
        start, cpu = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=tmp)
        took, after = time.perf_counter() - start, resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            raise SystemExit(f"{root}: sysid maneuver failed:\n{done.stderr[-2000:]}")
        lines = [line for line in done.stdout.splitlines() if line.startswith("maneuver: ")]
        return took, (after.ru_utime + after.ru_stime) - (cpu.ru_utime + cpu.ru_stime), " | ".join(lines[1:])


def side_by_side(args) -> None:
    """`sysid maneuver` of this code (default settings) and of ``--against`` (--eager), in
    turn, cold caches each: median wall times and their ratio."""
    model = str(args.run.resolve()) if args.run else "esso_osaka"
    runs = {"today (--against, --eager)": (args.against.resolve(), ["--eager"]),
            "this code (default settings)": (ROOT, [])}
    times: dict[str, list[float]] = {name: [] for name in runs}
    cpus: dict[str, list[float]] = {name: [] for name in runs}
    print(f"sysid maneuver {model} --turning 35 --zigzag 20/20 --side starboard"
          f"{'' if args.duration is None else f' --duration {args.duration:g}'}; cold caches, {args.threads} thread(s)")
    for repeat in range(args.repeats):
        for name, (root, extra) in (runs.items() if repeat % 2 == 0 else reversed(runs.items())):
            before = os.getloadavg()[0]
            took, cpu, said = timed_command(root, extra, model, args.duration, args.threads)
            times[name].append(took)
            cpus[name].append(cpu)
            print(f"  {name}: {took:.1f} s wall, {cpu:.1f} s CPU (load {before:.1f} -> {os.getloadavg()[0]:.1f})"
                  f"   {said}", flush=True)
    old, new = (statistics.median(v) for v in times.values())
    old_cpu, new_cpu = (statistics.median(v) for v in cpus.values())
    print(f"median: today {old:.1f} s, this code {new:.1f} s: {old / new:.1f}x faster "
          f"(CPU {old_cpu:.1f} s and {new_cpu:.1f} s: {old_cpu / new_cpu:.1f}x)")


if __name__ == "__main__":
    main()
