"""Latency of an exported step (``sysid export``) at batch 1 on this CPU, as a controller calls it.

Exports the run's model (the compiled package and the portable program) into a temporary
folder, then times, each in a fresh python that imports torch alone (no sysid), one thread:
the package through ``torch._inductor.aoti_load_package`` (checks off, and with
``AOTI_RUNTIME_CHECK_INPUTS=1``; the package exported ``--with-gate``, which returns the kNN
gate's decision too), and the portable program through ``torch.export.load``;
beside them, in this process, sysid's eager step of the same model. Prints the median time
per step, each as a ratio to the compiled package's and as the share of a control period at
1 Hz and 10 Hz, and the time of a 60-s look-ahead (60 steps of 1 s) of each.

    python benchmarks/export_latency.py RUN_DIR [--dt 1.0] [--calls 3000]
"""
from __future__ import annotations

import argparse
import inspect
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

def timed(step, calls: int) -> dict:
    """Median seconds per call of `step` at batch 1 (a straight run's state and inputs), and
    the seconds of a 60-step look-ahead; run here and, by its source, in a fresh python."""
    import time

    import torch
    x = torch.tensor([[0.0, 0.4, 0.0, 0.0, 0.0, 0.0]], dtype=torch.float64)
    u = torch.tensor([[10.0, 0.1, 1.0, 0.5]], dtype=torch.float64)
    times = []
    with torch.no_grad():
        for _ in range(20):
            step(x, u)
        for _ in range(calls):
            t0 = time.perf_counter()
            step(x, u)
            times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        y = x
        for _ in range(60):
            y = step(y, u)
            y = y[0] if isinstance(y, (tuple, list)) else y   # --with-gate: (state, gate_on)
        ahead = time.perf_counter() - t0
    times.sort()
    return {"step": times[len(times) // 2], "ahead": ahead}


FRESH = inspect.getsource(timed) + r"""
import json, sys, torch
torch.set_num_threads(1)
path, loader, calls = sys.argv[1], sys.argv[2], int(sys.argv[3])
step = torch._inductor.aoti_load_package(path) if loader == "package" else torch.export.load(path).module()
print(json.dumps({**timed(step, calls), "sysid": "sysid" in sys.modules}))
"""


def fresh(path: Path, loader: str, calls: int, checked: bool = False) -> dict:
    """`timed` of an exported file in a python with torch alone (one thread)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("AOTI_RUNTIME_CHECK_INPUTS", None)
    if checked:
        env["AOTI_RUNTIME_CHECK_INPUTS"] = "1"
    done = subprocess.run([sys.executable, "-c", FRESH, str(path), loader, str(calls)], capture_output=True,
                          text=True, env=env, check=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert not result["sysid"]
    return result


def eager(run_dir: Path, dt: float, calls: int) -> dict:
    """`timed` of sysid's eager step of the run's model, in this process."""
    import torch

    from sysid.config.choices import Method
    from sysid.fast.stepper import Step
    from sysid.runs.layout import load_model
    torch.set_num_threads(1)
    return timed(Step(load_model(run_dir)[1], Method.EULER, dt), calls)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--dt", type=float, default=1.0)
    parser.add_argument("--calls", type=int, default=3000)
    args = parser.parse_args()
    from sysid.cli import run
    with tempfile.TemporaryDirectory() as tmp:
        compiled, portable, gated = Path(tmp) / "model.pt2", Path(tmp) / "portable.pt2", Path(tmp) / "gated.pt2"
        run(["-q", "export", str(args.run_dir), "-o", str(compiled), "--dt", repr(args.dt)])
        run(["-q", "export", str(args.run_dir), "-o", str(gated), "--dt", repr(args.dt), "--with-gate"])
        run(["-q", "export", str(args.run_dir), "-o", str(portable), "--dt", repr(args.dt), "--portable"])
        rows = {"compiled package (aoti_load_package)": fresh(compiled, "package", args.calls),
                "compiled package, AOTI_RUNTIME_CHECK_INPUTS=1": fresh(compiled, "package", args.calls, True),
                "compiled package --with-gate": fresh(gated, "package", args.calls),
                "portable program (torch.export.load)": fresh(portable, "program", max(args.calls // 10, 100)),
                "sysid eager step (in process)": eager(args.run_dir, args.dt, max(args.calls // 10, 100))}
    base = rows["compiled package (aoti_load_package)"]["step"]
    print(f"batch 1, float64, one thread, dt {args.dt:g} s; median of {args.calls} calls (fewer for the slow ones)")
    print(f"{'':48s} {'us/step':>9} {'x compiled':>10} {'of 1 s':>9} {'of 0.1 s':>9} {'60 steps [ms]':>14}")
    for name, r in rows.items():
        print(f"{name:48s} {r['step'] * 1e6:9.1f} {r['step'] / base:10.2f} {r['step'] / 1.0:9.1e} "
              f"{r['step'] / 0.1:9.1e} {r['ahead'] * 1e3:14.2f}")


if __name__ == "__main__":
    main()
