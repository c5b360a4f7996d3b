"""The native MMG kernel's entries (`sysid.mmg.native`) of this checkout beside those of another
commit (default ``main``), side by side in one process, on the hybrid D2 training step's own calls.

The calls are recorded from one training step of ``configs/experiments/hybrid_D2.toml`` (batch
256, T = 10, one network, float32): the rollout's first call (the values alone), its 9 calls
with the Jacobian and the backward's 9 vector-Jacobian products, with their gradients. Each
entry is timed through its Python face, the ctypes call and what surrounds it included:

* ``values + Jacobian``: `TrainingKernel.__call__` with the Jacobian (9 calls);
* ``values alone``: `TrainingKernel.__call__` without it (the rollout's first call);
* ``state_gradient``: `TrainingKernel.state_gradient` (9 calls);
* ``rate``: the no-grad entry `rate` (maneuvers, predictions) on the 9 states;
* ``C: values + Jac.``, ``C: state_gradient``: the library's two training entries alone (ctypes,
  outputs allocated once): the kernel without the Python around it;

at 256 rows (one network), 1280 rows (K = 5 side by side, ``sysid reproduce --seeds 5``: the rows
repeated 5 times) and 1 row (the Python around the call). The other commit's ``native.py`` and
``native_kernel.cpp`` (``git show REF:...``) are loaded as a second module with their library
built into a scratch cache, so both run on the same tensors in one process: interleaved rounds
(the two in alternating order), medians of the thread's CPU time per call (which the other jobs
of a shared machine disturb less than wall time), the ratio before / after, and whether the
outputs are the same bits.

With ``--step DIR`` instead: the whole training step (batch 256, T = 10, 1 thread, as `Trainer`
takes it: `training_speed.CheckoutStep`) of this checkout and of the checkout at DIR (e.g. a
worktree at main's commit), each in a worker process of its own, in alternating order for
``--rounds`` rounds of ``--repeats`` steps: medians of wall and process CPU time per step, their
ratios, and each side's loss before the first step.

    python benchmarks/native_kernel_speed.py [--base main] [--rounds 15] [--repeats 20] [--data DIR]
    python benchmarks/native_kernel_speed.py --step DIR [--rounds 15] [--repeats 10] [--data DIR]

With ``--in-step``: the same training step in this process, its kernel this checkout's
`TrainingKernel` or the other commit's (``--base``), alternating: the kernel's effect on the step
with the caches as a step leaves them; medians of CPU time per step and their ratio.

    python benchmarks/native_kernel_speed.py --in-step [--base main] [--rounds 15] [--repeats 10]
"""
from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))


def recorded_calls(data: str | None):
    """(c, families, mean, std, calls, gradients) of one hybrid D2 training step: `calls` the
    kernel's (state, inputs, jacobian) and `gradients` its (jacobian, g_rate, g_force, g_z), in
    order, cloned."""
    import training_speed
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import split_windows
    from sysid.mmg import native
    from sysid.runs.lifecycle import training_runs
    exp = load_experiment(ROOT / training_speed.CONFIGS["D2"])
    t = exp.training
    train = split_windows(training_runs(exp, data), t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                          t.block_s, exp.experiment.seed)[0]
    calls, gradients, kernels = [], [], []
    call, gradient = native.TrainingKernel.__call__, native.TrainingKernel.state_gradient

    def recording_call(self, state, inputs, jacobian=True):
        kernels.append(self)
        calls.append((state.detach().clone(), inputs.detach().clone(), jacobian))
        return call(self, state, inputs, jacobian)

    def recording_gradient(self, jacobian, g_rate, g_force, g_z):
        gradients.append((jacobian.clone(), *[None if g is None else g.clone() for g in (g_rate, g_force, g_z)]))
        return gradient(self, jacobian, g_rate, g_force, g_z)
    step = training_speed.training_step(exp, train, 256, 1, fast=True, trainer=True)[0]
    native.TrainingKernel.__call__, native.TrainingKernel.state_gradient = recording_call, recording_gradient
    try:
        step()
    finally:
        native.TrainingKernel.__call__, native.TrainingKernel.state_gradient = call, gradient
    if not calls:
        raise SystemExit("native_kernel_speed: the step made no native kernel call (is the kernel built? see the log)")
    from sysid.hybrid.force_models import build_mmg
    c = build_mmg(exp, torch.float32).coefficients.values_view(torch.float32)
    kernel = kernels[0]
    return c, kernel.families, kernel._keep[1], kernel._keep[2], calls, gradients


def module_at(ref: str, scratch: Path):
    """``sysid.mmg.native`` of commit `ref` as a module of its own, its library built in `scratch`."""
    for name in ("native.py", "native_kernel.cpp"):
        shown = subprocess.run(["git", "show", f"{ref}:sysid/mmg/{name}"], cwd=ROOT, capture_output=True, text=True)
        if shown.returncode != 0:
            raise SystemExit(f"native_kernel_speed: git show {ref}:sysid/mmg/{name} failed: {shown.stderr.strip()}")
        (scratch / name).write_text(shown.stdout)
    spec = importlib.util.spec_from_file_location("native_before", scratch / "native.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    module._STATE["library"] = module.load(module.build(scratch / "cache").path)
    return module


def repeated(t: torch.Tensor | None, k: int) -> torch.Tensor | None:
    """`t` (1, rows, ...) as (k, rows, ...) (K members' rows), or its first row (1, 1, ...) for k = 0."""
    if t is None:
        return None
    if k == 0:
        return t[:, :1].contiguous() if t.dim() > 2 else t[:1].contiguous()
    return t.expand(k, *t.shape[1:]).contiguous() if t.dim() > 2 else t.repeat(k, *[1] * (t.dim() - 1))


def entries(module, c, families, mean, std, calls, gradients):
    """name -> a function of no argument running that entry over the recorded calls, with its
    outputs (for the bit check) from the last run."""
    kernel = module.TrainingKernel(c, families, mean, std, torch.float32)
    first = [x for x in calls if not x[2]]
    rest = [x for x in calls if x[2]]
    jacobians = [kernel(s, i, True)[3] for s, i, _ in rest]
    gradients = [(j, *g[1:]) for j, g in zip(jacobians, gradients)]

    def with_jacobian():
        return [kernel(s, i, True) for s, i, _ in rest]

    def alone():
        return [kernel(s, i, False) for s, i, _ in first]

    def vjp():
        return [kernel.state_gradient(*g) for g in gradients]

    def rate():
        return [module.rate(s, i, c, families) for s, i, _ in rest]

    # the C entries alone (ctypes, outputs allocated once): the kernel without the Python around it
    pointers = [(s.numel() // 6, s.data_ptr(), i.data_ptr()) for s, i, _ in rest]
    out = [torch.empty(n * 126, dtype=torch.float32) for n, _, _ in pointers]
    coefficients, mean_p, std_p = kernel._pointers

    def raw_jacobian():
        for (n, s, i), o in zip(pointers, out):
            p = o.data_ptr()
            kernel._training(n, s, i, coefficients, kernel.families, mean_p, std_p, p, p + 24 * n, p + 36 * n,
                             p + 72 * n)
        return out
    vjp_out = [torch.empty(j.numel() // 18, dtype=torch.float32) for j in jacobians]
    keep = [[None if x is None else x.contiguous() for x in g[1:]] for g in gradients]
    vjp_pointers = [tuple(None if x is None else x.data_ptr() for x in k) for k in keep]

    def raw_vjp():
        for j, g, o in zip(jacobians, vjp_pointers, vjp_out):
            kernel._gradient(j.numel() // 108, j.data_ptr(), *g, o.data_ptr())
        return vjp_out
    return {"values + Jacobian": (with_jacobian, len(rest)), "values alone": (alone, len(first)),
            "state_gradient": (vjp, len(gradients)), "rate": (rate, len(rest)),
            "C: values + Jac.": (raw_jacobian, len(rest)), "C: state_gradient": (raw_vjp, len(gradients))}


def same_bits(a, b) -> bool:
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same_bits(x, y) for x, y in zip(a, b))
    if a is None or b is None:
        return a is None and b is None
    return a.shape == b.shape and bool(torch.equal(a.view(torch.int32), b.view(torch.int32)))


def steps_side_by_side(other: str, data: str | None, rounds: int, repeats: int) -> None:
    """The training step of this checkout and of `other`, in worker processes, alternating."""
    from training_speed import CONFIGS, CheckoutStep
    sides = {"this": CheckoutStep(str(ROOT), CONFIGS["D2"], data, 256, 1),
             "other": CheckoutStep(other, CONFIGS["D2"], data, 256, 1)}
    wall: dict[str, list[float]] = {k: [] for k in sides}
    cpu: dict[str, list[float]] = {k: [] for k in sides}
    try:
        for r in range(rounds):
            for side in (("this", "other") if r % 2 == 0 else ("other", "this")):
                w, c = sides[side].times(repeats)
                wall[side].append(w)
                cpu[side].append(c)
    finally:
        for step in sides.values():
            step.close()
    w = {k: statistics.median(v) for k, v in wall.items()}
    c = {k: statistics.median(v) for k, v in cpu.items()}
    print(f"training step, hybrid D2, batch 256, T = 10, 1 thread ({rounds} alternating rounds of {repeats} steps, "
          f"medians; ratio: the other's time over this one's)")
    print(f"{'':6s} {'wall ms':>8s} {'ratio':>7s} {'CPU ms':>8s} {'ratio':>7s}  loss before the first step")
    for k, name in (("this", str(ROOT)), ("other", other)):
        print(f"{k:6s} {1e3 * w[k]:8.2f} {w[k] / w['this']:6.3f}x {1e3 * c[k]:8.2f} {c[k] / c['this']:6.3f}x  "
              f"{sides[k].first_loss:.10g} ({name})")


def kernels_in_the_step(base: str, data: str | None, rounds: int, repeats: int) -> None:
    """The training step with this checkout's `TrainingKernel` and with `base`'s, alternating."""
    import training_speed
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import split_windows
    from sysid.mmg import native
    from sysid.runs.lifecycle import training_runs
    exp = load_experiment(ROOT / training_speed.CONFIGS["D2"])
    t = exp.training
    train = split_windows(training_runs(exp, data), t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                          t.block_s, exp.experiment.seed)[0]
    ours = native.TrainingKernel
    with tempfile.TemporaryDirectory() as scratch:
        classes = {"before": module_at(base, Path(scratch)).TrainingKernel, "after": ours}
        steps = {k: training_speed.training_step(exp, train, 256, 1, fast=True, trainer=True) for k in classes}
        times: dict[str, list[float]] = {k: [] for k in classes}
        losses = {}
        try:
            for r in range(rounds):
                for side in (("before", "after") if r % 2 == 0 else ("after", "before")):
                    native.TrainingKernel = classes[side]
                    step, loss = steps[side]
                    if r == 0:
                        with torch.no_grad():
                            losses[side] = float(loss())
                    step()
                    start = time.thread_time()
                    for _ in range(repeats):
                        step()
                    times[side].append((time.thread_time() - start) / repeats)
        finally:
            native.TrainingKernel = ours
    b, a = statistics.median(times["before"]), statistics.median(times["after"])
    print(f"training step, hybrid D2, batch 256, T = 10, 1 thread, one process, its kernel {base}'s or this "
          f"checkout's ({rounds} alternating rounds of {repeats} steps, medians of CPU time): before {1e3 * b:.2f} ms, "
          f"after {1e3 * a:.2f} ms, {b / a:.3f}x; loss before the first step {losses['before']:.10g} and "
          f"{losses['after']:.10g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="main", help="the commit to compare against (default: main)")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--repeats", type=int, default=20, help="passes over the recorded calls per round")
    parser.add_argument("--data", default=None)
    parser.add_argument("--step", default=None, metavar="DIR",
                        help="instead: the whole training step of this checkout beside the checkout at DIR")
    parser.add_argument("--in-step", action="store_true",
                        help="instead: the training step in this process with either commit's kernel")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.in_step:
        kernels_in_the_step(args.base, args.data, args.rounds, args.repeats)
        return
    if args.step:
        steps_side_by_side(args.step, args.data, args.rounds, args.repeats)
        return
    from sysid.mmg import native
    if not native.available():
        raise SystemExit("native_kernel_speed: the native kernel is not available here (see the log line above)")
    c, families, mean, std, calls, gradients = recorded_calls(args.data)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
    base = subprocess.run(["git", "rev-parse", "--short", args.base], cwd=ROOT, capture_output=True, text=True).stdout
    print(f"torch {torch.__version__}, 1 thread; before: {args.base} ({base.strip()}), after: this checkout "
          f"({head.strip()}, working tree); {args.rounds} interleaved rounds of {args.repeats} passes, medians of CPU time per call")
    with tempfile.TemporaryDirectory() as scratch:
        before = module_at(args.base, Path(scratch))
        print(f"{'entry':18s} {'rows':>5s} {'before us':>10s} {'after us':>9s} {'ratio':>6s}  same bits (CPU us per call)")
        for k, label in ((1, 256), (5, 1280), (0, 1)):
            sized = [(repeated(s, k), repeated(i, k), j) for s, i, j in calls]
            grads = [(None, *[repeated(g, k) for g in x[1:]]) for x in gradients]
            sides = {"before": entries(before, c, families, mean, std, sized, grads),
                     "after": entries(native, c, families, mean, std, sized, grads)}
            for name in sides["after"]:
                times: dict[str, list[float]] = {"before": [], "after": []}
                outputs = {}
                for r in range(args.rounds):
                    for side in (("before", "after") if r % 2 == 0 else ("after", "before")):
                        run, n = sides[side][name]
                        outputs[side] = run()
                        start = time.thread_time()
                        for _ in range(args.repeats):
                            run()
                        times[side].append((time.thread_time() - start) / (args.repeats * n))
                b, a = statistics.median(times["before"]), statistics.median(times["after"])
                same = "yes" if same_bits(outputs["before"], outputs["after"]) else "NO"
                print(f"{name:18s} {label:5d} {1e6 * b:10.1f} {1e6 * a:9.1f} {b / a:5.2f}x  {same}", flush=True)


if __name__ == "__main__":
    main()
