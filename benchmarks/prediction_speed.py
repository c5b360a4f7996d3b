"""Prediction speed of sysid beside the lab's numpy simulator, in one process, in one run.

Prints, ours (eager and compiled) next to the lab's `mmg-1p1r-simulator`:

1. one right-hand-side call on one recorded state (float64);
2. rows per second of the batched right-hand side at 4096 and 65536 rows (ours float32),
   with --threads and with one thread per core (--batch-threads);
3. one 100 s prediction at dt 1 s from a recorded state with the recorded inputs: the
   lab's classical RK4 beside ours (RK4 and Euler) for MMG, NN-only and hybrid models
   (kNN gate in input and in feature space, bank of the D2 training samples);
4. the one-time cost: compiling each step (or loading it from the disk cache);
5. the eager MMG against the lab, interleaved: one right-hand-side call and one 100 s RK4
   prediction (dt 1 s), as speed ratios (the eager path: the Python API, every first call);
6. a compiled 600 s maneuver at dt 0.1 s (35 deg turning circle, 6000 closed-loop RK4
   steps) of --maneuver-model (a run directory of a trained model, e.g. a hybrid, or a ship
   name; default: the Esso Osaka's MMG), once the loop is compiled or loaded from the cache.

Timings alternate ours and the lab's call by call and report medians, so a busy machine
slows both alike: compare ratios, within one run. The lab simulator is optional (found in
$SYSID_SHARED/peers or ../shared/peers); without it the lab's columns are skipped.

    python benchmarks/prediction_speed.py [--threads 1] [--batch-threads 2] [--bank 20000] [--cold] [--run RUN_DIR ...]
        [--sections 12356] [--maneuver-model RUN_DIR]
"""
from __future__ import annotations

import argparse
import gc
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
STATE = ["x", "u", "y", "v", "psi", "r"]
INPUTS = ["n_prop", "delta_rad", "wind_velo_true", "wind_dir_true"]


def shared_dir() -> Path:
    return Path(os.environ.get("SYSID_SHARED", ROOT.parent / "shared"))


def load_lab():
    """The lab's simulator (`peers/lab_sim.py`), or None with the reason printed."""
    peers = shared_dir() / "peers"
    if not (peers / "lab_sim.py").is_file():
        print(f"lab simulator not found in {peers}: its columns are skipped")
        return None
    sys.path.insert(0, str(peers))
    try:
        import warnings
        warnings.filterwarnings("ignore", category=RuntimeWarning)  # its 0/0 at n = 0, by design
        from lab_sim import Sim
        return Sim()
    except (Exception, SystemExit) as exc:
        print(f"lab simulator in {peers} does not load ({exc}): its columns are skipped")
        return None


def recorded_case():
    """Start state (6,) and 101 rows of inputs of a recorded zigzag (the oracle's file)."""
    import pandas as pd
    path = shared_dir() / "oracle" / "traj_zigzag_dt1p0.csv"
    if path.is_file():
        traj = pd.read_csv(path)
        return traj[STATE].to_numpy()[0], traj[INPUTS].to_numpy(), "recorded zigzag (oracle file)"
    x0 = np.array([0.0, 0.35, 0.0, 0.01, 0.2, 0.01])
    inputs = np.tile([10.0, 0.35, 2.0, 1.0], (101, 1))
    return x0, inputs, "steady turn (oracle file absent)"


def medians(calls: dict, repeats: int, seconds: float = 3.0) -> dict:
    """Median seconds per call of each callable, calls interleaved; stops after `seconds`.

    As `timeit` does, the garbage collector is off while a call is timed, so no call pays
    for another's garbage (torchdiffeq's eager steps leave cycles); it collects once before
    the first round and, on its own thresholds, between rounds. (A full collection forced
    before every round evicts the caches of whichever call runs next, always the first of
    `calls`: it cost that call about 0.5 ms of a 6 ms prediction.)
    """
    for fn in calls.values():
        fn()
    times = {k: [] for k in calls}
    deadline = time.perf_counter() + seconds
    enabled = gc.isenabled()
    gc.collect()
    try:
        for _ in range(repeats):
            gc.disable()
            for key, fn in calls.items():
                start = time.perf_counter()
                fn()
                times[key].append(time.perf_counter() - start)
            if enabled:
                gc.enable()
            if time.perf_counter() > deadline and len(times[key]) >= 3:
                break
    finally:
        if enabled:
            gc.enable()
    return {k: statistics.median(v) for k, v in times.items()}


def random_rows(batch: int, dtype=torch.float64, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    state = torch.randn(batch, 6, dtype=torch.float64, generator=g) * torch.tensor([10, 0.3, 10, 0.1, 3, 0.05])
    state[:, 1] += 0.3
    inputs = torch.rand(batch, 4, dtype=torch.float64, generator=g) * torch.tensor([20, 1.2, 5, 6.28]) \
        + torch.tensor([-5, -0.6, 0, 0])
    return state.to(dtype), inputs.to(dtype)


def training_samples(bank: int):
    """(states, inputs, label) of the kNN bank: the D2 training files' samples (up to
    `bank`) when the dataset is present, else random rows (a harder, unstructured bank)."""
    try:
        from sysid.data.recordings import read_run
        from sysid.data.datasets import training_files
        runs = [read_run(f) for f in training_files("D2")]
        states = torch.tensor(np.concatenate([r.states for r in runs]))[:bank]
        inputs = torch.tensor(np.concatenate([r.inputs for r in runs]))[:bank]
        return states, inputs, " D2"
    except Exception as exc:  # the dataset is optional here
        print(f"   (dataset unavailable: {exc}; the kNN bank is random rows)")
        states, inputs = random_rows(bank, seed=1)
        states[:, 1] = states[:, 1].abs()
        return states, inputs, " random"


def models(bank: int, runs: list[str]):
    """(label, model) pairs: MMG, NN-only and hybrid with gates, or the given run directories."""
    from sysid import MMG, load_ship
    from sysid.hybrid.correction import ForceCorrection, correction_inputs
    from sysid.hybrid.force_models import CorrectedModel
    from sysid.hybrid.knn_gate import KNNGate
    if runs:
        from sysid.runs.layout import load_model
        return [(f"run {r}", load_model(r)[1]) for r in runs]
    out = [("MMG", MMG(load_ship("esso_osaka")))]
    states, inputs, source = training_samples(bank)
    for label, physics, space in (("NN-only, gate on inputs", False, "inputs"),
                                  ("hybrid, gate on inputs", True, "inputs"),
                                  ("hybrid, gate on features (64)", True, "features")):
        torch.manual_seed(0)
        mmg = MMG(load_ship("esso_osaka"))
        net = ForceCorrection(dtype=torch.float64)
        s = correction_inputs(states, inputs, mmg(states, inputs).relative_wind)
        net.set_standardization(s.mean(0), s.std(0), torch.zeros(3), torch.ones(3))
        model = CorrectedModel(mmg, net, None, physics=physics, gate_space=space)
        with torch.no_grad():
            z = model.gate_coordinates(s)
        model.gate, model.gate_enabled = KNNGate(10, 0.9995, z.shape[-1], torch.float64).fit(z), True
        out.append((f"{label}, bank {len(z)}{source}", model))
    return out


def timed_first_call(fn):
    start = time.perf_counter()
    result = fn()
    return result, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads (default 1)")
    parser.add_argument("--batch-threads", type=int, default=os.cpu_count() or 1,
                        help="section 2 also runs with this many threads (default: one per core)")
    parser.add_argument("--bank", type=int, default=20000,
                        help="at most this many samples in the kNN bank of the synthetic gated models")
    parser.add_argument("--run", action="append", default=[], help="benchmark these run directories instead")
    parser.add_argument("--cold", action="store_true", help="empty compile cache (measures compile time)")
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--sections", default="12356", help="which sections to run (default 12356)")
    parser.add_argument("--maneuver-model", default="esso_osaka",
                        help="section 6: run directory of a trained model (a hybrid: the issue's case) or a ship name")
    parser.add_argument("--all-methods", action="store_true",
                        help="RK4 and Euler for every model (default: both for MMG, RK4, the lab's rule, for the others)")
    args = parser.parse_args()
    if args.cold:
        os.environ["SYSID_CACHE"] = tempfile.mkdtemp(prefix="sysid-cache-")
    torch.set_num_threads(args.threads)
    from sysid import MMG, load_ship
    from sysid.fast.compiled import cache_dir

    lab = load_lab()
    x0_np, inputs_np, case = recorded_case()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} thread(s), {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.1f}; compile cache {cache_dir()}")
    print(f"case: {case}; times are medians of interleaved calls\n")
    mmg = MMG(load_ship("esso_osaka"))

    if "1" in args.sections:
        single_call(mmg, x0_np, inputs_np, lab, args.repeats)
    if "2" in args.sections:
        batched(lab, sorted({args.threads, args.batch_threads}))
    if "3" in args.sections:
        predictions(args, x0_np, inputs_np, lab, mmg)
    if "5" in args.sections:
        eager_against_lab(mmg, x0_np, inputs_np, lab, args.repeats)
    if "6" in args.sections:
        compiled_maneuver(args.maneuver_model)
    print("\n4. Training throughput: see the training benchmark (hook: benchmarks/training_speed.py)")
    hook = Path(__file__).with_name("training_speed.py")
    if hook.is_file():
        print(f"   run: python {hook.relative_to(ROOT)}")


def single_call(mmg, x0_np, inputs_np, lab, repeats: int) -> None:
    from sysid.fast.compiled import compiled_derivative
    from sysid.dynamics.equations import derivative
    print("1. One right-hand-side call on one state (float64)")
    x1 = torch.tensor(x0_np)[None]
    u1 = torch.tensor(inputs_np[0])[None]
    rhs1, first = timed_first_call(lambda: compiled_derivative(mmg, 1))
    print(f"   compiled RHS ready in {first:.1f} s ({'fell back to eager' if rhs1 is None else 'compiled or cached'})")
    calls = {"eager": lambda: derivative(mmg, x1, u1)}
    if rhs1 is not None:
        calls["compiled"] = lambda: rhs1(x1, u1)
    if lab is not None:
        calls["lab"] = lambda: lab.rhs(0.0, x0_np[None], *inputs_np[0])
    with torch.no_grad():
        t = medians(calls, repeats * 5)
    _row(t, "us", 1e6)


def batched(lab, thread_counts: list[int]) -> None:
    from sysid import MMG, load_ship
    from sysid.fast.compiled import compiled_derivative
    from sysid.dynamics.equations import derivative
    print("\n2. Batched right-hand side, rows per second (ours float32, lab float64 numpy)")
    before = torch.get_num_threads()
    m32 = MMG(load_ship("esso_osaka"), dtype=torch.float32)
    for threads in thread_counts:
        torch.set_num_threads(threads)  # large compiled kernels keep the count they were compiled with
        for batch in (4096, 65536):
            xs, us = random_rows(batch, torch.float32)
            rhs, first = timed_first_call(lambda: compiled_derivative(m32, batch, torch.float32))
            calls = {"eager": lambda: derivative(m32, xs, us)}
            if rhs is not None:
                calls["compiled"] = lambda: rhs(xs, us)
            if lab is not None:
                xl, ul = xs.double().numpy(), us.double().numpy()
                calls["lab"] = lambda: lab.rhs(0.0, xl, ul[:, 0], ul[:, 1], ul[:, 2], ul[:, 3])
            with torch.no_grad():
                t = medians(calls, 30)
            rates = {k: batch / v for k, v in t.items()}
            print(f"   {batch:>6} rows, {threads} thread(s): " + ", ".join(f"{k} {v / 1e6:,.2f} M rows/s" if k != "lab"
                                                              else f"{k} {v:,.0f} rows/s" for k, v in rates.items())
                  + (f"; compiled/lab {rates['compiled'] / rates['lab']:.0f}x" if "compiled" in rates and "lab" in rates else "")
                  + f" (compile/load {first:.1f} s)")
    torch.set_num_threads(before)


def predictions(args, x0_np, inputs_np, lab, mmg) -> None:
    from sysid import integrate, predict
    from sysid.dynamics.integrators import Integrator
    print("\n3. One 100 s prediction at dt 1 s (101 states), one ship, float64")
    x0 = torch.tensor(x0_np)
    inputs = torch.tensor(inputs_np)
    lab_pred = None
    if lab is not None:
        def lab_pred():
            s, out = x0_np[None].copy(), [x0_np[None]]
            for k in range(100):
                s = lab.rk4_step(1.0, 0.0, s, *inputs_np[k])
                out.append(s)
            return np.concatenate(out)
    header = f"   {'model':<58} {'method':<6} {'compile/load':>12} {'eager':>9} {'compiled':>9} {'lab RK4':>9} {'lab/compiled':>12}"
    print(header)
    for label, model in models(args.bank, args.run):
        for method in ("rk4", "euler") if label == "MMG" or args.all_methods else ("rk4",):
            compiled = Integrator(method, compiled=True)
            _, first = timed_first_call(lambda: predict(model, x0, inputs, 1.0, compiled))
            calls = {"compiled": lambda: predict(model, x0, inputs, 1.0, compiled)}
            if lab_pred is not None:
                calls["lab"] = lab_pred
            with torch.no_grad():  # ours and the lab's interleaved; eager (torchdiffeq) apart,
                t = medians(calls, 20, seconds=6.0)  # as its garbage slows whatever runs next
                t.update(medians({"eager": lambda: integrate(model, x0, inputs, 1.0, method)}, 5, seconds=3.0))
            ratio = f"{t['lab'] / t['compiled']:>11.0f}x" if "lab" in t else f"{'-':>12}"
            lab_ms = f"{t['lab'] * 1e3:>7.1f}ms" if "lab" in t else f"{'-':>9}"
            print(f"   {label:<58} {method:<6} {first:>11.1f}s {t['eager'] * 1e3:>7.1f}ms "
                  f"{t['compiled'] * 1e3:>7.2f}ms {lab_ms} {ratio}")
    if lab_pred is not None:
        with torch.no_grad():
            gap = np.abs(predict(mmg, x0, inputs, 1.0, Integrator("rk4", compiled=True)).numpy() - lab_pred())
        print(f"   MMG RK4, ours vs lab: max |difference| {gap[:, [1, 3, 5]].max():.1e} in u, v, r "
              f"(exact vs 100-point Simpson cross-flow)")


def eager_against_lab(mmg, x0_np, inputs_np, lab, repeats: int) -> None:
    """Section 5: the eager MMG (float64, one state) beside the lab, calls interleaved."""
    from sysid import integrate
    from sysid.dynamics.equations import derivative
    print("\n5. Eager MMG against the lab, interleaved (float64, one state)")
    if lab is None:
        print("   (no lab simulator: skipped)")
        return
    x1, u1 = torch.tensor(x0_np)[None], torch.tensor(inputs_np[0])[None]
    x0, inputs = torch.tensor(x0_np), torch.tensor(inputs_np)

    def lab_pred():
        s = x0_np[None].copy()
        for k in range(100):
            s = lab.rk4_step(1.0, 0.0, s, *inputs_np[k])
        return s

    with torch.no_grad():
        rhs = medians({"eager": lambda: derivative(mmg, x1, u1),
                       "lab": lambda: lab.rhs(0.0, x0_np[None], *inputs_np[0])}, repeats * 5)
        rk4 = medians({"eager": lambda: integrate(mmg, x0, inputs, 1.0, "rk4"), "lab": lab_pred}, 15, seconds=10.0)
    print(f"   one RHS call:        eager {rhs['eager'] * 1e6:7.0f} us, lab {rhs['lab'] * 1e6:7.0f} us: "
          f"eager/lab speed {rhs['lab'] / rhs['eager']:.2f}x")
    print(f"   100 s RK4, dt 1 s:   eager {rk4['eager'] * 1e3:7.1f} ms, lab {rk4['lab'] * 1e3:7.1f} ms: "
          f"eager/lab speed {rk4['lab'] / rk4['eager']:.2f}x")


def compiled_maneuver(model_name: str) -> None:
    """Section 6: one compiled 600 s maneuver (35 deg turning, dt 0.1 s), median of 3."""
    from sysid.maneuvers import TurningCircle, default_conditions, load_maneuver_model, simulate_maneuvers
    from sysid.maneuvers.closed_loop import compiled_loop
    print("\n6. Compiled 600 s maneuver at dt 0.1 s (35 deg turning circle, starboard)")
    subject = load_maneuver_model(model_name)
    conditions, _ = default_conditions(subject.model, subject.ship, dt=0.1, duration=600.0)
    if compiled_loop(subject.model, conditions.method) is None:
        print("   compiled loop unavailable (SYSID_COMPILE=0 or no C++ compiler): skipped")
        return
    maneuver = [TurningCircle(35.0)]
    _, first = timed_first_call(lambda: simulate_maneuvers(subject.model, maneuver, conditions, compiled=True))
    times = []
    for _ in range(3):
        start = time.perf_counter()
        simulate_maneuvers(subject.model, maneuver, conditions, compiled=True)
        times.append(time.perf_counter() - start)
    took = statistics.median(times)
    print(f"   {subject.label} ({subject.kind}): {conditions.steps} steps in {took:.3f} s "
          f"({'within' if took <= 1.0 else 'over'} 1 s); compile or cache load and first run {first:.1f} s")


def _row(times: dict, unit: str, scale: float) -> None:
    parts = [f"{k} {v * scale:.1f} {unit}" for k, v in times.items()]
    if "lab" in times:
        parts += [f"{k}/lab speed {times['lab'] / v:.2f}x" for k, v in times.items() if k != "lab"]
    print("   " + ", ".join(parts))


if __name__ == "__main__":
    main()
