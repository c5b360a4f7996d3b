"""CPU of ``sysid reproduce --seeds N``'s work after training, this code beside an older
checkout, on the same trained runs: the mean-of-seeds ensembles' evaluations and every
model's recorded maneuvers (`sysid.protocol.overlap.AfterTraining` with every run ready and
all slots free, as after the last trial), then ``maneuver_indices.csv`` from those
predictions (`sysid.maneuvers.recorded.write_record_comparison`).

    python benchmarks/after_training_speed.py --run /tmp/repro5 --against /path/to/old/checkout [--repeats 2]

`--run` is a finished reproduction with seeds (its ``runs/NAME/seedK`` and the MMGs' run
directories are copied, never written). Each side runs in a fresh process (its imports
included) with `--workers` worker processes, the sides in turn, `--repeats` times; printed:
CPU seconds of the process and its workers, wall seconds, their medians and ratio, and how
far the two sides' ensemble metrics and ``maneuver_indices.csv`` differ.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]

SIDE = r"""
import json, resource, sys, time
from pathlib import Path
started, cpu0 = time.perf_counter(), time.process_time()

def main():
    import pandas as pd
    from sysid.protocol.reproduce import PROTOCOL, protocol_experiment
    from sysid.protocol.overlap import AfterTraining
    from sysid.protocol.seed_runs import SeedGroup
    from sysid.protocol.paper import run_label
    from sysid.runs.lifecycle import cached_test_runs
    from sysid.maneuvers.recorded import write_record_comparison
    out, workers = Path(sys.argv[1]), int(sys.argv[2])
    experiments = {n: protocol_experiment(n) for n in PROTOCOL}
    after = AfterTraining(experiments, out, cached_test_runs(None), None, workers, lambda m: None)
    labels = {}
    with after.pool:
        for name, exp in experiments.items():
            seeds = sorted(int(p.name[4:]) for p in (out / "runs" / name).glob("seed*"))
            after.ready(name, SeedGroup(name, seeds, pd.DataFrame(), {}, None, 0.0) if seeds else None)
            dataset = exp.experiment.dataset if exp.needs_training else "-"
            labels[run_label(name, exp.experiment.model, dataset)] = out / "runs" / name
        after.free(workers)
        after.finish()
    for name, (group, (target, _, path)) in after.ensembles.items():
        exp = experiments[name]
        labels[run_label(target, exp.experiment.model, exp.experiment.dataset)] = path
    write_record_comparison(out, labels, None, workers=workers, predicted=after.predicted)
    own = time.process_time() - cpu0
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(json.dumps({"cpu": own + children.ru_utime + children.ru_stime, "driver": own,
                      "wall": time.perf_counter() - started}))

if __name__ == "__main__":
    main()
"""


def _copy_runs(source: Path, target: Path) -> None:
    """The trained seed runs and the MMGs' run directories of `source` into `target`
    (no ensembles: they are what the work writes)."""
    for path in (source / "runs").iterdir():
        if "_ensemble_" not in path.name:
            shutil.copytree(path, target / "runs" / path.name)


def _side(code: Path, source: Path, workers: int) -> tuple[dict, Path]:
    """One side in a fresh process with `code` first on the path: its timings and output."""
    out = Path(tempfile.mkdtemp(prefix="after-training-"))
    _copy_runs(source, out)
    script = out / "side.py"
    script.write_text(SIDE)
    env = dict(os.environ, PYTHONPATH=str(code))
    done = subprocess.run([sys.executable, str(script), str(out), str(workers)], env=env, capture_output=True,
                          text=True, check=False)
    if done.returncode:
        raise SystemExit(f"{code}: exit {done.returncode}\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1]), out


def _differences(ours: Path, theirs: Path) -> str:
    """The largest relative difference of the ensembles' metrics and of maneuver_indices.csv."""
    def largest(a: pd.DataFrame, b: pd.DataFrame) -> tuple[float, str]:
        numbers = a.select_dtypes("number").columns
        x, y = a[numbers].to_numpy(float), b[numbers].to_numpy(float)
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.abs(x - y) / np.maximum(np.abs(y), 1e-300)
        rel[np.isnan(x) & np.isnan(y)] = 0.0
        rel[np.isnan(x) ^ np.isnan(y)] = np.inf  # a NaN on one side only
        if not rel.size or not np.any(rel > 0):
            return 0.0, ""
        i, j = np.unravel_index(np.argmax(rel), rel.shape)
        where = " ".join(str(a[c].iloc[i]) for c in ("scenario", "model", "file") if c in a)
        return float(rel[i, j]), f" ({numbers[j]} of {where}: {x[i, j]:.6g} against {y[i, j]:.6g})"
    metrics = max(largest(pd.read_csv(p), pd.read_csv(theirs / p.relative_to(ours)))
                  for p in ours.glob("runs/*_ensemble_*/metrics.csv"))
    indices = largest(pd.read_csv(ours / "maneuver_indices.csv"), pd.read_csv(theirs / "maneuver_indices.csv"))
    return (f"largest relative difference: ensembles' metrics {metrics[0]:.2g}{metrics[1]}, "
            f"maneuver_indices.csv {indices[0]:.2g}{indices[1]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", type=Path, required=True, help="a finished reproduction with seeds")
    parser.add_argument("--against", type=Path, required=True, help="an older checkout")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    times: dict[str, list[dict]] = {"this": [], "against": []}
    outs: dict[str, Path] = {}
    for r in range(args.repeats):
        for side, code in (("this", ROOT), ("against", args.against.resolve())):
            with open("/proc/loadavg") as f:
                load = f.read().split()[0]
            found, out = _side(code, args.run, args.workers)
            times[side].append(found)
            if side in outs:
                shutil.rmtree(out)
            else:
                outs[side] = out
            print(f"round {r + 1} {side:8s} CPU {found['cpu']:6.1f} s (driver {found['driver']:5.1f} s)  "
                  f"wall {found['wall']:6.1f} s  load {load}", flush=True)
    med = {s: {k: statistics.median(t[k] for t in v) for k in ("cpu", "wall")} for s, v in times.items()}
    print(f"median CPU: this {med['this']['cpu']:.1f} s, against {med['against']['cpu']:.1f} s "
          f"(ratio {med['against']['cpu'] / med['this']['cpu']:.2f}x); median wall: this {med['this']['wall']:.1f} s, "
          f"against {med['against']['wall']:.1f} s")
    print(_differences(outs["this"], outs["against"]))
    for out in outs.values():
        shutil.rmtree(out)


if __name__ == "__main__":
    main()
