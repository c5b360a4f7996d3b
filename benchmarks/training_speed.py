"""Training throughput of the multi-step loss on the real data (D1, D2), one process.

Prints, per data set and batch size: time per minibatch (forward + backward + Adam step of
T = 5 Euler steps of the hybrid right-hand side), window-steps per second and epochs per
second; with --converge also the wall time of a whole training to its early stop.

    python benchmarks/training_speed.py [--data DIR] [--threads 1] [--converge]
"""
from __future__ import annotations

import argparse
import time

import torch

from sysid.data.datasets import data_root
from sysid.errors import DataError
from sysid.config.experiment import load_experiment
from sysid.runs.lifecycle import training_runs
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.hybrid.correction import ForceCorrection
from sysid.identify.trainer import Trainer, multistep_loss, split_windows

CONFIGS = {"D1": "configs/experiments/hybrid_D1.toml", "D2": "configs/experiments/hybrid_D2.toml"}


def minibatch_seconds(exp, train, batch: int, repeats: int = 8) -> float:
    """Mean wall time [s] of one training step on `batch` windows."""
    mmg = build_mmg(exp, torch.float32).requires_grad_(False)
    net = ForceCorrection(exp.network.hidden, torch.float32, exp.network.members)
    model = PerMember(CorrectedModel(mmg, net, None, True, exp.gate.space))
    w_v = 1.0 / train.states[:, :, [1, 3, 5]].reshape(-1, 3).var(0)
    w_F = torch.ones(3)
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    chunk = train.select(torch.arange(min(batch, len(train))))

    def step():
        loss_v, loss_F = multistep_loss(model, chunk, w_v, w_F)
        loss = loss_v + 1e-3 * loss_F
        opt.zero_grad()
        loss.backward()
        opt.step()

    for _ in range(2):
        step()
    start = time.perf_counter()
    for _ in range(repeats):
        step()
    return (time.perf_counter() - start) / repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--converge", action="store_true", help="also train each config to its early stop")
    args = parser.parse_args()
    try:
        data_root(args.data)
    except DataError as exc:
        raise SystemExit(f"training_speed: {exc}")
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} thread(s)")
    for name, path in CONFIGS.items():
        exp = load_experiment(path)
        runs = training_runs(exp, args.data)
        t = exp.training
        train, _, _, _ = split_windows(runs, t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                                       t.block_s, exp.experiment.seed)
        print(f"\n{name}: {len(train)} training windows of {t.steps} steps (config batch {t.batch_size})")
        print(f"{'batch':>6} {'ms/step':>9} {'window-steps/s':>15} {'epochs/s':>9}")
        for batch in sorted({128, 512, t.batch_size, 1024, len(train)}):
            seconds = minibatch_seconds(exp, train, batch)
            steps_per_epoch = -(-len(train) // batch)
            print(f"{batch:6d} {1e3 * seconds:9.1f} {min(batch, len(train)) * t.steps / seconds:15.0f} "
                  f"{1.0 / (seconds * steps_per_epoch):9.2f}")
        if args.converge:
            start = time.perf_counter()
            trainer = Trainer(exp, progress=False, log=lambda m: None).fit(runs)
            s = trainer.summary_
            print(f"to convergence: {time.perf_counter() - start:.1f} s, {s.epochs} epochs "
                  f"(best {s.best_epoch}; {', '.join(f'{k}: {v}' for k, v in s.stopped.items())})")


if __name__ == "__main__":
    main()
