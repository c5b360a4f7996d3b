"""`sysid train` of one config, timed side by side against another checkout of sysid, in one run.

Runs ``python -m sysid train CONFIG --epochs E --threads T`` alternately with this checkout's
code and with the code of `--base` (a git worktree of the commit to compare against, e.g.
``git worktree add /work/wt-base 0928648``; put first on PYTHONPATH, same interpreter and
packages), `--repeats` times each, every run into its own scratch run directory. Prints per run
the wall time [s], the CPU time of the child [s] and the run's ``val_loss_multistep`` (its
summary.json), then the medians and the ratio base / this (above 1: this checkout is faster)
and the relative difference of the validation losses. Wall time on a machine shared with other
jobs moves with their load; the child CPU time moves less, and the two commands alternate so
that both see the same load.

    python benchmarks/train_command_speed.py --base /work/wt-base [--config configs/experiments/hybrid_D2.toml]
        [--epochs 15] [--threads 1] [--repeats 1] [--data DIR]
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


def run_train(code: Path, config: Path, output: Path, epochs: int, threads: int, data: str | None) -> dict:
    """One `sysid train` with the package of checkout `code`: wall [s], child CPU [s], val loss."""
    command = [sys.executable, "-m", "sysid", "-q", "train", str(config), "-o", str(output), "--epochs", str(epochs),
               "--threads", str(threads), "--overwrite"] + (["--data", data] if data else [])
    env = {**os.environ, "PYTHONPATH": str(code)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(command, env=env, cwd=code, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"train_command_speed: {' '.join(command)} (PYTHONPATH={code}) failed:\n{done.stderr[-2000:]}")
    summary = json.loads((output / "summary.json").read_text())
    val = summary.get("val_loss_multistep", summary.get("training", {}).get("val_loss_multistep"))
    return {"wall": wall, "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "val": val}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="checkout (worktree) of the code to compare against")
    parser.add_argument("--config", default="configs/experiments/hybrid_D2.toml")
    parser.add_argument("--epochs", type=int, default=15)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--data", default=None)
    args = parser.parse_args()
    base = Path(args.base).resolve()
    if not (base / "sysid" / "__init__.py").is_file():
        raise SystemExit(f"train_command_speed: --base {base}: no sysid package there (a checkout of this repository?)")
    config = (ROOT / args.config).resolve()
    if not config.is_file():
        raise SystemExit(f"train_command_speed: --config {config}: no such file")
    print(f"sysid train {args.config} --epochs {args.epochs} --threads {args.threads}: base {base} "
          f"against {ROOT}, {args.repeats} repeat(s) each, alternating; load {os.getloadavg()[0]:.1f}", flush=True)
    results: dict[str, list[dict]] = {"base": [], "this": []}
    with tempfile.TemporaryDirectory(prefix="train_command_speed-") as scratch:
        for repeat in range(args.repeats):
            for label, code in (("base", base), ("this", ROOT)):
                out = run_train(code, config, Path(scratch) / f"{label}-{repeat}", args.epochs, args.threads, args.data)
                results[label].append(out)
                print(f"  {label:4s} run {repeat + 1}: wall {out['wall']:8.1f} s, CPU {out['cpu']:8.1f} s, "
                      f"val_loss_multistep {out['val']:.5f} (load {os.getloadavg()[0]:.1f})", flush=True)
    median = {label: {k: statistics.median(r[k] for r in rows) for k in ("wall", "cpu", "val")}
              for label, rows in results.items()}
    b, t = median["base"], median["this"]
    print(f"medians: base wall {b['wall']:.1f} s, CPU {b['cpu']:.1f} s; this wall {t['wall']:.1f} s, "
          f"CPU {t['cpu']:.1f} s; base / this: wall {b['wall'] / t['wall']:.2f}x, CPU {b['cpu'] / t['cpu']:.2f}x; "
          f"validation loss {t['val']:.5f} against {b['val']:.5f} ({100 * (t['val'] / b['val'] - 1):+.1f} %)")


if __name__ == "__main__":
    main()
