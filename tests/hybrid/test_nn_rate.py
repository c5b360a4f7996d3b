"""NN-only's training right-hand side as one autograd Function (`sysid.hybrid.fused_rate.nn_rate`)
on the real D2 training windows: gradcheck in float64 with respect to the state and every
parameter (one network and K = 3 side by side); float32 training rollouts (the experiment's
network) equal to autograd over every operation of `forward` and the equations of motion, to
round-off, repeated bit for bit; each member side by side equal to its network alone."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch

from sysid.dynamics.equations import integrate_training
from sysid.hybrid import force_models, fused_rate
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.mmg.coefficient_lookup import Rows, coefficient_matrix
from sysid.mmg.vjp import RATE_ROWS
from rollout_gradcheck import gradcheck_of_a_rollout, rollout_case

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def d2(dataset_dir):
    """(experiment, windows' states (T + 1, N, 6), inputs (T + 1, N, 4), dt) float64: the NN-only D2
    experiment's first 256 training windows, time first."""
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import split_windows
    from sysid.runs.lifecycle import training_runs
    exp = load_experiment(ROOT / "configs" / "experiments" / "nn_D2.toml")
    t = exp.training
    train = split_windows(training_runs(exp, None), t.steps, t.stride_s, t.val_fraction, True, torch.float64,
                          t.block_s, exp.experiment.seed)[0]
    chunk = train.select(torch.arange(256))
    return exp, chunk.states, chunk.inputs, chunk.dt


def _nn_only(exp, states, dtype, hidden=None, members: int = 1) -> CorrectedModel:
    """An NN-only model of the experiment with `members` networks, its FNN standardised on
    `states` (seeded), its force's statistics of the order of D2's residual forces [N, N, N m]."""
    torch.manual_seed(0)
    net = ForceCorrection(hidden or exp.network.hidden, dtype, members)
    flat = states.reshape(-1, 6).to(dtype)
    net.set_standardization(flat.mean(0).repeat(2)[:9], flat.std(0).repeat(2)[:9] + 0.1,
                            torch.tensor([0.1, -0.05, 0.02]), torch.tensor([1.5, 0.7, 0.4]))
    return CorrectedModel(build_mmg(exp, dtype).requires_grad_(False), net, None, False, exp.gate.space)


def _plan(model, like, parameters):
    net = model.correction_net
    rates = coefficient_matrix(model.mmg.coefficients.values_view(like.dtype), Rows(RATE_ROWS), like)
    return fused_rate.NNPlan(rates, net.input_mean, net.input_std, net.output_std, net.output_mean, parameters)


@pytest.mark.parametrize("members", [1, 3])
def test_gradcheck_of_the_nn_only_rate_in_float64(d2, members):
    exp, states, inputs, _ = d2
    model = _nn_only(exp, states, torch.float64, (8, 6), members)
    net = model.correction_net
    state = states[3, :60:4].reshape(members, -1, 6) if members > 1 else states[3, :60:4]
    u = inputs[3, :60:4].reshape(state.shape[:-1] + (4,))
    state = state.clone().requires_grad_(True)
    parameters = [p for pair in zip(net.weights, net.biases) for p in pair]

    def rate(state, *parameters):  # a plan per evaluation: gradcheck moves the parameters
        return fused_rate.nn_rate(state, u, _plan(model, state, parameters))[:2]
    assert torch.autograd.gradcheck(rate, (state, *parameters))


@pytest.mark.parametrize("members", [1, 3])
def test_gradcheck_of_a_rollout_of_calls_sharing_a_plan_in_float64(d2, members):
    """Three Euler steps through one plan (a rollout's: its calls share the plan's views of the
    parameters), and a fourth call whose outputs reach nothing: gradcheck with respect to the
    first state and every parameter."""
    exp, states, inputs, _ = d2
    model = _nn_only(exp, states, torch.float64, (8, 6), members)
    net = model.correction_net
    state, u = rollout_case(states, inputs, members)
    parameters = [p for pair in zip(net.weights, net.biases) for p in pair]
    assert gradcheck_of_a_rollout(fused_rate.nn_rate, lambda state, parameters: _plan(model, state, parameters),
                                  state, u, parameters, forces=1)


def _rollout(model, states, inputs, dt, fast=True):
    """Loss, states and every network gradient of a T-step Euler rollout, member k on its own
    windows (states (T + 1, K, B, 6))."""
    pred, f_nn, f_mmg = integrate_training(PerMember(model), states[0], inputs, dt, fast)
    loss = pred[1:, ..., [1, 3, 5]].sub(states[1:, ..., [1, 3, 5]]).square().mean() \
        + 1e-3 * (f_nn.square().mean() + f_mmg.square().mean())
    net = model.correction_net
    net.zero_grad()
    loss.backward()
    return [loss.detach(), pred.detach(), f_mmg.detach()] + [p.grad.clone() for p in net.parameters()]


def test_a_float32_nn_only_rollout_equals_autograd(d2, monkeypatch):
    """The experiment's network on 256 D2 windows (K = 1) and 3 members on 64 windows each,
    float32: loss, states and gradients through the Function equal those through autograd over
    every operation (``fast=False``) within 2e-5 of each quantity's largest magnitude; F_MMG is
    zeros either way; a second rollout repeats the first bit for bit; member k's states and
    gradients equal those of its network alone on its windows."""
    exp, states, inputs, dt = d2
    calls = []
    original = force_models.nn_rate

    def counted(state, inputs, plan):
        calls.append((tuple(state.shape), state.requires_grad))
        return original(state, inputs, plan)
    monkeypatch.setattr(force_models, "nn_rate", counted)
    one = [x.float().unsqueeze(1) for x in (states, inputs)]
    split = [x.float()[:, :192].reshape(x.shape[0], 3, 64, x.shape[-1]) for x in (states, inputs)]
    for members, data in ((1, one), (3, split)):
        model = _nn_only(exp, states, torch.float32, members=members)
        calls.clear()
        new = _rollout(model, *data, dt)
        shape = tuple(data[0].shape[1:])
        steps = data[0].shape[0] - 1
        assert calls == [(shape, False)] + [(shape, True)] * (steps - 1)  # every step; the first has no gradient
        again = _rollout(model, *data, dt)
        old = _rollout(model, *data, dt, fast=False)
        assert len(calls) == 2 * steps
        assert not new[2].any() and not old[2].any()
        for a, b, r in zip(new, old, again):
            assert torch.equal(a, r)
            scale = float(b.abs().max())
            torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * scale)
    net = model.correction_net
    for k in range(3):
        alone = _nn_only(exp, states, torch.float32)
        with torch.no_grad():
            for p, q in zip(alone.correction_net.parameters(), net.parameters()):
                p.copy_(q[k:k + 1])
        single = _rollout(alone, *[x[:, k:k + 1] for x in split], dt)
        torch.testing.assert_close(single[1], new[1][:, k:k + 1], rtol=2e-5, atol=2e-5 * float(new[1].abs().max()))
        for a, b in zip(single[3:], new[3:]):  # the loss is a mean over the K members' windows too
            b = 3.0 * b[k:k + 1]
            torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * float(b.abs().max()))


@pytest.mark.parametrize("dtype, tolerance", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
def test_the_no_grad_rate_of_nn_only_equals_the_equations_of_motion_over_forward(d2, dtype, tolerance):
    """`eager_rate` of NN-only (validation rollouts: one network, and K = 3 members each on its
    own rows through the training layers' forward) equals the equations of motion over
    `forward`'s F_NN, to `tolerance` of the largest rate; with gradient it does not apply."""
    from sysid.dynamics.equations import state_derivative
    exp, states, inputs, _ = d2
    one = _nn_only(exp, states, dtype, (16, 8))
    members = PerMember(_nn_only(exp, states, dtype, (16, 8), members=3))
    for model, shape in ((one, (96, 6)), (members, (3, 32, 6))):
        state = states[4, :96].reshape(shape).to(dtype)
        u = inputs[4, :96].reshape(shape[:-1] + (4,)).to(dtype)
        with torch.no_grad():
            rate, gate = model.eager_rate(state, u)
            expected = state_derivative(state, model(state, u).total, model.coefficients)
        assert gate is None and rate.shape == shape
        torch.testing.assert_close(rate, expected, rtol=0, atol=tolerance * float(expected.abs().max()))
        assert model.eager_rate(state.requires_grad_(True), u) is None


def test_the_wind_tangents_over_u_v_psi_are_the_state_wide_ones_columns(d2):
    """`motion_columns` with psi's tangent over (u, v, psi) gives the relative wind's values and
    the (u, v, psi) columns of the tangents `motion_tangents` gives over the whole state (zero
    in x, y, r), on real rows and at the guards: a ship at rest (u = v = 0, the speed guard),
    a calm (U_T = 0), and both."""
    from sysid.mmg.motion import constants
    from sysid.mmg.tangents import basis, motion_columns, motion_tangents, relative_wind_tangents
    _, states, inputs, _ = d2
    state, u = states[2, :64].clone(), inputs[2, :64].clone()
    state[:8, [1, 3]] = 0.0
    u[4:12, 2] = 0.0
    k, B = constants(state), basis(state)
    U_T, zeta = u[:, 2:3], u[:, 3:4]
    wide = relative_wind_tangents(motion_tangents(state, k, B), U_T, zeta, k, B.e_psi)
    narrow = relative_wind_tangents(motion_columns(state, k), U_T, zeta, k, B.psi_of_uvpsi)
    for name in ("omega", "U_A", "gamma_A"):
        assert torch.equal(getattr(narrow, name), getattr(wide, name))
    for name in ("d_UA", "d_gamma"):
        w, n = getattr(wide, name), getattr(narrow, name)
        assert not w[:, [0, 2, 5]].any()
        torch.testing.assert_close(n, w[:, [1, 3, 4]], rtol=1e-15, atol=0.0)
    # the guards were taken: at rest the angle is the true wind's (d gamma = -d psi), at rest in
    # a calm the drift angle's (its tangent 0 at u = v = 0)
    assert wide.d_gamma[:4, 4].eq(-1.0).all() and not wide.d_gamma[4:8].any()
