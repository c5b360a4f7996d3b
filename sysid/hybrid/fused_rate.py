"""The hybrid's training right-hand side as one autograd Function: one network (K = 1), or K
networks side by side on the member axis, each on its own rows (states (K, ..., 6)).

At state x (..., 6) with inputs (..., 4), one call gives what a training rollout reads:

    dx/dt = r_MMG(x) + F_NN(z(x)) M,   F_NN (..., 3),   F_MMG (..., 3),

with r_MMG (dx/dt of F_MMG), F_MMG and the FNN's standardised inputs z from one call of the
native kernel (`sysid.mmg.native.TrainingKernel`, with their Jacobian J with respect to the
state), F_NN from the FNN's layers (`sysid.hybrid.layers`), and M (3, 6) the mass terms of the
equations of motion (`sysid.mmg.vjp.force_rate`). Its backward is the chain rule written out:

    g_F = g_{F_NN} + g_{dx/dt} M^T,   (g_z, dW, db) = the layers' backward of g_F,
    g_x = J (g_{dx/dt}, g_{F_MMG}, g_z)   (the kernel's vector-Jacobian product),

in place of three autograd Functions (kernel, layers, the force's rate) and the views and
casts between them: the same numbers as those (`sysid.hybrid.force_models.CorrectedModel.training_rate`
without it) to round-off, `tests/hybrid/test_fused_rate.py`. A state without gradient (a rollout's first)
skips the Jacobian. With K members the kernel takes all K x rows at once and the layers run as
batched products (`sysid.hybrid.layers.forward_members`), member k's network on member k's rows.

NN-only (F = F_NN, `nn_rate`) has the same shape without the kernel: s and the rigid-body part of
the equations of motion (the Coriolis and kinematic features) in torch, F_NN by the layers, dx/dt
= the features times the mass terms' matrix (`sysid.mmg.vjp.rate_of_force`'s). No Jacobian is
built: u, v, r enter s and the features through a few products, x and y not at all, so the
backward applies the chain rule column by column from the forward's (rows, 1) columns and the
relative wind's tangents over (u, v, psi) (`sysid.mmg.tangents.motion_columns`),
`tests/hybrid/test_nn_rate.py`.
"""
from __future__ import annotations

import torch

from sysid.hybrid import layers
from sysid.mmg.motion import constants
from sysid.mmg.native import TrainingKernel
from sysid.mmg.tangents import basis, motion_columns, relative_wind_tangents


class Plan:
    """What each call of one rollout reads, looked up once (the parameters stay where they are
    during a rollout: an optimizer steps between rollouts): the kernel, the mass terms M (3, 6)
    and M^T, sigma_F and mu_F (3,), the network's parameters as the Function's inputs and their
    2-d views (W_L^T as a contiguous copy, b_L as a column, the hidden layers' doubled:
    `sysid.hybrid.layers.forward_single`)."""

    def __init__(self, kernel: TrainingKernel, mass: torch.Tensor, scale: torch.Tensor, shift: torch.Tensor,
                 parameters):
        self.kernel, self.mass, self.mass_T = kernel, mass, mass.mT.contiguous()
        self.scale, self.shift = scale, shift
        self.parameters = tuple(parameters)
        self.members = self.parameters[0].shape[0]
        if self.members != 1:  # K side by side: the parameters as they are, (K, ...)
            self.weights, self.biases = list(self.parameters[0::2]), list(self.parameters[1::2])
            return
        with torch.no_grad():
            self.weights = [w[0] for w in self.parameters[0::2]]
            self.biases = [b[0] for b in self.parameters[1::2]]
            self.last_T = self.weights[-1].mT.contiguous()
            self.last_bias = self.biases[-1].unsqueeze(-1)
            self.doubled = [(2.0 * w, 2.0 * b) for w, b in zip(self.weights[:-1], self.biases[:-1])]


def _force_backward(plan: Plan, h, grad_rate, grad_nn, state_gradient: bool) -> tuple:
    """The chain rule's part shared by both Functions' backwards: (rows, g_{dx/dt} (rows, 6) or
    None, g_z or None, the parameters' gradients) from the gradients of dx/dt and F_NN, with
    g_F = g_{F_NN} + g_{dx/dt} M^T through the layers' backward; rows = the batch flattened
    (K x rows for K members)."""
    rows = h[0].shape[-2] * plan.members
    g_rate = None if grad_rate is None else grad_rate.reshape(rows, 6)
    if grad_nn is None:
        g_force = None if g_rate is None else torch.mm(g_rate, plan.mass_T)
    else:
        g_force = grad_nn.reshape(rows, 3) if g_rate is None else torch.addmm(grad_nn.reshape(rows, 3), g_rate,
                                                                                plan.mass_T)
    g_z, grads = None, [None] * len(plan.parameters)
    if g_force is not None:
        single = plan.members == 1
        g_z, grads = layers.backward(g_force if single else g_force.view(plan.members, -1, 3), h, plan.weights,
                                     plan.scale, single, state_gradient)
    return rows, g_rate, g_z, grads


class _HybridRate(torch.autograd.Function):
    """(state, inputs, plan, W_1, b_1, ..., W_L, b_L) -> (dx/dt, F_NN, F_MMG); W_i (K, n_{i-1},
    n_i), b_i (K, n_i) as `sysid.hybrid.correction.ForceCorrection` holds them (the plan's);
    with K > 1, state (K, ..., 6)."""

    @staticmethod
    def forward(ctx, state, inputs, plan, *parameters):
        ctx.set_materialize_grads(False)
        state_gradient = ctx.needs_input_grad[0]
        rate_mmg, f_mmg, z, jacobian = plan.kernel(state, inputs, state_gradient)
        if plan.members == 1:
            f_nn = torch.empty_like(f_mmg)
            h = layers.forward_single(z.view(-1, 9), plan.weights, plan.biases, plan.scale, plan.shift,
                                      f_nn.view(-1, 3), (plan.last_T, plan.last_bias), plan.doubled)
        else:
            f_nn, h = layers.forward_members(z.view(plan.members, -1, 9), plan.weights, plan.biases, plan.scale,
                                             plan.shift)
            f_nn = f_nn.view(f_mmg.shape)
        rate = torch.empty_like(rate_mmg)
        torch.addmm(rate_mmg.view(-1, 6), f_nn.view(-1, 3), plan.mass, out=rate.view(-1, 6))
        ctx.save_for_backward(jacobian, *h)
        ctx.plan = plan
        return rate, f_nn, f_mmg

    @staticmethod
    def backward(ctx, grad_rate, grad_nn, grad_mmg):
        jacobian, *h = ctx.saved_tensors
        plan = ctx.plan
        state_gradient = ctx.needs_input_grad[0]
        _, g_rate, g_z, grads = _force_backward(plan, h, grad_rate, grad_nn, state_gradient)
        # (..., 6): the Jacobian's batch shape, the state's
        g_state = plan.kernel.state_gradient(jacobian, g_rate, grad_mmg, g_z) if state_gradient else None
        return g_state, None, None, *grads


def hybrid_rate(state: torch.Tensor, inputs: torch.Tensor, plan: Plan) -> tuple:
    """(dx/dt (..., 6), F_NN (..., 3), F_MMG (..., 3)) at state (..., 6) with inputs (..., 4)
    (see the module docstring), rows contiguous; `plan` of this rollout."""
    return _HybridRate.apply(state, inputs, plan, *plan.parameters)


# NN-only (F = F_NN): the same Function shape without the MMG. The features of the equations
# of motion, as `sysid.mmg.vjp.rate_of_force` lays them out: (F (3), a * b (7), state (6)) times
# the (16, 6) matrix of the mass terms, a = (u, v, r, u, u, v, v), b = (r, r, r, cos psi, sin psi,
# cos psi, sin psi) [m/s, 1/s]


class NNPlan(Plan):
    """`Plan` of an NN-only rollout: no kernel; the (16, 6) matrix of the equations of motion
    (`sysid.mmg.vjp.rate_of_force`'s; its first 3 rows are the mass terms M), the FNN's
    standardisation mean and std (9,); for the backward the kinematic features' (7, 6) and
    the state's (6, 6) blocks."""

    def __init__(self, rates: torch.Tensor, mean: torch.Tensor, std: torch.Tensor, scale: torch.Tensor,
                 shift: torch.Tensor, parameters):
        super().__init__(None, rates[:3], scale, shift, parameters)
        self.rates, self.mean, self.std = rates, mean, std
        # (7, 6), (6, 6): products with a gradient's transpose (rows last: quicker than rows first)
        self.kinematic, self.state_rates = rates[3:10].contiguous(), rates[10:].contiguous()


def _inputs_and_kinematics(state: torch.Tensor, inputs: torch.Tensor, plan: NNPlan, jacobian: bool):
    """(z (rows, 9) the FNN's standardised inputs, a * b (rows, 7), then with `jacobian` what
    the backward's chain rule reads: a, b (rows, 7), the tangents over (u, v, psi) (rows, 3) of
    the relative wind's speed U_A and angle gamma_A, cos gamma_A, sin gamma_A and U_A (rows, 1),
    else None); rows = the batch flattened."""
    state, inputs = state.reshape(-1, 6), inputs.reshape(-1, 4)
    k = constants(state)
    m = motion_columns(state, k)
    n, delta, U_T, zeta = inputs.split_with_sizes((1, 1, 1, 1), -1)
    wind = relative_wind_tangents(m, U_T, zeta, k, basis(state).psi_of_uvpsi)
    u, v, psi, r = m.u, m.v, m.psi, m.r
    cos_psi, sin_psi = torch.cos(psi), torch.sin(psi)
    a = torch.cat([u, v, r, u, u, v, v], -1)
    b = torch.cat([r, r, r, cos_psi, sin_psi, cos_psi, sin_psi], -1)
    s = torch.cat([u, v, r, delta, n, wind.omega, cos_psi, sin_psi], -1)
    z = (s - plan.mean) / plan.std
    if not jacobian:
        return z, a * b, None
    return z, a * b, (a, b, wind.d_UA, wind.d_gamma, wind.cos_g, wind.sin_g, wind.U_A)


def _state_gradient(plan: NNPlan, saved, g_rate, g_z, rows: int) -> torch.Tensor:
    """g_x (rows, 6) from g_{dx/dt} (rows, 6) and g_z (rows, 9) (either None: zeros), the chain
    rule column by column: x and y enter nothing; u, v, r through s = (u, v, r, ...) and a * b
    with d(a b) = b da + a db (a = (u, v, r, u, u, v, v), b = (r, r, r, cos psi, sin psi, cos
    psi, sin psi)); psi through cos psi and sin psi; u, v, psi through the relative wind
    omega = U_A (cos g, sin g) (g = gamma_A): g_omega . d omega = (g_omega . (cos g, sin g)) dU_A
    + U_A (g_omega . (-sin g, cos g)) dg; and dx/dt's own state terms (psi_dot = r)."""
    a, b, d_UA, d_gamma, cos_g, sin_g, U_A = saved
    if g_rate is None:
        g_rate = a.new_zeros(rows, 6)
    zero = a.new_zeros(rows, 1)
    g_ab = torch.mm(plan.kinematic, g_rate.mT).unsqueeze(-1)       # (7, rows, 1): of a * b's 7
    g_s = (a.new_zeros(rows, 9) if g_z is None else g_z.reshape(rows, 9) / plan.std).split(1, -1)
    u, v, r, cos_psi, sin_psi = a[:, :1], a[:, 1:2], a[:, 2:3], b[:, 3:4], b[:, 4:5]
    g_u = torch.addcmul(torch.addcmul(torch.addcmul(g_s[0], g_ab[0], r), g_ab[3], cos_psi), g_ab[4], sin_psi)
    g_v = torch.addcmul(torch.addcmul(torch.addcmul(g_s[1], g_ab[1], r), g_ab[5], cos_psi), g_ab[6], sin_psi)
    g_r = torch.addcmul(torch.addcmul(torch.addcmul(g_s[2], g_ab[0], u), g_ab[1], v), g_ab[2], r, value=2.0)
    g_cos = torch.addcmul(torch.addcmul(g_s[7], g_ab[3], u), g_ab[5], v)  # of cos psi, then of sin psi
    g_sin = torch.addcmul(torch.addcmul(g_s[8], g_ab[4], u), g_ab[6], v)
    g_speed = torch.addcmul(g_s[5] * cos_g, g_s[6], sin_g)                 # of U_A
    g_angle = torch.addcmul(g_s[6] * cos_g, g_s[5], sin_g, value=-1.0) * U_A
    wind = torch.addcmul(g_speed * d_UA, g_angle, d_gamma)                  # of (u, v, psi)
    g_psi = torch.addcmul(torch.addcmul(wind[:, 2:], g_sin, cos_psi), g_cos, sin_psi, value=-1.0)
    g_state = torch.cat([zero, g_u + wind[:, :1], zero, g_v + wind[:, 1:2], g_psi, g_r], -1)
    return g_state + torch.mm(plan.state_rates, g_rate.mT).mT


class _NNRate(torch.autograd.Function):
    """(state, inputs, plan, W_1, b_1, ..., W_L, b_L) -> (dx/dt, F_NN, zeros in place of F_MMG) of
    an NN-only model; parameters as `_HybridRate`'s; with K > 1, state (K, ..., 6)."""

    @staticmethod
    def forward(ctx, state, inputs, plan, *parameters):
        ctx.set_materialize_grads(False)
        state_gradient = ctx.needs_input_grad[0]
        z, kinematic, saved = _inputs_and_kinematics(state, inputs, plan, state_gradient)
        rows = z.shape[0]
        if plan.members == 1:
            f_nn = z.new_empty(rows, 3)
            h = layers.forward_single(z, plan.weights, plan.biases, plan.scale, plan.shift, f_nn,
                                      (plan.last_T, plan.last_bias), plan.doubled)
        else:
            f_nn, h = layers.forward_members(z.view(plan.members, -1, 9), plan.weights, plan.biases, plan.scale,
                                             plan.shift)
            f_nn = f_nn.view(rows, 3)
        rate = torch.cat([f_nn, kinematic, state.reshape(rows, 6)], -1) @ plan.rates
        f_mmg = torch.zeros_like(f_nn)
        ctx.mark_non_differentiable(f_mmg)
        ctx.save_for_backward(*(saved or (None,) * 7), *h)
        ctx.plan, ctx.batch = plan, state.shape[:-1]
        return rate.view(state.shape), f_nn.view(*ctx.batch, 3), f_mmg.view(*ctx.batch, 3)

    @staticmethod
    def backward(ctx, grad_rate, grad_nn, grad_mmg):
        saved, h = ctx.saved_tensors[:7], ctx.saved_tensors[7:]
        plan = ctx.plan
        state_gradient = ctx.needs_input_grad[0]
        rows, g_rate, g_z, grads = _force_backward(plan, h, grad_rate, grad_nn, state_gradient)
        g_state = None
        if state_gradient and (g_rate is not None or g_z is not None):
            g_state = _state_gradient(plan, saved, g_rate, g_z, rows).view(*ctx.batch, 6)
        return g_state, None, None, *grads


def nn_rate(state: torch.Tensor, inputs: torch.Tensor, plan: NNPlan) -> tuple:
    """(dx/dt (..., 6), F_NN (..., 3), zeros (..., 3) for F_MMG) of an NN-only model at state
    (..., 6) with inputs (..., 4): s and the equations of motion in torch without autograd,
    with their Jacobian (`sysid.mmg.tangents`' relative wind), F_NN by the FNN's layers; its
    backward the chain rule written out as `_HybridRate`'s. `plan` of this rollout."""
    return _NNRate.apply(state, inputs, plan, *plan.parameters)
