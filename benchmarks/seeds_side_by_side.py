"""N seeds of one protocol configuration trained side by side in one process
(`sysid.identify.side_by_side`) against the same N seeds trained one after another, in one
run: process CPU time and wall time of each, their ratio, and the largest relative
difference of the seeds' validation losses (they should agree to round-off).

The training stage runs a fixed number of epochs (patience above it, so no seed stops
early and both ways do the same work); the warm start is shortened, as it is per seed in
both ways. CPU time is the measure on a loaded machine (wall time is printed beside it).

    python benchmarks/seeds_side_by_side.py [--data DIR] [--only D1] [--seeds 5] [--epochs 3]
        [--warm-start 5] [--threads 1]
"""
from __future__ import annotations

import argparse
import time

import torch

from sysid.config.experiment import load_experiment
from sysid.data.datasets import data_root
from sysid.errors import DataError
from sysid.identify import side_by_side
from sysid.identify.side_by_side import fit_side_by_side
from sysid.identify.trainer import Trainer
from sysid.runs.lifecycle import training_runs

CONFIGS = {"D1": "configs/experiments/hybrid_D1.toml", "D2": "configs/experiments/hybrid_D2.toml"}


def _timed(work):
    """(result, CPU seconds of this process, wall seconds) of work()."""
    cpu, wall = time.process_time(), time.perf_counter()
    result = work()
    return result, time.process_time() - cpu, time.perf_counter() - wall


def _cpu_counted(owner, name: str, spent: list[float]) -> None:
    """Wrap owner.name so that its process CPU time adds up in spent[0]."""
    work = getattr(owner, name)

    def counted(*args, **kwargs):
        cpu = time.process_time()
        try:
            return work(*args, **kwargs)
        finally:
            spent[0] += time.process_time() - cpu

    setattr(owner, name, counted)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None)
    parser.add_argument("--only", choices=sorted(CONFIGS), default="D1")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--warm-start", type=int, default=5, help="warm-start epochs of every seed")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    try:
        data_root(args.data)
    except DataError as exc:
        raise SystemExit(f"seeds_side_by_side: {exc}") from None
    torch.set_num_threads(args.threads)
    base = load_experiment(CONFIGS[args.only])
    runs = training_runs(base, args.data)
    exps = [base.replace(experiment={"seed": base.experiment.seed + k},
                         training={"epochs": args.epochs, "patience": args.epochs + 1,
                                   "warm_start_epochs": args.warm_start})
            for k in range(args.seeds)]
    print(f"torch {torch.__version__}, {args.threads} thread(s); {args.only}: {args.seeds} seeds, "
          f"{args.epochs} training epochs, {args.warm_start} warm-start epochs each")

    def quiet(exp):
        return Trainer(exp, progress=False, log=lambda _: None)

    stage_side, stage_solo = [0.0], [0.0]  # CPU seconds of the training stage (stage 5)
    _cpu_counted(side_by_side, "train_side_by_side", stage_side)
    _cpu_counted(Trainer, "train", stage_solo)
    pair, cpu_side, wall_side = _timed(lambda: fit_side_by_side([quiet(e) for e in exps], runs))
    alone, cpu_solo, wall_solo = _timed(lambda: [quiet(e).fit(runs) for e in exps])
    differences = [abs(a.summary_.val_loss_multistep - b.summary_.val_loss_multistep) / b.summary_.val_loss_multistep
                   for a, b in zip(pair, alone)]
    train_side = sum(pair[0].history_[pair[0].history_.stage == "train"].seconds)
    train_solo = sum(sum(t.history_[t.history_.stage == "train"].seconds) for t in alone)
    print(f"one by one:   CPU {cpu_solo:7.1f} s, wall {wall_solo:7.1f} s; training stage CPU {stage_solo[0]:.1f} s, "
          f"wall {train_solo:.1f} s")
    print(f"side by side: CPU {cpu_side:7.1f} s, wall {wall_side:7.1f} s; training stage CPU {stage_side[0]:.1f} s, "
          f"wall {train_side:.1f} s")
    print(f"side by side / one by one: whole fit CPU {cpu_side / cpu_solo:.2f}x (wall {wall_side / wall_solo:.2f}x); "
          f"training stage CPU {stage_side[0] / stage_solo[0]:.2f}x (wall {train_side / train_solo:.2f}x)")
    print(f"largest relative difference of a seed's val_loss_multistep: {max(differences):.2e}")


if __name__ == "__main__":
    main()
