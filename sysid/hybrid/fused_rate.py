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
"""
from __future__ import annotations

import torch

from sysid.hybrid import layers
from sysid.mmg.native import TrainingKernel


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
        rows = h[0].shape[-2] * plan.members
        g_rate = None if grad_rate is None else grad_rate.view(rows, 6)
        if grad_nn is None:
            g_force = None if g_rate is None else torch.mm(g_rate, plan.mass_T)
        else:
            g_force = grad_nn.view(rows, 3) if g_rate is None else torch.addmm(grad_nn.view(rows, 3), g_rate,
                                                                                 plan.mass_T)
        state_gradient = ctx.needs_input_grad[0]
        g_z, grads = None, [None] * len(plan.parameters)
        if g_force is not None:
            single = plan.members == 1
            g_z, grads = layers.backward(g_force if single else g_force.view(plan.members, -1, 3), h, plan.weights,
                                         plan.scale, single, state_gradient)
        # (..., 6): the Jacobian's batch shape, the state's
        g_state = plan.kernel.state_gradient(jacobian, g_rate, grad_mmg, g_z) if state_gradient else None
        return g_state, None, None, *grads


def hybrid_rate(state: torch.Tensor, inputs: torch.Tensor, plan: Plan) -> tuple:
    """(dx/dt (..., 6), F_NN (..., 3), F_MMG (..., 3)) at state (..., 6) with inputs (..., 4)
    (see the module docstring), rows contiguous; `plan` of this rollout."""
    return _HybridRate.apply(state, inputs, plan, *plan.parameters)
