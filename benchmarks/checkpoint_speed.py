"""The per-epoch training checkpoint (`TrainingCheckpoint.save`) of this tree against another
git revision's (default ``main``), side by side in one process, interleaved rounds, medians:

1. one save of a real state, CPU per save: hybrid D2 trained alone, and one seed of nn_D2
   trained K = 5 seeds side by side (the states are captured from short trainings first);
2. the training stage of nn_D2, K seeds side by side, each seed writing its checkpoint after
   every epoch, with one save or the other (process CPU of `train_side_by_side`); the seeds'
   validation losses must be equal to the bit both ways (the checkpoint does not touch
   training).

    python benchmarks/checkpoint_speed.py [--data DIR] [--against main] [--rounds 5]
        [--seeds 5] [--epochs 12] [--warm-start 5] [--threads 1]
"""
from __future__ import annotations

import argparse
import copy
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from sysid.config.experiment import load_experiment
from sysid.identify import checkpoint, side_by_side
from sysid.identify.side_by_side import fit_side_by_side
from sysid.identify.trainer import Trainer
from sysid.runs.lifecycle import training_runs

HYBRID, NN = "configs/experiments/hybrid_D2.toml", "configs/experiments/nn_D2.toml"
THIS_SAVE = checkpoint.TrainingCheckpoint.save   # this tree's, before the benchmark swaps it


def other_module(revision: str):
    """`sysid.identify.checkpoint` as of git `revision`, imported under another name."""
    root = Path(__file__).resolve().parents[1]
    text = subprocess.run(["git", "show", f"{revision}:sysid/identify/checkpoint.py"], cwd=root, check=True,
                          capture_output=True, text=True).stdout
    path = Path(tempfile.mkdtemp()) / "checkpoint_other.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("checkpoint_other", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["checkpoint_other"] = module
    spec.loader.exec_module(module)
    return module


def trainers(config: str, seeds: int, epochs: int, warm_start: int, folder: Path) -> list[Trainer]:
    base = load_experiment(config)
    return [Trainer(base.replace(experiment={"seed": base.experiment.seed + k},
                                 training={"epochs": epochs, "patience": epochs + 1, "warm_start_epochs": warm_start}),
                    progress=False, log=lambda _: None, checkpoint=folder / f"seed{k}.pt") for k in range(seeds)]


def captured(data, warm_start: int, seeds: int, folder: Path) -> dict:
    """{label: (config, CheckpointState)} of the last epoch of two short trainings."""
    got = {}
    save = checkpoint.TrainingCheckpoint.save

    def keep(self, state):
        got[self.path] = (self.config, copy.deepcopy(state))
        save(self, state)

    checkpoint.TrainingCheckpoint.save = keep
    try:
        hybrid = trainers(HYBRID, 1, 3, warm_start, folder / "hybrid")[0]
        hybrid.fit(training_runs(hybrid.experiment, data))
        nn = trainers(NN, seeds, 3, warm_start, folder / "nn")
        fit_side_by_side(nn, training_runs(nn[0].experiment, data))
    finally:
        checkpoint.TrainingCheckpoint.save = save
    return {"hybrid D2 (alone)": got[folder / "hybrid" / "seed0.pt"],
            f"nn_D2 seed 0 (K = {seeds} side by side)": got[folder / "nn" / "seed0.pt"]}


def save_with(module):
    """A `TrainingCheckpoint.save` that writes with `module`'s code."""
    if module is checkpoint:
        return THIS_SAVE
    return lambda self, state: module.TrainingCheckpoint(self.path, self.config).save(
        module.CheckpointState(**{k: getattr(state, k) for k in state.__dataclass_fields__}))


def per_save_ms(module, config: str, state, path: Path, n: int) -> float:
    file = checkpoint.TrainingCheckpoint(path, config)
    save = save_with(module)
    cpu = time.process_time()
    for _ in range(n):
        save(file, state)
    return (time.process_time() - cpu) / n * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None)
    parser.add_argument("--against", default="main", help="git revision whose checkpoint.py to compare with")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--epochs", type=int, default=12, help="training-stage epochs of the whole-stage part")
    parser.add_argument("--warm-start", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    other = other_module(args.against)
    arms = {args.against: other, "this tree": checkpoint}
    folder = Path(tempfile.mkdtemp(prefix="checkpoint_speed."))
    print(f"torch {torch.__version__}, {args.threads} thread(s); {args.rounds} interleaved rounds; "
          f"checkpoint format {args.against}: version {other.VERSION}, this tree: version {checkpoint.VERSION}")

    states = captured(args.data, args.warm_start, args.seeds, folder)
    for label, (config, state) in states.items():
        tensors = len(state.model) + len(state.best_state or {}) + sum(len(s) for s in state.optimizer["state"].values())
        times = {name: [] for name in arms}
        for _ in range(args.rounds):
            for name, module in arms.items():
                per_save_ms(module, config, state, folder / "micro.pt", 20)   # warm
                times[name].append(per_save_ms(module, config, state, folder / "micro.pt", 200))
        a, b = (statistics.median(t) for t in times.values())
        print(f"save, {label}, {tensors} tensors: {args.against} {a:.2f} ms, this tree {b:.2f} ms CPU "
              f"(median of {args.rounds}); {a / b:.2f}x")

    stage, saving = {name: [] for name in arms}, {name: [] for name in arms}
    losses = {name: None for name in arms}
    original, counted = checkpoint.TrainingCheckpoint.save, side_by_side.train_side_by_side
    spent, in_save = [0.0], [0.0]

    def counted_save(save):
        def timed_save(self, state):
            cpu = time.process_time()
            try:
                return save(self, state)
            finally:
                in_save[0] += time.process_time() - cpu
        return timed_save

    def timed(*a, **k):
        cpu = time.process_time()
        try:
            return counted(*a, **k)
        finally:
            spent[0] += time.process_time() - cpu

    side_by_side.train_side_by_side = timed
    try:
        runs = training_runs(load_experiment(NN), args.data)
        for r in range(args.rounds):
            for name, module in arms.items():
                checkpoint.TrainingCheckpoint.save = counted_save(save_with(module))
                spent[0] = in_save[0] = 0.0
                fitted = fit_side_by_side(trainers(NN, args.seeds, args.epochs, args.warm_start, folder / f"{r}"), runs)
                stage[name].append(spent[0])
                saving[name].append(in_save[0])
                got = [t.summary_.val_loss_multistep for t in fitted]
                if losses[name] is None:
                    losses[name] = got
                print(f"  round {r + 1}: {name}: training stage {spent[0]:.2f} s CPU, its saves {in_save[0]:.2f} s",
                      flush=True)
    finally:
        checkpoint.TrainingCheckpoint.save, side_by_side.train_side_by_side = original, counted
    a, b = (statistics.median(t) for t in stage.values())
    print(f"training stage, nn_D2 {args.seeds} seeds side by side x {args.epochs} epochs: {args.against} {a:.2f} s, "
          f"this tree {b:.2f} s CPU (median of {args.rounds}); {a / b:.2f}x, {a - b:.2f} s less "
          f"({(a - b) / (args.seeds * args.epochs) * 1e3:.1f} ms per seed and epoch)")
    a, b = (statistics.median(t) for t in saving.values())
    print(f"  of which the {args.seeds * args.epochs} saves: {args.against} {a:.2f} s, this tree {b:.2f} s CPU "
          f"(median of {args.rounds}); {a / b:.2f}x")
    first, second = losses.values()
    print(f"seeds' val_loss_multistep equal to the bit both ways: {first == second} ({first})")


if __name__ == "__main__":
    main()
