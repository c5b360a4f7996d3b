"""Training throughput of the multi-step loss on the real data (D1, D2), one process.

Prints, per data set and batch size: time per minibatch (forward + backward + Adam step of
the config's T Euler steps of the hybrid right-hand side), window-steps per second and epochs per
second; with --members K the time of a step that trains K networks side by side (the
FNN's member axis; what K seeds trained in one process would cost) beside one network and
beside the K networks' step through the separate Functions (kernel, layers; not fused);
with --limit the step at the config's batch beside its arithmetic limit (the FLOP count of the
FNN's products and the measured time of that arithmetic alone: the products and tanh of T
forward steps and their backward, without the MMG, the integrator or autograd's bookkeeping)
and beside the step's own arithmetic (its layers' and native kernel's calls alone);
with --compiled the step whose hybrid right-hand side (MMG, FNN, equations of motion) is one
torch.compile'd function (Inductor; its caches persist in TORCHINDUCTOR_CACHE_DIR, so a second
run of this script measures the warm start) beside today's eager step, interleaved, with the
time of its first step (the compile, or the cache load) and the two losses;
with --ops the aten operations dispatched by one right-hand-side call of the training loss
(forward with the force record, its backward) and by the MMG's forward alone, and by one call
of the training path with the MMG's hand-derived VJP (`sysid.mmg.vjp`) and its backward;
with --vjp the step through the hand-derived VJP (the training default) beside the step
through autograd (the path before it), interleaved, wall and CPU time, and both losses;
with --native the step through the native MMG kernel (`sysid.mmg.native`, the training default
where it is built) beside the step through the torch VJP and through autograd, interleaved, wall
and CPU time, the losses, and the kernel's first-use build with a cold and a warm cache; with
--against DIR also the step of the checkout at DIR (its own code, in a subprocess started once,
alternating with this one's; e.g. /work/wt-trainspeed-base at 0928648); with --ship NAME the
hybrid's MMG is that ship file's (e.g. kvlcc2_l7, the standard families) on the config's windows;
with --profile the
operators of this step by CPU time (torch.profiler); with --converge also the wall time of a whole training to its early stop; with
--parts the CPU time of the pieces of an epoch and of the seed ensembles' evaluation, each
beside the way it was done before (interleaved repeats, medians of process CPU time, which a
machine shared with other jobs disturbs less than wall time).

    python benchmarks/training_speed.py [--data DIR] [--threads 1] [--only D2] [--batches 256] [--members K]
        [--limit] [--vjp] [--native] [--against DIR] [--ship NAME] [--profile] [--ops] [--converge] [--parts]
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from sysid.data.datasets import data_root
from sysid.dynamics.integrators import Integrator
from sysid.errors import DataError
from sysid.config.experiment import load_experiment
from sysid.runs.lifecycle import training_runs
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.hybrid.correction import ForceCorrection
from sysid.identify.trainer import Trainer, multistep_loss, split_windows

CONFIGS = {"D1": "configs/experiments/hybrid_D1.toml", "D2": "configs/experiments/hybrid_D2.toml"}


def training_step(exp, train, batch: int, members: int | None = None, fast: bool = True, trainer: bool = False):
    """One training step (forward, backward, Adam) on the first `batch` windows, as a
    function, and its loss function: the multi-step loss L_v + 1e-3 L_F through the
    hand-derived VJP of the MMG (`fast`, the training default) or through autograd; with
    `trainer`, the step as `Trainer` takes it: lambda_v L_v + lambda_F L_F + lambda_L2
    |theta|^2 of the config, Adam with ``foreach`` (`_WORKER`'s step; with `fast`, the
    trainer's `sysid.identify.loop.GradientStep` itself)."""
    from sysid.dynamics.equations import integrate_training
    from sysid.identify.trainer import VEL, adam, output_penalty, velocity_loss, weight_norm
    torch.manual_seed(0)
    mmg = build_mmg(exp, torch.float32).requires_grad_(False)
    net = ForceCorrection(exp.network.hidden, torch.float32, members or exp.network.members)
    model = PerMember(CorrectedModel(mmg, net, None, True, exp.gate.space))
    w_v = 1.0 / train.states[:, :, [1, 3, 5]].reshape(-1, 3).var(0)
    w_F = torch.ones(3)
    t = exp.training
    lambdas = (t.lambda_v, t.lambda_F, t.lambda_L2) if trainer else (1.0, 1e-3, 0.0)
    opt = adam(net.parameters(), t.learning_rate) if trainer else torch.optim.Adam(net.parameters(), 1e-3)
    chunk = train.select(torch.arange(min(batch, len(train))))
    k = net.members
    states = chunk.states.unsqueeze(1).expand(-1, k, -1, -1)
    inputs = chunk.inputs.unsqueeze(1).expand(-1, k, -1, -1)

    def loss():
        pred, f_nn, f_mmg = integrate_training(model, states[0], inputs, chunk.dt, fast)
        loss_v = velocity_loss(pred[1:, ..., VEL] - states[1:, ..., VEL], w_v)
        value = lambdas[0] * loss_v + lambdas[1] * output_penalty(f_nn, f_mmg, w_F).mean()
        return value + lambdas[2] * weight_norm(net) if trainer else value

    if trainer and fast:  # the trainer's own step (its loss: `loss`'s numbers)
        from sysid.identify.loop import GradientStep
        gradient_step = GradientStep(exp)

        def step():
            gradient_step(model, chunk, w_v, w_F, opt, "train", 1, t.learning_rate)
        return step, loss

    def step():
        value = loss()
        opt.zero_grad()
        value.backward()
        opt.step()
    return step, loss


def minibatch_seconds(exp, train, batch: int, repeats: int = 8, members: int | None = None,
                      fast: bool = True) -> float:
    """Mean wall time [s] of one training step on `batch` windows (`members` networks side
    by side, each on the same windows; default: the config's); `fast`: through the MMG's
    hand-derived VJP (the training default), else through autograd."""
    step = training_step(exp, train, batch, members, fast)[0]
    for _ in range(2):
        step()
    start = time.perf_counter()
    for _ in range(repeats):
        step()
    return (time.perf_counter() - start) / repeats


@contextlib.contextmanager
def separate_functions():
    """Members side by side (K > 1) through the separate autograd Functions (the native
    kernel's, the layers') instead of the fused right-hand side (`sysid.hybrid.fused_rate`)."""
    fused = CorrectedModel._fused_training_rate

    def fused_for_one(coefficients, net, families, otherwise):
        return fused(coefficients, net, families, otherwise) if net.members == 1 else otherwise
    CorrectedModel._fused_training_rate = staticmethod(fused_for_one)
    try:
        yield
    finally:
        CorrectedModel._fused_training_rate = staticmethod(fused)


def per_step_seconds(step, repeats: int) -> tuple[float, float]:
    """(wall, process CPU) seconds per call of `step` over `repeats` calls, after one warm-up."""
    step()
    start, start_cpu = time.perf_counter(), time.process_time()
    for _ in range(repeats):
        step()
    return (time.perf_counter() - start) / repeats, (time.process_time() - start_cpu) / repeats


def vjp_comparison(exp, train, batch: int, repeats: int = 5, rounds: int = 5) -> None:
    """The step through the hand-derived VJP against the step through autograd, interleaved:
    medians of wall and process CPU time per step, the ratio, and the two losses."""
    old, old_loss = training_step(exp, train, batch, 1, fast=False)
    new, new_loss = training_step(exp, train, batch, 1, fast=True)
    losses = float(old_loss().detach()), float(new_loss().detach())
    wall: dict[str, list[float]] = {"old": [], "new": []}
    cpu: dict[str, list[float]] = {"old": [], "new": []}
    for _ in range(rounds):
        for label, step in (("old", old), ("new", new)):
            w, c = per_step_seconds(step, repeats)
            wall[label].append(w)
            cpu[label].append(c)
    w_old, w_new = statistics.median(wall["old"]), statistics.median(wall["new"])
    c_old, c_new = statistics.median(cpu["old"]), statistics.median(cpu["new"])
    print(f"hand-derived VJP against autograd, batch {min(batch, len(train))}, T = {exp.training.steps}, K = 1 "
          f"({rounds} interleaved rounds of {repeats} steps, medians): wall {1e3 * w_new:.1f} against "
          f"{1e3 * w_old:.1f} ms/step ({w_old / w_new:.2f}x), CPU {1e3 * c_new:.1f} against {1e3 * c_old:.1f} "
          f"ms/step ({c_old / c_new:.2f}x); loss before the first step {losses[1]:.9g} against {losses[0]:.9g}")


# the step of another checkout (PYTHONPATH set to it) as its `Trainer` takes it; run
# as a worker that reads a number of steps per line and answers "wall cpu" seconds per step
_WORKER = r"""
import sys, time, torch
from sysid.config.experiment import load_experiment
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.identify.trainer import adam, multistep_loss, split_windows, weight_norm
from sysid.runs.lifecycle import training_runs
config, data, batch, threads = sys.argv[1], sys.argv[2] or None, int(sys.argv[3]), int(sys.argv[4])
torch.set_num_threads(threads)
exp = load_experiment(config)
t = exp.training
train = split_windows(training_runs(exp, data), t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                      t.block_s, exp.experiment.seed)[0]
torch.manual_seed(0)
net = ForceCorrection(exp.network.hidden, torch.float32, 1)
model = PerMember(CorrectedModel(build_mmg(exp, torch.float32).requires_grad_(False), net, None, True, exp.gate.space))
w_v = 1.0 / train.states[:, :, [1, 3, 5]].reshape(-1, 3).var(0)
opt = adam(net.parameters(), t.learning_rate)
chunk = train.select(torch.arange(min(batch, len(train))))
def loss():
    loss_v, loss_F = multistep_loss(model, chunk, w_v, torch.ones(3))
    return t.lambda_v * loss_v + t.lambda_F * loss_F + t.lambda_L2 * weight_norm(net)
try:  # the trainer's own step where the checkout has one (sysid.identify.loop.GradientStep)
    from sysid.identify.loop import GradientStep
    gradient_step = GradientStep(exp)
    def step():
        gradient_step(model, chunk, w_v, torch.ones(3), opt, "train", 1, t.learning_rate)
except ImportError:
    def step():
        value = loss()
        opt.zero_grad()
        value.backward()
        opt.step()
with torch.no_grad():
    first = float(loss())
step()
print("ready", first, flush=True)
for line in sys.stdin:
    n = int(line)
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(n):
        step()
    print((time.perf_counter() - wall) / n, (time.process_time() - cpu) / n, flush=True)
"""


class CheckoutStep:
    """The training step of the checkout at `directory`, in a worker process (`_WORKER`)."""

    def __init__(self, directory: str, config: str, data: str | None, batch: int, threads: int):
        env = dict(os.environ, PYTHONPATH=str(Path(directory).resolve()))
        self.process = subprocess.Popen([sys.executable, "-c", _WORKER, config, data or "", str(batch), str(threads)],
                                        cwd=directory, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True)
        ready = self.process.stdout.readline().split()
        if not ready or ready[0] != "ready":
            raise SystemExit(f"training_speed: the step of {directory} did not start")
        self.first_loss = float(ready[1])

    def times(self, steps: int) -> tuple[float, float]:
        """(wall, CPU) seconds per step over `steps` steps."""
        self.process.stdin.write(f"{steps}\n")
        self.process.stdin.flush()
        wall, cpu = self.process.stdout.readline().split()
        return float(wall), float(cpu)

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait()


def native_comparison(exp, config: str, train, batch: int, data: str | None, against: str | None, threads: int,
                      repeats: int = 5, rounds: int = 5) -> None:
    """The step as `Trainer` takes it through the native kernel, through the torch path
    (`sysid.mmg.native.torch_path`: the torch VJP of the Esso Osaka's MMG, autograd over the
    forward for other families) and through autograd, with `against`'s step (another checkout) when given, interleaved:
    medians of wall and CPU time per step, their ratios, the losses before the first step; and
    the kernel's build with a cold cache (a fresh directory) and a warm one."""
    from sysid.mmg import native
    with tempfile.TemporaryDirectory() as scratch:
        cold = native.build(Path(scratch))
        warm = native.build(Path(scratch))
    print(f"native kernel: first use with a cold cache {cold.seconds:.2f} s (compiled: {cold.compiled}), "
          f"with a warm cache {1e3 * warm.seconds:.1f} ms (compiled: {warm.compiled})")
    if not native.available():
        raise SystemExit("training_speed: the native kernel is not available here (see the log line above)")

    def via_torch(fn):
        def run():
            with native.torch_path():
                return fn()
        return run
    new, new_loss = training_step(exp, train, batch, 1, fast=True, trainer=True)
    vjp, vjp_loss = training_step(exp, train, batch, 1, fast=True, trainer=True)
    old, old_loss = training_step(exp, train, batch, 1, fast=False, trainer=True)
    steps = {"native": new, "torch path": via_torch(vjp), "autograd": old}
    losses = {"native": new_loss(), "torch path": via_torch(vjp_loss)(), "autograd": old_loss()}
    losses = {k: float(v.detach()) for k, v in losses.items()}
    checkout = CheckoutStep(against, config, data, batch, threads) if against else None
    wall: dict[str, list[float]] = {k: [] for k in [*steps, "against"]}
    cpu: dict[str, list[float]] = {k: [] for k in [*steps, "against"]}
    try:
        for _ in range(rounds):
            for label, step in steps.items():
                w, c = per_step_seconds(step, repeats)
                wall[label].append(w)
                cpu[label].append(c)
            if checkout is not None:
                w, c = checkout.times(repeats)
                wall["against"].append(w)
                cpu["against"].append(c)
    finally:
        if checkout is not None:
            checkout.close()
    med_w = {k: statistics.median(v) for k, v in wall.items() if v}
    med_c = {k: statistics.median(v) for k, v in cpu.items() if v}
    print(f"step, batch {min(batch, len(train))}, T = {exp.training.steps}, K = 1 ({rounds} interleaved rounds of "
          f"{repeats} steps, medians; ratios: the other's time over the native step's)")
    print(f"{'':12s} {'wall ms':>8} {'ratio':>7} {'CPU ms':>8} {'ratio':>7}  loss before the first step")
    for label in med_w:
        name = f"{against}" if label == "against" else label
        loss = checkout.first_loss if label == "against" else losses[label]
        print(f"{label:12s} {1e3 * med_w[label]:8.1f} {med_w[label] / med_w['native']:6.2f}x "
              f"{1e3 * med_c[label]:8.1f} {med_c[label] / med_c['native']:6.2f}x  {loss:.9g}"
              + (f" ({name}, its own code)" if label == "against" else ""))


def profile_step(exp, train, batch: int, rows: int = 25) -> None:
    """The operators of the training step (native kernel) by self CPU time, torch.profiler."""
    from torch.profiler import ProfilerActivity, profile
    step = training_step(exp, train, batch, 1, fast=True, trainer=True)[0]
    for _ in range(3):
        step()
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        for _ in range(10):
            step()
    print(f"torch.profiler, 10 steps, batch {min(batch, len(train))}:")
    print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=rows))


def compiled_comparison(exp, train, batch: int, repeats: int = 5) -> None:
    """Today's eager step and the step with a compiled right-hand side, interleaved (medians),
    on the same network, windows and losses (batch `batch`, K = 1)."""
    from torchdiffeq import odeint
    from sysid.dynamics.equations import derivative_channels
    from sysid.hybrid.correction import correction_inputs
    from sysid.identify.trainer import VEL, adam, output_penalty, velocity_loss
    from sysid.mmg.coefficients import PackedCoefficients

    mmg = build_mmg(exp, torch.float32).requires_grad_(False)
    net = ForceCorrection(exp.network.hidden, torch.float32, 1)
    model = PerMember(CorrectedModel(mmg, net, None, True, exp.gate.space))
    w_v = 1.0 / train.states[:, :, [1, 3, 5]].reshape(-1, 3).var(0)
    w_F = 1.0 / net.output_std
    opt = adam(net.parameters(), 1e-3)
    chunk = train.select(torch.arange(min(batch, len(train))))
    packed = PackedCoefficients(mmg.coefficients)
    index = dict(packed.index)

    class Values:  # the packed coefficients read by name, in the compiled function
        def __init__(self, values):
            self.values = values

        def __getattr__(self, name):
            return self.values[index[name]]

        def values_view(self, dtype=None):
            return self

    def rate(state, inputs, values, mu_s, sd_s, mu_F, sd_F, *layers):
        c = Values(values)
        f_mmg, wind, _ = mmg._total_force(state, inputs, c, True)
        z = (correction_inputs(state, inputs, torch.cat(wind, -1)) - mu_s) / sd_s
        for i in range(0, len(layers), 2):
            z = torch.baddbmm(layers[i + 1].unsqueeze(1), z.reshape(1, -1, z.shape[-1]), layers[i])
            z = torch.tanh(z) if i + 2 < len(layers) else z
        f_nn = z.reshape(*state.shape[:-1], 3) * sd_F + mu_F
        total = (f_mmg + f_nn).unbind(-1)
        return torch.stack(derivative_channels(state, total, c), -1), f_nn, f_mmg
    compiled = torch.compile(rate, dynamic=False)

    class Rate(torch.nn.Module):
        def __init__(self, inputs, record):
            super().__init__()
            self.inputs, self.record = inputs, record

        def forward(self, tau, x):
            k = min(max(int(tau), 0), self.inputs.shape[0] - 1)
            layers = [t for pair in zip(net.weights, net.biases) for t in pair]
            dx, f_nn, f_mmg = compiled(x, self.inputs[k], packed.values, net.input_mean, net.input_std,
                                       net.output_mean, net.output_std, *layers)
            self.record.append((f_nn, f_mmg))
            return chunk.dt * dx

    def compiled_loss():
        states, inputs, record = chunk.states.unsqueeze(1), chunk.inputs.unsqueeze(1), []
        tau = torch.arange(inputs.shape[0], dtype=states.dtype)
        pred = odeint(Rate(inputs, record), states[0], tau, method="euler")
        loss_v = velocity_loss(pred[1:, ..., VEL] - states[1:, ..., VEL], w_v)
        f_nn, f_mmg = (torch.stack(f) for f in zip(*record))
        return loss_v, output_penalty(f_nn, f_mmg, w_F).mean()

    def step(loss_fn):
        def run():
            loss_v, loss_F = loss_fn()
            loss = loss_v + exp.training.lambda_F * loss_F
            opt.zero_grad()
            loss.backward()
            opt.step()
        return run
    eager = step(lambda: multistep_loss(model, chunk, w_v, w_F))
    fast = step(compiled_loss)
    with torch.no_grad():
        before = [float(v) for v in multistep_loss(model, chunk, w_v, w_F)]
    start = time.perf_counter()
    with torch.no_grad():
        after = [float(v) for v in compiled_loss()]
    first_forward = time.perf_counter() - start
    start = time.perf_counter()
    fast()
    first_step = time.perf_counter() - start
    times = {"eager": [], "compiled": []}
    for _ in range(3):
        for label, fn in (("eager", eager), ("compiled", fast)):
            fn()
            start = time.perf_counter()
            for _ in range(repeats):
                fn()
            times[label].append((time.perf_counter() - start) / repeats)
    a, b = statistics.median(times["eager"]), statistics.median(times["compiled"])
    print(f"compiled right-hand side, batch {len(chunk)}: first no-gradient call {first_forward:.1f} s and first step "
          f"{first_step:.1f} s (compile or cache load; cache {os.environ.get('TORCHINDUCTOR_CACHE_DIR', 'default')}); "
          f"{1e3 * b:.1f} ms/step against eager {1e3 * a:.1f} ({a / b:.2f}x); losses (L_v, L_F) "
          f"{after[0]:.6g}, {after[1]:.6g} against {before[0]:.6g}, {before[1]:.6g}")


def operation_counts(exp, train, batch: int) -> None:
    """Aten operations dispatched by one training right-hand-side call (K = 1, `batch` rows)."""
    from torch.utils._python_dispatch import TorchDispatchMode
    from sysid.dynamics.equations import ShipDynamics, TrainingDynamics

    class Count(TorchDispatchMode):
        def __init__(self):
            super().__init__()
            self.n = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            self.n += 1
            return func(*args, **(kwargs or {}))

    mmg = build_mmg(exp, torch.float32).requires_grad_(False)
    net = ForceCorrection(exp.network.hidden, torch.float32, 1)
    chunk = train.select(torch.arange(min(batch, len(train))))
    x = chunk.states[1].unsqueeze(0).clone().requires_grad_(True)  # a state inside a rollout
    inputs = chunk.inputs.unsqueeze(1)
    rhs = ShipDynamics(PerMember(CorrectedModel(mmg, net, None, True, exp.gate.space)), inputs, chunk.dt, [])
    rhs(torch.tensor(0.0), x)  # the coefficient views are made on a first call
    counts = {}
    for label, fn in (("MMG forward (F_MMG)", lambda: mmg.total_force(x, inputs[1])),
                      ("right-hand side with the force record", lambda: rhs(torch.tensor(1.0), x))):
        with Count() as c:
            out = fn()
        counts[label] = c.n
    with Count() as c:
        out.sum().backward()
    counts["its backward"] = c.n
    fast = TrainingDynamics(rhs.force_model.training_rate(), inputs, chunk.dt)
    x.grad = None
    fast(torch.tensor(0.0), x)  # the coefficient look-ups are cached on a first call
    with Count() as c:
        out = fast(torch.tensor(1.0), x)
    counts["the same through the hand-derived VJP"] = c.n
    with Count() as c:
        out.sum().backward()
    counts["its backward "] = c.n
    print(f"aten operations per right-hand-side call, batch {len(chunk)}: "
          + ", ".join(f"{k.strip()} {v}" for k, v in counts.items()))
    # what a hand-derived backward of the MMG could save at most: its forward without autograd
    # (plain guard forms) against its forward and backward through autograd, interleaved
    with Count() as c:
        with torch.no_grad():
            mmg.total_force(x, inputs[1])
    plain_ops = c.n
    weights = torch.randn(x.shape[:-1] + (3,))

    def autograd_pass():
        x.grad = None
        (mmg.total_force(x, inputs[1])[0] * weights).sum().backward()

    def plain_pass():
        with torch.no_grad():
            mmg.total_force(x, inputs[1])
    def whole_pass():
        x.grad = None
        rhs.record.clear()
        rhs(torch.tensor(1.0), x).sum().backward()
    def vjp_pass():
        x.grad = None
        fast.f_nn.clear()
        fast.f_mmg.clear()
        fast(torch.tensor(1.0), x).sum().backward()
    times: dict[str, list[float]] = {"whole": [], "autograd": [], "plain": [], "vjp": []}
    for _ in range(5):
        for label, fn in (("whole", whole_pass), ("autograd", autograd_pass), ("plain", plain_pass),
                          ("vjp", vjp_pass)):
            times[label] += cpu_ms(lambda fn=fn: [fn() for _ in range(10)], 1)
    w, a, b, v = (statistics.median(times[k]) / 10 for k in ("whole", "autograd", "plain", "vjp"))
    print(f"CPU ms per call, batch {len(chunk)}: the right-hand side forward and backward {w:.2f}, of which the MMG's "
          f"{a:.2f} through autograd; the MMG's forward without autograd {b:.2f} ({plain_ops} operations, "
          f"{a / b:.1f}x less than through autograd); the right-hand side through the hand-derived VJP, forward "
          f"and backward, {v:.2f} ({w / v:.2f}x less than through autograd)")


def network_flops(widths: list[int], rows: int, steps: int) -> tuple[float, float]:
    """(forward, forward + backward) FLOP of the FNN's products for `rows` windows over `steps`
    Euler steps: 2 n_in n_out per row and layer forward; backward twice that (the gradient of
    the weights and of the layer's input, which the rollout needs for every layer)."""
    forward = sum(2.0 * a * b for a, b in zip(widths[:-1], widths[1:])) * rows * steps
    return forward, 3.0 * forward


def own_arithmetic_seconds(exp, train, rows: int, repeats: int = 8) -> tuple[float, float]:
    """(the FNN's, the native kernel's) mean wall time [s] of one training step's arithmetic as
    the step computes it, without autograd, the integrator or Adam: per Euler step the layers
    forward (`sysid.hybrid.layers.forward_single`) and the kernel's values (with their Jacobian
    but at the first step), then per step the layers' backward (`sysid.hybrid.layers.backward`)
    and the kernel's vector-Jacobian product, on the first `rows` windows' recorded states."""
    from sysid.hybrid import layers
    from sysid.mmg import native
    torch.manual_seed(0)
    mmg = build_mmg(exp, torch.float32).requires_grad_(False)
    net = ForceCorrection(exp.network.hidden, torch.float32, 1)
    c = mmg.coefficients.values_view(torch.float32)
    kernel = native.TrainingKernel(c, native.families_of(mmg), net.input_mean, net.input_std, torch.float32)
    chunk = train.select(torch.arange(min(rows, len(train))))
    steps = chunk.states.shape[0] - 1
    states = [chunk.states[k].contiguous() for k in range(steps)]
    inputs = [chunk.inputs[k].contiguous() for k in range(steps)]
    weights = [w[0].detach() for w in net.weights]
    biases = [b[0].detach() for b in net.biases]
    last = (weights[-1].mT.contiguous(), biases[-1].unsqueeze(-1))
    doubled = [(2.0 * w, 2.0 * b) for w, b in zip(weights[:-1], biases[:-1])]
    z = [kernel(states[k], inputs[k], False)[2] for k in range(steps)]
    g_force, g_rate = torch.ones(len(chunk), 3), torch.ones(len(chunk), 6)

    def fnn():
        saved = []
        for k in range(steps):
            out = torch.empty(len(chunk), 3)
            saved.append(layers.forward_single(z[k], weights, biases, net.output_std, net.output_mean, out, last,
                                               doubled))
        for k in range(steps - 1, -1, -1):
            layers.backward(g_force, saved[k], weights, net.output_std, True, k > 0)

    def mmg_part():
        jacobians = [kernel(states[k], inputs[k], k > 0)[3] for k in range(steps)]
        for k in range(steps - 1, 0, -1):
            kernel.state_gradient(jacobians[k], g_rate, g_force, z[k])

    times = []
    for part in (fnn, mmg_part):
        part()
        start = time.perf_counter()
        for _ in range(repeats):
            part()
        times.append((time.perf_counter() - start) / repeats)
    return times[0], times[1]


def arithmetic_seconds(widths: list[int], rows: int, steps: int, repeats: int = 8) -> float:
    """Mean wall time [s] of the arithmetic of one training step alone: per Euler step the
    FNN's products and tanh forward, then per step and layer the two backward products and the
    tanh derivative, on (rows, width) float32 tensors made once (no autograd, no MMG, no
    integrator): the floor an implementation of the step could reach on this machine."""
    gen = torch.Generator().manual_seed(0)
    weights = [torch.randn(a, b, generator=gen) / a ** 0.5 for a, b in zip(widths[:-1], widths[1:])]
    x = torch.randn(rows, widths[0], generator=gen)
    grads = [torch.empty_like(w) for w in weights]

    def step():
        saved = []
        for _ in range(steps):
            z = x
            for i, w in enumerate(weights):
                saved.append(z)
                z = z @ w
                if i < len(weights) - 1:
                    z = torch.tanh(z)
        g = torch.ones(rows, widths[-1])
        for _ in range(steps):
            gi = g
            for i in range(len(weights) - 1, -1, -1):
                z = saved[i]
                torch.mm(z.t(), gi, out=grads[i])
                gi = gi @ weights[i].t()
                if i > 0:
                    gi = gi * (1.0 - z * z)  # tanh' from the saved activation
    step()
    start = time.perf_counter()
    for _ in range(repeats):
        step()
    return (time.perf_counter() - start) / repeats


def cpu_ms(fn, repeats: int) -> list[float]:
    """CPU times [ms] of `repeats` calls of `fn` (after one warm-up call)."""
    fn()
    out = []
    for _ in range(repeats):
        start = time.process_time()
        fn()
        out.append(1e3 * (time.process_time() - start))
    return out


def side_by_side(label: str, old, new, repeats: int = 7) -> None:
    """Median CPU time of `old` and `new`, called alternately, and their ratio."""
    times = {"old": [], "new": []}
    for _ in range(repeats):
        times["old"] += cpu_ms(old, 1)
        times["new"] += cpu_ms(new, 1)
    a, b = statistics.median(times["old"]), statistics.median(times["new"])
    print(f"{label:44s} {a:9.1f} {b:9.1f} {a / b:6.2f}x")


def parts(exp, runs, train, val, data=None) -> None:
    """Pieces of a hybrid training epoch and of a seed ensemble's evaluation, before and after."""
    from sysid.hybrid.ensemble import SeedEnsemble
    from sysid.hybrid.knn_gate import KNNGate
    from sysid.identify.checkpoint import CheckpointState, TrainingCheckpoint
    from sysid.identify.trainer import adam, weight_norm
    from sysid.evaluation.evaluate import evaluate_model
    from sysid.runs.lifecycle import cached_test_runs
    import tempfile

    t = exp.training
    mmg = build_mmg(exp, torch.float32).requires_grad_(False)
    net = ForceCorrection(exp.network.hidden, torch.float32, exp.network.members)
    hybrid = CorrectedModel(mmg, net, None, True, exp.gate.space)
    model = PerMember(hybrid)
    w_v = 1.0 / train.states[:, :, [1, 3, 5]].reshape(-1, 3).var(0)
    w_F = torch.ones(3)
    chunk = train.select(torch.arange(min(t.batch_size, len(train))))
    print(f"\nCPU ms (median of interleaved repeats)      {'before':>9} {'after':>9} {'ratio':>7}")

    def train_step(opt):
        def step():
            loss_v, loss_F = multistep_loss(model, chunk, w_v, w_F)
            loss = loss_v + t.lambda_F * loss_F + t.lambda_L2 * weight_norm(net)
            opt.zero_grad()
            loss.backward()
            opt.step()
        return step
    side_by_side(f"train step, batch {len(chunk)}, Adam", train_step(torch.optim.Adam(net.parameters(), t.learning_rate)),
                 train_step(adam(net.parameters(), t.learning_rate)))

    # one warm-start epoch (one-step regression, batches of 256): before, inputs standardised
    # per batch and Adam parameter by parameter; after, standardised once, Adam foreach
    s = torch.randn(2 * len(train), 9)
    target = torch.randn(2 * len(train), 3)
    z = net.standardize_inputs(s).expand(net.members, *s.shape)
    s_members = s.expand(net.members, *s.shape)

    def warm_epoch(opt, old: bool):
        def epoch():
            for lo in range(0, len(s), 256):
                idx = torch.arange(lo, min(lo + 256, len(s)))
                y = (net.evaluate(s_members[:, idx], standardized=True, per_member=True)[0] if old
                     else net.layers(z[:, idx])[0])
                loss = ((y - target[idx]) ** 2).mean() + t.lambda_L2 * weight_norm(net)
                opt.zero_grad()
                loss.backward()
                opt.step()
        return epoch
    side_by_side(f"warm-start epoch, {len(s)} samples", warm_epoch(torch.optim.Adam(net.parameters(), 3e-3), True),
                 warm_epoch(adam(net.parameters(), 3e-3), False), 5)

    def val_loss():
        with torch.no_grad():
            multistep_loss(model, val, w_v)
    print(f"{'validation loss, ' + str(len(val)) + ' windows':44s} {statistics.median(cpu_ms(val_loss, 5)):9.1f}")
    with tempfile.TemporaryDirectory() as scratch:
        checkpoint = TrainingCheckpoint(f"{scratch}/c.pt", exp.to_toml())
        opt = adam(net.parameters(), t.learning_rate)
        train_step(opt)()
        rows = [{"stage": "train", "epoch": e, "train_loss": 0.1, "early_stopping_loss": 0.1} for e in range(100)]

        def save():
            checkpoint.save(CheckpointState("train", 100, model.state_dict(), opt.state_dict(), {},
                                            torch.Generator().get_state(), 0.1, 50,
                                            {k: v.clone() for k, v in model.state_dict().items()}, rows, [], {}))
        print(f"{'checkpoint write (every epoch)':44s} {statistics.median(cpu_ms(save, 5)):9.1f}")

    # a mean-of-5-seeds hybrid ensemble evaluated on the six test files (30 and 100 s),
    # float64 as the protocol: before, every member computes F_MMG; after, once
    tests = cached_test_runs(data)
    bank = torch.randn(4000, 9, dtype=torch.float64)
    members = []
    for seed in range(5):
        torch.manual_seed(seed)
        m = CorrectedModel(build_mmg(exp, torch.float64), ForceCorrection(exp.network.hidden, torch.float64),
                           None, True, exp.gate.space)
        m.gate = KNNGate(exp.gate.k, exp.gate.alpha, 9, torch.float64).fit(bank)
        m.gate_enabled = True
        members.append(m)
    shared = SeedEnsemble(members)
    separate = SeedEnsemble(members)
    separate._shared_mmg = False
    side_by_side("seed ensemble (5 hybrids), test evaluation",
                 lambda: evaluate_model(separate, tests, exp.evaluation.horizons, Integrator(exp.evaluation.integrator)),
                 lambda: evaluate_model(shared, tests, exp.evaluation.horizons, Integrator(exp.evaluation.integrator)), 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--members", type=int, default=0,
                        help="also time a step of K networks side by side against one, at the config's batch")
    parser.add_argument("--only", choices=sorted(CONFIGS), action="append", help="these data sets only (default: all)")
    parser.add_argument("--batches", default=None,
                        help="comma-separated batch sizes of the table (default: 128, 512, the config's, 1024, all)")
    parser.add_argument("--limit", action="store_true",
                        help="also the step at the config's batch beside its arithmetic limit (interleaved)")
    parser.add_argument("--compiled", action="store_true",
                        help="also the step with a torch.compile'd right-hand side beside today's eager step")
    parser.add_argument("--ops", action="store_true", help="also count the operations of one right-hand-side call")
    parser.add_argument("--vjp", action="store_true",
                        help="also the step through the MMG's hand-derived VJP beside the step through autograd")
    parser.add_argument("--native", action="store_true",
                        help="also the step through the native MMG kernel beside the torch VJP and autograd")
    parser.add_argument("--against", default=None, metavar="DIR",
                        help="with --native: also the step of the checkout at DIR (its own code, a subprocess)")
    parser.add_argument("--ship", default=None, metavar="NAME",
                        help="the hybrid's MMG from this ship file instead of the config's (e.g. kvlcc2_l7: the "
                             "standard families through the native kernel), on the same windows; not with --against")
    parser.add_argument("--profile", action="store_true", help="also the step's operators by CPU time")
    parser.add_argument("--converge", action="store_true", help="also train each config to its early stop")
    parser.add_argument("--parts", action="store_true", help="CPU time of an epoch's pieces, before and after")
    args = parser.parse_args()
    try:
        data_root(args.data)
    except DataError as exc:
        raise SystemExit(f"training_speed: {exc}")
    if args.ship and args.against:
        raise SystemExit("training_speed: --ship with --against: the other checkout's step is the config's ship's; "
                         "drop one of them")
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} thread(s)" + (f", ship {args.ship}" if args.ship else ""))
    for name, path in CONFIGS.items():
        if args.only and name not in args.only:
            continue
        exp = load_experiment(path)
        runs = training_runs(exp, args.data)
        if args.ship:  # the windows stay the config's: only the MMG of the step changes
            exp = dataclasses.replace(exp, experiment=dataclasses.replace(exp.experiment, ship=args.ship),
                                      mmg=dataclasses.replace(exp.mmg, overrides={}))
        t = exp.training
        train, val, _, _ = split_windows(runs, t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                                         t.block_s, exp.experiment.seed)
        print(f"\n{name}: {len(train)} training windows of {t.steps} steps (config batch {t.batch_size})")
        print(f"{'batch':>6} {'ms/step':>9} {'window-steps/s':>15} {'epochs/s':>9}")
        try:
            batches = ([int(b) for b in args.batches.split(",")] if args.batches
                       else [128, 512, t.batch_size, 1024, len(train)])
        except ValueError:
            raise SystemExit(f"training_speed: --batches {args.batches!r}: give whole numbers separated by commas")
        for batch in sorted(set(batches)):
            seconds = minibatch_seconds(exp, train, batch)
            steps_per_epoch = -(-len(train) // batch)
            print(f"{batch:6d} {1e3 * seconds:9.1f} {min(batch, len(train)) * t.steps / seconds:15.0f} "
                  f"{1.0 / (seconds * steps_per_epoch):9.2f}")
        if args.members > 1:
            one = training_step(exp, train, t.batch_size, 1)[0]
            many = training_step(exp, train, t.batch_size, args.members)[0]
            unfused = training_step(exp, train, t.batch_size, args.members)[0]

            def separate():
                with separate_functions():
                    unfused()
            times: dict[str, list[tuple[float, float]]] = {"one": [], "many": [], "separate": []}
            for _ in range(5):  # interleaved rounds of 4 steps, medians of wall and CPU
                for label, fn in (("one", one), ("many", many), ("separate", separate)):
                    times[label].append(per_step_seconds(fn, 4))
            (a, a_cpu), (b, b_cpu), (c, c_cpu) = [
                tuple(statistics.median(x[i] for x in times[label]) for i in (0, 1)) for label in times]
            print(f"{args.members} networks side by side, batch {t.batch_size}: {1e3 * b:.1f} ms/step against "
                  f"{1e3 * a:.1f} for one ({b / a:.2f}x the time for {args.members}x the networks); through the "
                  f"separate Functions (kernel, layers) {1e3 * c:.1f} ms/step ({c / b:.2f}x the fused one); CPU "
                  f"{1e3 * b_cpu:.1f}, {1e3 * a_cpu:.1f}, {1e3 * c_cpu:.1f} ms/step ({b_cpu / a_cpu:.2f}x, "
                  f"{c_cpu / b_cpu:.2f}x)")
        if args.limit:
            widths = [9, *exp.network.hidden, 3]
            rows = min(t.batch_size, len(train))
            step, old, floor, own_fnn, own_mmg = [], [], [], [], []
            for _ in range(3):  # interleaved, medians
                step.append(minibatch_seconds(exp, train, t.batch_size))
                old.append(minibatch_seconds(exp, train, t.batch_size, fast=False))
                floor.append(arithmetic_seconds(widths, rows, t.steps))
                f, m = own_arithmetic_seconds(exp, train, rows)
                own_fnn.append(f)
                own_mmg.append(m)
            a, o, b = statistics.median(step), statistics.median(old), statistics.median(floor)
            f, m = statistics.median(own_fnn), statistics.median(own_mmg)
            forward, both = network_flops(widths, rows, t.steps)
            print(f"arithmetic limit, batch {rows}, T = {t.steps}, FNN {'-'.join(map(str, widths))}: "
                  f"{forward / 1e9:.3f} GFLOP forward, {both / 1e9:.3f} with the backward; that arithmetic alone "
                  f"{1e3 * b:.1f} ms ({both / b / 1e9:.1f} GFLOP/s) against the step's {1e3 * a:.1f} ms "
                  f"({a / b:.1f}x the limit; through autograd {1e3 * o:.1f} ms, {o / b:.1f}x)")
            print(f"the step's own arithmetic, without autograd, the integrator or Adam: the FNN's layers as "
                  f"it computes them (sysid.hybrid.layers) {1e3 * f:.1f} ms, the native kernel's calls "
                  f"{1e3 * m:.1f} ms, together {1e3 * (f + m):.1f} ms ({a / (f + m):.2f}x of it is the step)")
        if args.ops:
            operation_counts(exp, train, t.batch_size)
        if args.vjp:
            vjp_comparison(exp, train, t.batch_size)
        if args.native:
            native_comparison(exp, path, train, t.batch_size, args.data, args.against, args.threads)
        if args.profile:
            profile_step(exp, train, t.batch_size)
        if args.compiled:
            compiled_comparison(exp, train, t.batch_size)
        if args.parts:
            parts(exp, runs, train, val, args.data)
        if args.converge:
            start = time.perf_counter()
            trainer = Trainer(exp, progress=False, log=lambda m: None).fit(runs)
            s = trainer.summary_
            print(f"to convergence: {time.perf_counter() - start:.1f} s, {s.epochs} epochs "
                  f"(best {s.best_epoch}; {', '.join(f'{k}: {v}' for k, v in s.stopped.items())})")


if __name__ == "__main__":
    main()
