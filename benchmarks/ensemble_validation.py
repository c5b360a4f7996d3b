"""The protocol hybrids as K-member ensembles, judged on VALIDATION data only (issue 34 item 4).

For each of hybrid_D1 and hybrid_D2 trained with N seeds (the seed run directories of a
``sysid reproduce --seeds N`` output, ``RUNS/hybrid_D?/seed{k}``), the validation loss
``val_loss_multistep`` (the run's objective: 30-s Euler rollouts, velocity loss weighted by
1 / variance, kNN gate on) on the held-out validation logs of the config (``[training]
validation = "files"``, the same logs for every seed), of

- every single seed (checked against the value its summary.json holds),
- every mean-of-seeds ensemble of K of the N seeds (`sysid.hybrid.ensemble.SeedEnsemble`,
  all subsets of size K), for K = 2..N.

No test file is opened: the validation logs are training logs held out by the config's
``split_seed``. Models are evaluated in float64 (the run directory's model), so a single
seed's loss differs from its float32 summary value at round-off.

    python benchmarks/ensemble_validation.py RUNS [--data DIR] [--only D1]
"""
from __future__ import annotations

import argparse
import itertools
import statistics
from pathlib import Path

import torch

from sysid.device import compute_threads
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.identify.losses import VEL
from sysid.identify.trainer import Trainer
from sysid.identify.windowing import held_out_validation
from sysid.protocol.reproduce import protocol_experiment
from sysid.runs.rundir import RunDir
from sysid.runs.lifecycle import training_runs
from sysid.runs.rundir import load_model


def validation_losses(runs_dir: Path, name: str, data) -> dict:
    """{"seeds": {seed: (loss, summary loss)}, "ensembles": {K: [loss of each subset]}}."""
    exp = protocol_experiment(name)
    logs = training_runs(exp, data)
    held_out = held_out_validation(exp, logs)
    assert held_out is not None, f"{name}: [training] validation is not \"files\""
    train_logs, validation = list(held_out.train), list(held_out.validation)
    trainer = Trainer(exp, progress=False, log=lambda _: None)
    trainer._validation_runs = validation   # as `Trainer.prepare` sets it
    dtype, device = torch.float64, torch.device("cpu")
    cut = trainer.split(train_logs, dtype, device)
    train, val = cut.train, cut.val
    w_v = 1.0 / train.states[:, :, VEL].reshape(-1, 3).var(0)

    def loss(model) -> float:
        with torch.no_grad():
            return trainer.objective(model, train_logs, val, w_v, dtype, device)

    folders = sorted((runs_dir / name).glob("seed*"), key=lambda p: int(p.name[4:]))
    models = {int(p.name[4:]): load_model(p)[1] for p in folders}
    seeds = {k: (loss(m), RunDir(runs_dir / name / f"seed{k}").read_summary().val_loss_multistep)
             for k, m in models.items()}
    ensembles = {}
    for size in range(2, len(models) + 1):
        ensembles[size] = [loss(SeedEnsemble([models[k] for k in subset]))
                           for subset in itertools.combinations(sorted(models), size)]
    return {"seeds": seeds, "ensembles": ensembles, "validation_logs": [r.name for r in validation]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, help="the runs/ folder of a sysid reproduce --seeds N output")
    parser.add_argument("--data", default=None)
    parser.add_argument("--only", choices=("D1", "D2"), action="append")
    args = parser.parse_args()
    with compute_threads(1):
        for ds in args.only or ("D1", "D2"):
            name = f"hybrid_{ds}"
            result = validation_losses(args.runs, name, args.data)
            singles = [v for v, _ in result["seeds"].values()]
            mean, spread = statistics.mean(singles), statistics.stdev(singles)
            print(f"\n{name}: validation logs {', '.join(result['validation_logs'])}")
            for k, (v, summary) in result["seeds"].items():
                print(f"  seed {k}: {v:.5f} (summary.json, float32: {summary:.5f})")
            print(f"  single seed: mean {mean:.5f}, std {spread:.5f} over {len(singles)} seeds")
            for size, values in result["ensembles"].items():
                m = statistics.mean(values)
                print(f"  {size}-seed ensembles ({len(values)} subsets): mean {m:.5f}, range "
                      f"[{min(values):.5f}, {max(values):.5f}]; {100 * (1 - m / mean):.1f} % below the single "
                      f"seed's mean ({(mean - m) / spread:.2f} seed std)")


if __name__ == "__main__":
    main()
