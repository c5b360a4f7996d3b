"""The hybrid's training right-hand side of one network as one autograd Function
(`sysid.hybrid.fused_rate`) on the real D2 training windows: gradcheck in float64 with respect
to the state and every parameter; a T = 10 float32 training rollout (the experiment's network,
256 windows) equal to autograd over every operation and to the torch path, to round-off, and
repeated bit for bit; the kernel's values without the Jacobian equal to those with it."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from sysid.dynamics.equations import integrate_training
from sysid.hybrid import force_models, fused_rate
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.mmg import native
from sysid.mmg.vjp import force_rate
from rollout_gradcheck import gradcheck_of_a_rollout, rollout_case

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def d2(dataset_dir):
    """(experiment, windows' states (11, N, 6), inputs (11, N, 4)) float64: the D2 experiment's
    first 256 training windows, time first."""
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import split_windows
    from sysid.runs.lifecycle import training_runs
    if native.library() is None:
        pytest.fail("the native kernel did not build or load (see the sysid.mmg.native log line)")
    exp = load_experiment(ROOT / "configs" / "experiments" / "hybrid_D2.toml")
    t = exp.training
    train = split_windows(training_runs(exp, None), t.steps, t.stride_s, t.val_fraction, True, torch.float64,
                          t.block_s, exp.experiment.seed)[0]
    chunk = train.select(torch.arange(256))
    return exp, chunk.states, chunk.inputs, chunk.dt


def _hybrid(exp, states, dtype, hidden=None, mean=(0.1, -0.05, 0.02), std=(1.5, 0.7, 0.4),
            members: int = 1) -> CorrectedModel:
    """A hybrid of the experiment with `members` networks, its FNN standardised on `states`
    (seeded), its force's statistics `mean`, `std` [N, N, N m] of the order of D2's F_MMG."""
    torch.manual_seed(0)
    net = ForceCorrection(hidden or exp.network.hidden, dtype, members)
    flat = states.reshape(-1, 6).to(dtype)
    net.set_standardization(flat.mean(0).repeat(2)[:9], flat.std(0).repeat(2)[:9] + 0.1, torch.tensor(mean),
                            torch.tensor(std))
    return CorrectedModel(build_mmg(exp, dtype).requires_grad_(False), net, None, True, exp.gate.space)


def test_gradcheck_of_the_fused_rate_in_float64(d2):
    exp, states, inputs, _ = d2
    model = _hybrid(exp, states, torch.float64, (8, 6))
    net = model.correction_net
    c = model.mmg.coefficients.values_view(torch.float64)
    kernel = native.TrainingKernel(c, native.families_of(model.mmg), net.input_mean, net.input_std, torch.float64)
    state = states[3, ::40].clone().requires_grad_(True)  # 7 windows, mid-rollout states
    u = inputs[3, ::40]
    parameters = [p for pair in zip(net.weights, net.biases) for p in pair]

    def rate(state, *parameters):  # a plan per evaluation: gradcheck moves the parameters
        plan = fused_rate.Plan(kernel, force_rate(c, state), net.output_std, net.output_mean, parameters)
        return fused_rate.hybrid_rate(state, u, plan)
    assert torch.autograd.gradcheck(rate, (state, *parameters))


@pytest.mark.parametrize("members", [1, 3])
def test_gradcheck_of_a_rollout_of_calls_sharing_a_plan_in_float64(d2, members):
    """Three Euler steps through one plan (a rollout's: the plan's views of the parameters shared
    by its calls, each call's parameter gradients summed by autograd), and a fourth call whose
    outputs reach nothing: gradcheck with respect to the first state and every parameter, one
    network and K = 3 side by side."""
    exp, states, inputs, _ = d2
    model = _hybrid(exp, states, torch.float64, (8, 6), members=members)
    net = model.correction_net
    c = model.mmg.coefficients.values_view(torch.float64)
    kernel = native.TrainingKernel(c, native.families_of(model.mmg), net.input_mean, net.input_std, torch.float64)
    state, u = rollout_case(states, inputs, members)
    parameters = [p for pair in zip(net.weights, net.biases) for p in pair]

    def plan_of(state, parameters):
        return fused_rate.Plan(kernel, force_rate(c, state), net.output_std, net.output_mean, parameters)
    assert gradcheck_of_a_rollout(fused_rate.hybrid_rate, plan_of, state, u, parameters, forces=2)


def _rollout(model, states, inputs, dt, fast=True):
    """Loss, states and every network gradient of a T = 10 Euler rollout (one network on the
    member axis, as training takes it)."""
    pred, f_nn, f_mmg = integrate_training(PerMember(model), states[0].unsqueeze(0), inputs.unsqueeze(1), dt, fast)
    loss = pred[1:, 0, :, [1, 3, 5]].sub(states[1:, :, [1, 3, 5]]).square().mean() \
        + 1e-3 * (f_nn.square().mean() + f_mmg.square().mean())
    net = model.correction_net
    net.zero_grad()
    loss.backward()
    return [loss.detach(), pred.detach()] + [p.grad.clone() for p in net.parameters()]


def test_a_float32_training_rollout_equals_autograd_and_the_torch_path(d2, monkeypatch):
    """The experiment's network (9-128-128-3) on 256 D2 windows, float32: loss, states and
    gradients through the fused Function, through autograd over every operation
    (``fast=False``, torch.tanh) and through the torch path (`native.torch_path`: the torch VJP
    of the MMG and the layers' Function) agree within 2e-5 of each quantity's largest
    magnitude; a second rollout repeats the first bit for bit."""
    exp, states, inputs, dt = d2
    model = _hybrid(exp, states, torch.float32)
    states, inputs = states.float(), inputs.float()
    calls = []
    original = force_models.hybrid_rate

    def counted(state, inputs, plan):
        calls.append(state.requires_grad)
        return original(state, inputs, plan)
    monkeypatch.setattr(force_models, "hybrid_rate", counted)
    new = _rollout(model, states, inputs, dt)
    assert calls == [False] + [True] * 9  # every step fused; the first state has no gradient
    again = _rollout(model, states, inputs, dt)
    old = _rollout(model, states, inputs, dt, fast=False)
    with native.torch_path():
        torch_path = _rollout(model, states, inputs, dt)
    assert len(calls) == 20
    for a, b, t, r in zip(new, old, torch_path, again):
        assert torch.equal(a, r)
        scale = float(b.abs().max())
        torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * scale)
        torch.testing.assert_close(t, b, rtol=2e-5, atol=2e-5 * scale)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_kernels_values_without_the_jacobian_are_those_with_it(d2, dtype):
    exp, states, inputs, _ = d2
    model = _hybrid(exp, states, dtype)
    net = model.correction_net
    c = model.mmg.coefficients.values_view(dtype)
    kernel = native.TrainingKernel(c, native.families_of(model.mmg), net.input_mean, net.input_std, dtype)
    state, u = states.reshape(-1, 6).to(dtype), inputs.reshape(-1, 4).to(dtype)
    *values, jacobian = kernel(state, u, True)
    *alone, none = kernel(state, u, False)
    assert none is None and jacobian.shape == (state.shape[0], 6, 18)
    for a, b in zip(alone, values):
        assert torch.equal(a, b)


def test_gradcheck_of_the_fused_rate_of_members_side_by_side_in_float64(d2):
    """K = 3 networks, each on its own rows (states (K, rows, 6)): gradcheck with respect to the
    states and every member's parameters."""
    exp, states, inputs, _ = d2
    model = _hybrid(exp, states, torch.float64, (8, 6), members=3)
    net = model.correction_net
    c = model.mmg.coefficients.values_view(torch.float64)
    kernel = native.TrainingKernel(c, native.families_of(model.mmg), net.input_mean, net.input_std, torch.float64)
    state = states[3, :60].reshape(3, 20, 6)[:, ::4].clone().requires_grad_(True)  # 5 windows a member
    u = inputs[3, :60].reshape(3, 20, 4)[:, ::4]
    parameters = [p for pair in zip(net.weights, net.biases) for p in pair]

    def rate(state, *parameters):
        plan = fused_rate.Plan(kernel, force_rate(c, state), net.output_std, net.output_mean, parameters)
        return fused_rate.hybrid_rate(state, u, plan)
    assert torch.autograd.gradcheck(rate, (state, *parameters))


def _members_rollout(model, states, inputs, dt, fast=True):
    """Loss, states and every network gradient of a T = 10 Euler rollout of K members, member k
    on its own windows (states (T + 1, K, B, 6)), as seeds side by side train."""
    pred, f_nn, f_mmg = integrate_training(PerMember(model), states[0], inputs, dt, fast)
    loss = pred[1:, ..., [1, 3, 5]].sub(states[1:, ..., [1, 3, 5]]).square().mean() \
        + 1e-3 * (f_nn.square().mean() + f_mmg.square().mean())
    net = model.correction_net
    net.zero_grad()
    loss.backward()
    return [loss.detach(), pred.detach()] + [p.grad.clone() for p in net.parameters()]


def test_a_float32_rollout_of_members_side_by_side_equals_the_separate_functions(d2, monkeypatch):
    """3 members of the experiment's network (9-128-128-3), each on its own 64 D2 windows,
    float32: loss, states and gradients through the fused Function equal those through the
    separate Functions (native kernel, layers) and through autograd over every operation to
    2e-5 of each quantity's largest magnitude; member k's states and gradients equal those of
    its network alone (K = 1) on its windows."""
    exp, states, inputs, dt = d2
    model = _hybrid(exp, states, torch.float32, members=3)
    split = [x.float()[:, :192].reshape(x.shape[0], 3, 64, x.shape[-1]) for x in (states, inputs)]
    calls = []
    original = force_models.hybrid_rate

    def counted(state, inputs, plan):
        calls.append(tuple(state.shape))
        return original(state, inputs, plan)
    monkeypatch.setattr(force_models, "hybrid_rate", counted)
    new = _members_rollout(model, *split, dt)
    assert calls == [(3, 64, 6)] * 10  # every step fused
    old = _members_rollout(model, *split, dt, fast=False)
    monkeypatch.setattr(force_models.CorrectedModel, "_fused_training_rate",
                        staticmethod(lambda coefficients, net, families, otherwise: otherwise))
    separate = _members_rollout(model, *split, dt)
    assert len(calls) == 10
    for a, b, t in zip(new, old, separate):
        scale = float(b.abs().max())
        torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * scale)
        torch.testing.assert_close(a, t, rtol=2e-5, atol=2e-5 * scale)
    monkeypatch.undo()
    net = model.correction_net
    for k in range(3):
        alone = _hybrid(exp, states, torch.float32)
        with torch.no_grad():
            for p, q in zip(alone.correction_net.parameters(), net.parameters()):
                p.copy_(q[k:k + 1])
            for name, buffer in net.named_buffers():
                getattr(alone.correction_net, name).copy_(buffer)
        one = _members_rollout(alone, *[x[:, k:k + 1] for x in split], dt)
        torch.testing.assert_close(one[1], new[1][:, k:k + 1], rtol=2e-5, atol=2e-5 * float(new[1].abs().max()))
        for a, b in zip(one[2:], new[2:]):  # the loss is a mean over the K members' windows too
            b = 3.0 * b[k:k + 1]
            torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * float(b.abs().max()))


def test_the_no_grad_rate_of_members_side_by_side_equals_the_torch_path(d2):
    """`PerMember.eager_rate` (validation rollouts of seeds side by side: the native kernel and
    the training layers' forward, member k's network on member k's rows) equals the equations
    of motion over the torch MMG and each member's own F_NN, in float64 to 1e-12 of the largest
    rate."""
    from sysid.dynamics.equations import state_derivative
    exp, states, inputs, _ = d2
    model = PerMember(_hybrid(exp, states, torch.float64, (16, 8), members=3))
    state, u = states[4, :96].reshape(3, 32, 6), inputs[4, :96].reshape(3, 32, 4)
    with torch.no_grad():
        rate, gate = model.eager_rate(state, u)
        forces = model(state, u)
        expected = state_derivative(state, forces.total, model.coefficients)
    assert gate is None and rate.shape == (3, 32, 6)
    torch.testing.assert_close(rate, expected, rtol=0, atol=1e-12 * float(expected.abs().max()))
    assert model.eager_rate(state.requires_grad_(True), u) is None  # with gradient: the training path
