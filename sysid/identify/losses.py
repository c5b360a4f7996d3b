"""The multi-step loss of training (Eqs. 13-17): L_v of Euler rollouts of T steps from each
window's recorded start, the output constraint L_F, the weights' |theta|^2, and Adam."""
from __future__ import annotations

import torch

from sysid.config.experiment import PAPER_FORCE_BAND, TrainingOptions
from sysid.dynamics.equations import integrate_loss, integrate_training
from sysid.dynamics.rollouts import WindowSet, velocity_loss
from sysid.hybrid.correction import ForceCorrection
from sysid.identify.adam import Adam
from sysid.hybrid.force_models import PerMember, correction_of
from sysid.channel_names import VELOCITY_INDEX

# the velocities (u, v_m, r) of a state (..., 6) as a strided slice: a view, not a gathered copy
VEL = slice(VELOCITY_INDEX[0], VELOCITY_INDEX[-1] + 1, VELOCITY_INDEX[1] - VELOCITY_INDEX[0])
if tuple(range(6))[VEL] != tuple(VELOCITY_INDEX):
    raise ImportError(f"the velocity channels {VELOCITY_INDEX} are not evenly spaced")


def output_penalty(f_nn: torch.Tensor, f_mmg: torch.Tensor, w_F: torch.Tensor,
                   band: float = PAPER_FORCE_BAND) -> torch.Tensor:
    """Eq. (17): w_F^T (|F_NN| - band |F_MMG|)^+ per sample, (..., 3) -> (...).

    Zero while every component of F_NN stays within `band` (20 %) of the MMG force's
    magnitude; grows linearly outside. w_F (3,) scales X [1/N], Y [1/N], N [1/(N m)].
    """
    return (torch.relu(f_nn.abs() - band * f_mmg.abs()) * w_F).sum(-1)


def adam(params, lr: float) -> Adam:
    """Adam (the paper's optimiser) updating all parameters in a few multi-tensor
    operations: torch.optim.Adam(foreach=True)'s numbers (`sysid.identify.adam.Adam`)."""
    return Adam(params, lr)


def weight_norm(net: ForceCorrection) -> torch.Tensor:
    """||theta||^2 of the FNN weights (Eq. 13), per member (losses are means over members):
    the layers' sums of squares added in order (no leading 0 +, no / 1 for one member: the
    same numbers with fewer operations and autograd nodes)."""
    norm = None
    for w in net.weights:
        square = (w * w).sum()
        norm = square if norm is None else norm + square
    if norm is None:
        raise ValueError("weight_norm: the network has no weights")
    return norm if net.members == 1 else norm / net.members


def multistep_loss(model, batch: WindowSet, w_v: torch.Tensor, w_F: torch.Tensor | None = None,
                   band: float = PAPER_FORCE_BAND):
    """(L_v, L_F) of Eqs. (15)-(17) as means over windows and steps: Euler rollouts of T steps
    from each window's first recorded state with its recorded inputs.

    `model` is a force model, or `PerMember` of a hybrid (then every FNN member rolls out
    the same windows and the losses are means over members too). L_F is 0 without `w_F`;
    `band` is the output constraint's share of |F_MMG| (Eq. 17).
    """
    states, inputs = batch.states, batch.inputs
    if isinstance(model, PerMember):
        k = model.model.correction_net.members
        states = states.unsqueeze(1).expand(states.shape[0], k, *states.shape[1:])
        inputs = inputs.unsqueeze(1).expand(inputs.shape[0], k, *inputs.shape[1:])
    if w_F is None:  # with gradients, the model's training right-hand side where it applies
        pred = integrate_loss(model, states[0], inputs, batch.dt)
    else:  # the MMG's hand-derived VJP where it applies (`integrate_training`), else autograd
        pred, f_nn, f_mmg = integrate_training(model, states[0], inputs, batch.dt)
    loss_v = velocity_loss(pred[1:, ..., VEL] - states[1:, ..., VEL], w_v)
    if w_F is None:
        return loss_v, loss_v.new_zeros(())
    return loss_v, output_penalty(f_nn, f_mmg, w_F, band).mean()


def step_loss(model, batch: WindowSet, w_v: torch.Tensor, w_F: torch.Tensor | None, training: TrainingOptions
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(lambda_v L_v + lambda_F L_F + lambda_L2 |theta|^2, L_v, L_F) of a gradient step (Eq. 13)
    with `training`'s lambdas and force band: `multistep_loss` and the `weight_norm` of the
    model's network (a force model's or a `PerMember`'s), without the operations that cannot
    change a number (lambda_v = 1; L_F = 0 without `w_F`, |theta|^2 = 0 without a network: a
    non-negative loss plus +0 is itself)."""
    t = training
    loss_v, loss_F = multistep_loss(model, batch, w_v, w_F, t.force_band)
    loss = loss_v if t.lambda_v == 1.0 else t.lambda_v * loss_v
    if w_F is not None:
        loss = loss + t.lambda_F * loss_F
    net = correction_of(model.model if isinstance(model, PerMember) else model)
    if net is not None:
        loss = loss + t.lambda_L2 * weight_norm(net)
    return loss, loss_v, loss_F


def validation_loss(model, batch: WindowSet, w_v: torch.Tensor) -> torch.Tensor:
    """L_v of `multistep_loss` without gradient (the early-stopping loss). A `PerMember` of a
    network of one member rolls out as its model: the same rollouts (one member's own force
    is the members' mean), through the model's no-grad path (the native MMG kernel where it
    applies, `CorrectedModel.eager_rate`), which equals the per-member path to round-off."""
    if isinstance(model, PerMember) and model.model.correction_net.members == 1:
        model = model.model
    with torch.no_grad():
        return multistep_loss(model, batch, w_v)[0]
