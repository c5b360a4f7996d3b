"""NN-only's training step, validation loss and epoch, this checkout's code against another
checkout's, alternately, in one run.

A step is `sysid.identify.losses.multistep_loss` of `PerMember` of the NN-only model (float32, the
config's network) on the config's batch of real training windows, then its backward: K = 1 (a
seed alone) and K members each rolling out the batch (the rows seeds side by side train, K x
batch). The validation loss is `validation_loss` on the same windows (no gradient). With
--epochs E, also E epochs: every training window once in batches of the config's size (each a
step as above, then Adam), then `validation_loss` on the validation windows (the rollouts and
updates of a side-by-side epoch, without the trainer's bookkeeping). Each checkout
runs in a subprocess with it first on PYTHONPATH (same interpreter and packages), one thread;
the rounds alternate between the checkouts and the medians of the per-round medians (wall and the
process's CPU time, the steadier one on a shared machine) are printed,
with the ratio against / this (above 1: this checkout is faster), and the first step's loss of
each (the same to round-off).

    python benchmarks/nn_only_step_speed.py --against DIR [--config configs/experiments/nn_D2.toml]
        [--members 5] [--steps 20] [--rounds 3] [--epochs 0] [--data DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time, statistics
import torch
torch.set_num_threads(1)
config, members, steps, epochs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
from sysid.config.experiment import load_experiment
from sysid.identify.trainer import split_windows
from sysid.runs.lifecycle import training_runs
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.identify.losses import multistep_loss, validation_loss
exp = load_experiment(config)
t = exp.training
train, val = split_windows(training_runs(exp, None), t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                           t.block_s, exp.experiment.seed)[:2]
batch = train.select(torch.arange(min(t.batch_size, len(train))))
flat = batch.states.reshape(-1, 6)
w_v = torch.ones(3)
out = {}
for k in (1, members):
    torch.manual_seed(0)
    net = ForceCorrection(exp.network.hidden, torch.float32, k)
    net.set_standardization(flat.mean(0).repeat(2)[:9], flat.std(0).repeat(2)[:9] + 0.1,
                            torch.tensor([0.1, -0.05, 0.02]), torch.tensor([1.5, 0.7, 0.4]))
    model = PerMember(CorrectedModel(build_mmg(exp, torch.float32).requires_grad_(False), net, None, False))
    def step():
        loss = multistep_loss(model, batch, w_v)[0]
        net.zero_grad()
        loss.backward()
        return float(loss)
    first = step()
    times = {"step": [], "validation": [], "step CPU": [], "validation CPU": []}
    for _ in range(steps):
        for name, work in (("step", step), ("validation", lambda: validation_loss(model, batch, w_v))):
            start, cpu = time.perf_counter(), time.process_time()
            work()
            times[name].append(time.perf_counter() - start)
            times[name + " CPU"].append(time.process_time() - cpu)
    for name, values in times.items():
        out[f"{name} K={k}"] = statistics.median(values)
    out[f"loss K={k}"] = first
    if epochs:
        from sysid.identify.adam import Adam
        opt = Adam(net.parameters(), t.learning_rate)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(epochs):
            for lo in range(0, len(train), t.batch_size):
                loss = multistep_loss(model, train.select(torch.arange(lo, min(lo + t.batch_size, len(train)))), w_v)[0]
                opt.zero_grad()
                loss.backward()
                opt.step()
            last = float(validation_loss(model, val, w_v))
        out[f"epoch K={k}"] = (time.perf_counter() - wall) / epochs
        out[f"epoch CPU K={k}"] = (time.process_time() - cpu) / epochs
        out[f"loss after the epochs K={k}"] = last
print(json.dumps(out))
"""


def run(code: Path, config: Path, members: int, steps: int, epochs: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(code), "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", CHILD, str(config), str(members), str(steps), str(epochs)], env=env,
                          cwd=code,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{code}: the child failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, type=Path, help="checkout to compare against")
    parser.add_argument("--config", default=ROOT / "configs/experiments/nn_D2.toml", type=Path)
    parser.add_argument("--members", type=int, default=5)
    parser.add_argument("--steps", type=int, default=20, help="timed steps a round (medians)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--epochs", type=int, default=0, help="also time this many epochs a round (0: none)")
    parser.add_argument("--data", default=None)
    args = parser.parse_args()
    if args.data:
        os.environ["SYSID_DATA"] = str(Path(args.data).resolve())
    elif "SYSID_DATA" not in os.environ:
        os.environ["SYSID_DATA"] = str((ROOT / ".." / "shared" / "data" / "frt-ds-esso").resolve())
    config = args.config.resolve()
    results: dict[str, list[dict]] = {"against": [], "this": []}
    for i in range(args.rounds):
        for label, code in (("against", args.against.resolve()), ("this", ROOT)):
            r = run(code, config, args.members, args.steps, args.epochs)
            results[label].append(r)
            print(f"round {i + 1} {label}: " + ", ".join(f"{k} {1e3 * v:.1f} ms" if not k.startswith("loss")
                                                         else f"{k} {v:.9g}" for k, v in r.items()), flush=True)
    for key in results["this"][0]:
        if key.startswith("loss"):
            continue
        a = statistics.median(r[key] for r in results["against"])
        b = statistics.median(r[key] for r in results["this"])
        print(f"{key}: against {1e3 * a:.1f} ms, this {1e3 * b:.1f} ms, ratio {a / b:.2f}x")


if __name__ == "__main__":
    main()
