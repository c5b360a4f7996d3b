"""The side-by-side training of N seeds of one configuration (what one `sysid reproduce --seeds N`
trial runs: `sysid.runs.lifecycle.run_seeds`, no test logs), timed with this checkout's code
and with another checkout's, alternately, in one run.

Each run is a subprocess with the checkout first on PYTHONPATH (same interpreter and packages),
its run directories in a scratch directory. Printed per run: wall and child CPU time [s], the
parts (the seeds' preparation: split, standardisation, warm start; the shared training stage;
each seed's finish: gate, validation loss; the run directories written), the epochs at which
each seed stopped, the epochs' wall time by the number of seeds still training, and each seed's
``val_loss_multistep``. Then the medians and the ratio against / this (above 1: this checkout
is faster). With the config's epochs the seeds stop early where they do in the reproduction.

    python benchmarks/side_by_side_trial_speed.py --against DIR [--config configs/experiments/hybrid_D2.toml]
        [--seeds 5] [--epochs E] [--repeats 1] [--data DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# run in the child, with the checkout's sysid: the parts timed by wrapping the functions they call
CHILD = r"""
import json, sys, time
from collections import defaultdict
config, out, seeds, epochs, data = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5] or None
import sysid.identify.side_by_side as sbs
import sysid.identify.trainer as trainer
import sysid.runs.lifecycle as lifecycle
from sysid.config.experiment import load_experiment
parts = defaultdict(float)

def timed(owner, name, part):
    work = getattr(owner, name)
    def wrapped(*args, **kwargs):
        start = time.perf_counter()
        try:
            return work(*args, **kwargs)
        finally:
            parts[part] += time.perf_counter() - start
    setattr(owner, name, wrapped)

timed(trainer.Trainer, "prepare", "prepare")
timed(trainer.Trainer, "finish", "finish")
timed(sbs, "train_side_by_side", "training stage")
timed(lifecycle, "_written", "written")
exp = load_experiment(config)
over = {"epochs": epochs} if epochs > 0 else {}
exps = [exp.replace(experiment={"seed": s, "name": f"seed{s}"}, training=over) for s in range(seeds)]
start = time.perf_counter()
results = lifecycle.run_seeds(exps, [f"{out}/seed{s}" for s in range(seeds)], [], data=data, progress=False,
                              logs=[lambda _: None] * seeds, group_log=lambda _: None, overwrite=True)
wall = time.perf_counter() - start
by_k, stops = defaultdict(float), []
import csv
histories = [[r for r in csv.DictReader(open(f"{out}/seed{s}/history.csv")) if r["stage"] == "train"]
             for s in range(seeds)]
for h in histories:
    stops.append(len(h))
for epoch in range(max(stops)):
    active = [h for h in histories if len(h) > epoch]
    by_k[len(active)] += float(active[0][epoch]["seconds"])
vals = [json.load(open(f"{out}/seed{s}/summary.json"))["val_loss_multistep"] for s in range(seeds)]
print(json.dumps({"wall": wall, "parts": parts, "stops": stops, "by_k": by_k, "val": vals}))
"""


def run(code: Path, config: Path, out: Path, seeds: int, epochs: int, data: str | None) -> dict:
    """One side-by-side training with checkout `code`: its child's report, wall [s], CPU [s]."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(config), str(out), str(seeds), str(epochs), data or ""],
                          env=env, cwd=code, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{code}: the child failed:\n{done.stderr[-3000:]}")
    report = json.loads(done.stdout.strip().splitlines()[-1])
    report["process_wall"] = wall
    report["cpu"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return report


def show(label: str, r: dict) -> None:
    parts = ", ".join(f"{k} {v:.1f}" for k, v in r["parts"].items())
    by_k = ", ".join(f"K={k}: {v:.1f}" for k, v in sorted(r["by_k"].items(), key=lambda kv: -int(kv[0])))
    print(f"{label}: wall {r['process_wall']:.1f} s, CPU {r['cpu']:.1f} s; parts [s]: {parts}")
    print(f"    stopped at epochs {r['stops']}; epochs' wall by seeds training [s]: {by_k}")
    print(f"    val_loss_multistep {[round(v, 8) for v in r['val']]}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, type=Path, help="checkout to compare against")
    parser.add_argument("--config", default=ROOT / "configs/experiments/hybrid_D2.toml", type=Path)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--epochs", type=int, default=0, help="override [training] epochs (0: the config's)")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--data", default=None)
    args = parser.parse_args()
    config = args.config.resolve()
    data = str(Path(args.data).resolve()) if args.data else None
    if data is None and "SYSID_DATA" not in os.environ:
        os.environ["SYSID_DATA"] = str((ROOT / ".." / "shared" / "data" / "frt-ds-esso").resolve())
    mine, theirs = [], []
    with tempfile.TemporaryDirectory(prefix="sbs-trial-") as scratch:
        for i in range(args.repeats):
            for label, code, into in (("against", args.against.resolve(), theirs), ("this", ROOT, mine)):
                r = run(code, config, Path(scratch) / f"{label}{i}", args.seeds, args.epochs, data)
                show(f"{label} ({code})", r)
                into.append(r)
    for key in ("process_wall", "cpu"):
        a, b = statistics.median(r[key] for r in theirs), statistics.median(r[key] for r in mine)
        print(f"median {key}: against {a:.1f} s, this {b:.1f} s, ratio {a / b:.2f}x")


if __name__ == "__main__":
    main()
