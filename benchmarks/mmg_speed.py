"""Speed of the batched MMG right-hand side and of predictions, on this machine's CPU.

Prints rows per second of forces + state derivative at batch 1, 64, 4096, 65536 (float32,
float64), the time of one 100 s Euler prediction of one ship (eager and compiled, `sysid.fast.compiled`),
and of all 30 s protocol windows of the six test files in one batch, with ratios to the
lab's numpy simulator as once measured (PERFORMANCE_NOTES.md: ~11 k rows/s batched,
~1.5 k rows/s single, 0.15-0.19 s per 100 s RK4 prediction). For the lab's simulator run
side by side in the same process, use benchmarks/prediction_speed.py.

    python benchmarks/mmg_speed.py [--no-compile] [--threads 2]
"""
from __future__ import annotations

import argparse
import time

import torch

from sysid import MMG, integrate, load_ship, predict, state_derivative
from sysid.dynamics.integrators import Integrator

LAB_BATCHED_ROWS_PER_S = 11e3
LAB_SINGLE_ROWS_PER_S = 1.5e3
LAB_PREDICTION_S = 0.17


def random_rows(batch: int, dtype: torch.dtype, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    scale = torch.tensor([10, 0.3, 10, 0.1, 3, 0.05], dtype=dtype)
    state = torch.randn(batch, 6, dtype=dtype, generator=g) * scale
    lo = torch.tensor([-5, -0.6, 0, 0], dtype=dtype)
    span = torch.tensor([20, 1.2, 5, 6.28], dtype=dtype)
    inputs = torch.rand(batch, 4, dtype=dtype, generator=g) * span + lo
    return state, inputs


def time_call(fn, min_seconds: float = 0.5, max_calls: int = 2000) -> float:
    fn()
    fn()
    calls, start = 0, time.perf_counter()
    while True:
        fn()
        calls += 1
        elapsed = time.perf_counter() - start
        if elapsed > min_seconds or calls >= max_calls:
            return elapsed / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--no-compile", action="store_true", help="skip the torch.compile figures")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    ship = load_ship("esso_osaka")
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, CPU")
    print("\n1. MMG forces + state derivative (eager), rows per second")
    print(f"{'dtype':>8} {'batch':>7} {'ms/call':>9} {'rows/s':>12} {'x lab numpy':>12}")
    for dtype in (torch.float32, torch.float64):
        model = MMG(ship, dtype=dtype)
        for batch in (1, 64, 4096, 65536):
            state, inputs = random_rows(batch, dtype)

            def call():
                with torch.no_grad():
                    forces = model(state, inputs)
                    state_derivative(state, forces.total, model.coefficients)
            per_call = time_call(call)
            rate = batch / per_call
            lab = LAB_SINGLE_ROWS_PER_S if batch == 1 else LAB_BATCHED_ROWS_PER_S
            print(f"{str(dtype)[6:]:>8} {batch:>7} {per_call * 1e3:>9.3f} {rate:>12,.0f} {rate / lab:>11.1f}x")

    print("\n2. One 100 s Euler prediction of one ship (dt = 1 s, 100 steps, torchdiffeq odeint)")
    model = MMG(ship, dtype=torch.float64)
    x0 = torch.tensor([0.0, 0.35, 0.0, 0.01, 0.2, 0.01], dtype=torch.float64)
    inputs = torch.tensor([10.0, 0.35, 2.0, 1.0], dtype=torch.float64).repeat(101, 1)
    with torch.no_grad():
        eager = time_call(lambda: integrate(model, x0, inputs, 1.0, "euler"), 1.0, 20)
    print(f"   eager:            {eager * 1e3:8.1f} ms  ({LAB_PREDICTION_S / eager:5.1f}x faster than the lab's RK4)")
    if not args.no_compile:
        start = time.perf_counter()
        with torch.no_grad():
            predict(model, x0, inputs, 1.0, Integrator("euler", compiled=True))
        compile_s = time.perf_counter() - start
        with torch.no_grad():
            compiled = time_call(lambda: predict(model, x0, inputs, 1.0, Integrator("euler", compiled=True)), 1.0, 50)
            gap = (predict(model, x0, inputs, 1.0, Integrator("euler", compiled=True))
                   - integrate(model, x0, inputs, 1.0, "euler")).abs().max()
        print(f"   compiled:         {compiled * 1e3:8.1f} ms  (compiled once in {compile_s:.0f} s; "
              f"max difference to eager {float(gap):.1e}; {eager / compiled:.1f}x eager)")

    print("\n3. All 30 s protocol windows of the six test files in one batch (Euler, float64)")
    try:
        from sysid.data.recordings import read_run
        from sysid.data.datasets import test_files
        from sysid.evaluation.evaluate import predict_windows
        runs = [read_run(p) for p in test_files().values()]
        n_windows = sum(len(r) // 30 for r in runs)
        per = time_call(lambda: predict_windows(model, runs, 30), 1.0, 20)
        print(f"   {n_windows} windows x 29 steps: {per * 1e3:.1f} ms "
              f"({n_windows * 29 / per:,.0f} window-steps/s)")
    except Exception as exc:  # the dataset is optional for this script
        print(f"   skipped: {exc}")


if __name__ == "__main__":
    main()
