"""The identified runs of ``sysid reproduce --seeds N`` (mmg_identified_D2 and
hybrid_identified_D2, one seed at a time, as their trials train), timed side by side against
another checkout of sysid, in one run; and whether each seed's results are the same.

Each seed is fitted (`Trainer.fit` on the training logs, 1 torch thread, no checkpoint file,
no evaluation on the test files) in a fresh process with this code and with the code of
`--base` (a checkout of the commit to compare against, put first on PYTHONPATH, same
interpreter and data), alternating seed by seed. Printed per seed: wall and CPU seconds of
the fit, its stages' epochs and CPU seconds (identification with its sigma, training), the
rest (warm start, gate, validation loss), and whether the identified coefficients and ``val_loss_multistep``
are equal to the bit (else their largest relative difference); then the totals and ratios.

    python benchmarks/identified_runs_speed.py --base /tmp/base [--seeds 5] [--only mmg_identified_D2]
        [--data DIR]

With ``--step`` instead: one identification step (a T = 5 Euler rollout of 512 recorded-like
states with the five identified hull coefficients trainable, and its backward) three ways:
through autograd over the MMG (`MMG.identified_rate` switched off), through this code's
identification path (`sysid.mmg.vjp.identified_rate`: the hand-derived VJP with respect to
the state and the coefficients, where it applies), and the floor: the same rollout through
the state's VJP with the coefficients frozen (`sysid.mmg.vjp.mmg_rate`, no coefficient
gradient); with the largest relative difference of the coefficients' gradients.

    python benchmarks/identified_runs_speed.py --step [--repeats 50]

With ``--project OUT`` (a finished ``sysid reproduce --seeds N`` output, its ``trials.log``):
the trials' list schedule on 2 slots in their start order (`reproduce_timeline.py`) as run,
and with each identified trial's wall time scaled by its seed's CPU ratio measured here.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from sysid.data.datasets import data_root

ROOT = Path(__file__).resolve().parents[1]
RUNS = ("mmg_identified_D2", "hybrid_identified_D2")

# one seed's fit in a fresh process: its times and results as one JSON line
FIT = """
import json, sys, time, torch
torch.set_num_threads(1)
import sysid
from sysid.config.experiment import load_experiment
from sysid.identify.trainer import Trainer
from sysid.runs.lifecycle import training_runs
spent = {}
def timed(part, work):  # the CPU seconds of a stage of the fit
    def run(*args, **kwargs):
        cpu = time.process_time()
        try:
            return work(*args, **kwargs)
        finally:
            spent[part] = spent.get(part, 0.0) + time.process_time() - cpu
    return run
Trainer.identify = timed("identify", Trainer.identify)
Trainer.train = timed("train", Trainer.train)
base = load_experiment(sys.argv[1])
runs = training_runs(base, None)
exp = base.replace(experiment={"seed": base.experiment.seed + int(sys.argv[2])}, training={"threads": 1})
wall, cpu = time.perf_counter(), time.process_time()
fit = Trainer(exp, progress=False, log=lambda _: None).fit(runs)
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
stages = fit.history_.groupby("stage")["seconds"].sum().to_dict() if len(fit.history_) else {}
epochs = fit.history_.groupby("stage")["epoch"].max().to_dict() if len(fit.history_) else {}
print(json.dumps({"code": sysid.__file__, "wall": wall, "cpu": cpu, "stages": stages, "stage_cpu": spent,
                  "epochs": {k: int(v) for k, v in epochs.items()},
                  "val": fit.summary_.val_loss_multistep, "identified": fit.summary_.identified}))
"""


def fit(code: Path, config: Path, seed: int, data: Path) -> dict:
    """One seed's fit with the sysid of `code` on the dataset `data` (its times and results)."""
    env = {**os.environ, "PYTHONPATH": str(code), "OMP_NUM_THREADS": "1", "SYSID_DATA": str(data)}
    done = subprocess.run([sys.executable, "-c", FIT, str(config), str(seed)], env=env, cwd=code,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"identified_runs_speed: seed {seed} of {config} (PYTHONPATH={code}) failed:\n"
                         f"{done.stderr[-2000:]}")
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if not result["code"].startswith(str(code)):
        raise SystemExit(f"identified_runs_speed: {result['code']} imported, not the sysid of {code}")
    return result


def difference(a: dict, b: dict) -> str:
    """'equal' when the identified coefficients and the validation loss are the same to the
    bit, else the largest relative difference (and that of the coefficients and of the loss)."""
    pairs = [(a["val"], b["val"])] + [(a["identified"][k], b["identified"][k]) for k in a["identified"]]
    if all(x == y for x, y in pairs):
        return "equal"
    rel = [abs(x - y) / max(abs(y), 1e-300) for x, y in pairs]
    return f"differ (max rel {max(rel):.1e}: coefficients {max(rel[1:], default=0.0):.1e}, val_loss_multistep {rel[0]:.1e})"


def line(r: dict) -> str:
    """Wall and CPU seconds of the fit; of its stages, epochs and CPU seconds (identify: its
    epochs and the sigma), and the rest (warm start, gate, validation loss)."""
    cpu = r["stage_cpu"]
    rest = r["cpu"] - sum(cpu.values())
    parts = ", ".join(f"{k} {r['epochs'][k]} ep {cpu[k]:.1f} s" for k in r["epochs"])
    return f"wall {r['wall']:6.1f} s  CPU {r['cpu']:6.1f} s  ({parts}, rest {rest:.1f} s)"


def step_times(repeats: int) -> None:
    """`--step`: the identification step through autograd against the VJP's floor."""
    import time

    import torch

    from sysid import MMG, load_ship
    from sysid.config.experiment import load_experiment
    from sysid.dynamics.equations import derivative
    from sysid.mmg import vjp

    torch.set_num_threads(1)
    ident = load_experiment(ROOT / "configs" / "experiments" / "mmg_identified_D2.toml").identify
    g = torch.Generator().manual_seed(0)
    state = torch.tensor([0.0, 0.4, 0.0, 0.0, 0.0, 0.0]) + torch.randn(512, 6, generator=g) * torch.tensor(
        [1.0, 0.2, 1.0, 0.05, 1.0, 0.01])
    inputs = torch.tensor([8.0, 0.0, 3.0, 1.0]) + torch.randn(512, 4, generator=g) * torch.tensor([2.0, 0.3, 1.0, 1.0])
    trained = MMG(load_ship("esso_osaka"), ident.parameters, dict(ident.bounds), dtype=torch.float32)
    autograd = MMG(load_ship("esso_osaka"), ident.parameters, dict(ident.bounds), dtype=torch.float32)
    autograd.identified_rate = lambda state, inputs: None  # the torch path: autograd over the forward
    frozen = MMG(load_ship("esso_osaka"), dtype=torch.float32)
    c = frozen.coefficients.values_view(torch.float32)

    def step(model):
        def work():
            model.zero_grad()
            x = state
            for _ in range(5):
                x = x + 0.1 * derivative(model, x, inputs)
            x[..., [1, 3, 5]].square().sum().backward()
        return work

    def vjp_floor():
        x = state.clone().requires_grad_(True)
        for _ in range(5):
            x = x + 0.1 * vjp.mmg_rate(x, inputs, c)[..., :6]
        x[..., [1, 3, 5]].square().sum().backward()

    ways = {"autograd": step(autograd), "identified": step(trained), "vjp": vjp_floor}
    times: dict[str, list[float]] = {k: [] for k in ways}
    for _ in range(repeats):
        for name, work in ways.items():
            started = time.perf_counter()
            work()
            times[name].append(time.perf_counter() - started)
    a, i, v = (sorted(times[k])[len(times[k]) // 2] * 1e3 for k in ways)
    moved = max(float(((p.grad - q.grad).abs() / q.grad.abs()).max())
                for p, q in zip(trained.parameters(), autograd.parameters()))
    print(f"one identification step, batch 512, T = 5, 1 thread (median of {repeats}, alternating): "
          f"autograd over the MMG {a:.2f} ms, the coefficients' VJP {i:.2f} ms ({a / i:.2f}x), the state-only "
          f"VJP floor {v:.2f} ms; coefficient gradients differ by {moved:.1e} (relative); load {os.getloadavg()[0]:.1f}")

def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", type=Path, help="checkout of the code to compare against")
    parser.add_argument("--step", action="store_true", help="time one identification step instead (see above)")
    parser.add_argument("--repeats", type=int, default=50, help="--step: steps timed each way")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--only", choices=RUNS, default=None)
    parser.add_argument("--data", default=None, help="dataset root (default: as sysid finds it)")
    parser.add_argument("--project", type=Path, default=None,
                        help="a reproduction's output: its trials' schedule with the identified ones scaled")
    args = parser.parse_args()
    if args.step:
        step_times(args.repeats)
        return
    if args.base is None:
        parser.error("--base is required (or --step)")
    base = args.base.resolve()
    data = data_root(args.data)
    print(f"this code {ROOT} against {base}; load {os.getloadavg()[0]:.1f}", flush=True)
    totals = {"this": [0.0, 0.0], "base": [0.0, 0.0]}
    ratios: dict[str, float] = {}  # runs/NAME/seedK -> CPU of this code / CPU of the base
    same = True
    for name in ([args.only] if args.only else RUNS):
        config = ROOT / "configs" / "experiments" / f"{name}.toml"
        for seed in range(args.seeds):
            this, then = fit(ROOT, config, seed, data), fit(base, config, seed, data)
            verdict = difference(this, then)
            same = same and verdict == "equal"
            print(f"{name} seed +{seed}: {verdict}; load {os.getloadavg()[0]:.1f}\n"
                  f"  this: {line(this)}\n  base: {line(then)}", flush=True)
            ratios[f"runs/{name}/seed{seed}"] = this["cpu"] / then["cpu"]
            for key, r in (("this", this), ("base", then)):
                totals[key][0] += r["wall"]
                totals[key][1] += r["cpu"]
    (tw, tc), (bw, bc) = totals["this"], totals["base"]
    print(f"total: wall {tw:.1f} s against {bw:.1f} s ({bw / tw:.2f}x), CPU {tc:.1f} s against {bc:.1f} s "
          f"({bc / tc:.2f}x); results {'equal to the bit' if same else 'NOT all equal'}")
    if args.project is not None:
        project(args.project, ratios)


def project(out: Path, ratios: dict[str, float]) -> None:
    """The trials of `out` on 2 slots in their start order, as run and with the identified
    trials (one seed each) scaled by `ratios`."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from reproduce_timeline import list_schedule, read_trials

    trials = read_trials(out)
    walls = [t.wall for t in trials]
    scaled = [t.wall * ratios.get(f"runs/{t.name}/{t.seeds[0]}", 1.0) if len(t.seeds) == 1 else t.wall
              for t in trials]
    changed = [(t, w) for t, w in zip(trials, scaled) if w != t.wall]
    print(f"{out}: {len(trials)} trials, {sum(walls):.0f} trial-seconds; the {len(changed)} identified ones "
          f"{sum(t.wall for t, _ in changed):.0f} s -> {sum(w for _, w in changed):.0f} s")
    print(f"  list schedule on 2 slots, start order: {list_schedule(walls, 2):.0f} s as run -> "
          f"{list_schedule(scaled, 2):.0f} s; lower bound max(longest, sum / 2) "
          f"{max(max(scaled), sum(scaled) / 2):.0f} s")


if __name__ == "__main__":
    main()
