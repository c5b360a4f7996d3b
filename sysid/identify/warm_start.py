"""Stages 2 and 4 of training: the FNN's standardisation and its warm start.

Input statistics come from the correction inputs s (N, 9) at the training windows' step
starts (relative wind computed from the recorded state and true wind, as the model sees
it); output statistics from the residual force the data imply,
M * (v[k+1] - v[k]) / dt + C(v[k]) - F_MMG(x[k]) (for NN-only without F_MMG), the force
that makes one Euler step land on the record [N, N, N m]. The warm start regresses every FNN
member on that standardised residual (one-step fit) with Adam.
"""
from __future__ import annotations

import torch

from sysid.config.experiment import Experiment
from sysid.dynamics.equations import required_force
from sysid.dynamics.rollouts import WindowSet
from sysid.errors import TrainingError
from sysid.hybrid.correction import ForceCorrection, correction_inputs
from sysid.hybrid.force_models import CorrectedModel
from sysid.identify.journal import TrainingJournal
from sysid.identify.losses import VEL, adam, weight_norm


def implied_residual(model: CorrectedModel, windows: WindowSet, pairs: int = 2
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Correction inputs s (N, 9), residual force (N, 3) and F_MMG (N, 3) at step starts."""
    # the first `pairs` steps of each window: with 2-s strides that covers each step once
    states, inputs = windows.states[:pairs + 1], windows.inputs[:pairs + 1]
    x, nxt, inp = states[:-1].reshape(-1, 6), states[1:].reshape(-1, 6), inputs[:-1].reshape(-1, 4)
    with torch.no_grad():
        acc = (nxt[:, VEL] - x[:, VEL]) / windows.dt
        need = required_force(x, acc, model.coefficients)
        forces = model.mmg(x, inp)
        f_mmg = forces.mmg if model.physics else torch.zeros_like(need)
        s = correction_inputs(x, inp, forces.relative_wind)
    return s, need - f_mmg, f_mmg


def standardize(model: CorrectedModel, train: WindowSet, stride_s: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Stage 2: the FNN's input statistics and the output statistics of the implied residual
    force, on the first steps of the training windows slid by `stride_s` [s]; returns the
    correction inputs s (N, 9) and the residual (N, 3) for the warm start."""
    net = model.correction_net
    stride = max(1, int(round(stride_s / train.dt)))
    s, residual, _ = implied_residual(model, train, stride)
    net.set_standardization(s.mean(0), s.std(0), residual.mean(0), residual.std(0))
    return s, residual


def warm_start(net: ForceCorrection, s: torch.Tensor, residual: torch.Tensor, device, experiment: Experiment,
               journal: TrainingJournal) -> None:
    """Stage 4: every FNN member regresses the standardised residual force (one step),
    ``[training] warm_start_epochs`` epochs of minibatches of 256 in a seeded order."""
    t = experiment.training
    target = (residual - net.output_mean) / net.output_std
    z = net.standardize_inputs(s).expand(net.members, *s.shape)  # (K, N, 9), fixed over the warm start
    opt = adam(net.parameters(), 3e-3)
    gen = torch.Generator().manual_seed(experiment.experiment.seed + 2)
    bar = journal.epochs(range(t.warm_start_epochs), "warm start", t.warm_start_epochs, 0)
    journal.warm_start_begins(bar, t.warm_start_epochs, len(s))
    for epoch in bar:
        order = torch.randperm(len(s), generator=gen).to(device)
        for lo in range(0, len(s), 256):
            idx = order[lo:lo + 256]
            y = net.layers(z[:, idx])[0]
            loss = ((y - target[idx]) ** 2).mean() + t.lambda_L2 * weight_norm(net)
            opt.zero_grad()
            loss.backward()
            opt.step()
        if not torch.isfinite(loss):
            raise TrainingError(f"{experiment.source}: [training] the warm-start loss became "
                                f"{loss.detach().item()}; no run written")
        journal.warm_start_epoch(bar, epoch + 1, t.warm_start_epochs, loss.item())
