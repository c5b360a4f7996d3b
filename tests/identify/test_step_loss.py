"""A gradient step's loss (`sysid.identify.losses.step_loss`, what `GradientStep` minimises)
is Eq. 13 written out, lambda_v L_v + lambda_F L_F + lambda_L2 |theta|^2 with |theta|^2 the
members' mean of the layers' sums of squares, bit for bit: the loss and its terms, and every
parameter's gradient (`torch.equal`), on real D1 and D2 training windows, hybrid and NN-only,
one network and three side by side, lambda_v of 1 (its product left out) and of 0.5."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.identify.losses import multistep_loss, step_loss

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", params=["D1", "D2"])
def windows(request, dataset_dir):
    """(experiment, its first 64 float32 training windows, w_v) of hybrid_D1 or hybrid_D2."""
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import split_windows
    from sysid.runs.lifecycle import training_runs
    exp = load_experiment(ROOT / "configs" / "experiments" / f"hybrid_{request.param}.toml")
    t = exp.training
    train = split_windows(training_runs(exp, None), t.steps, t.stride_s, t.val_fraction, True, torch.float32,
                          t.block_s, exp.experiment.seed)[0]
    w_v = 1.0 / train.states[:, :, [1, 3, 5]].reshape(-1, 3).var(0)
    return exp, train.select(torch.arange(64)), w_v


def _written_out(model, net, batch, w_v, w_F, t):
    """Eq. 13 as the trainer wrote it before: every term's product and sum through autograd."""
    loss_v, loss_F = multistep_loss(model, batch, w_v, w_F, t.force_band)
    norm = sum((w * w).sum() for w in net.weights) / net.members
    return t.lambda_v * loss_v + t.lambda_F * loss_F + t.lambda_L2 * norm, loss_v, loss_F


@pytest.mark.parametrize("members", [1, 3])
@pytest.mark.parametrize("physics", [True, False], ids=["hybrid", "nn-only"])
@pytest.mark.parametrize("lambda_v", [1.0, 0.5])
def test_the_step_loss_is_eq_13_written_out_bit_for_bit(windows, members, physics, lambda_v):
    exp, batch, w_v = windows
    t = dataclasses.replace(exp.training, lambda_v=lambda_v, lambda_L2=1e-3)
    torch.manual_seed(0)
    net = ForceCorrection(exp.network.hidden, torch.float32, members)
    model = PerMember(CorrectedModel(build_mmg(exp, torch.float32).requires_grad_(False), net, None, physics,
                                     exp.gate.space))
    w_F = 1.0 / net.output_std if physics else None
    results = []
    for loss_of in (_written_out, lambda *args: step_loss(args[0], *args[2:])):
        net.zero_grad(set_to_none=True)
        losses = loss_of(model, net, batch, w_v, w_F, t)
        losses[0].backward()
        results.append(([v.detach() for v in losses], [p.grad for p in net.parameters()]))
    (expected, expected_grads), (got, got_grads) = results
    assert all(torch.equal(a, b) for a, b in zip(expected, got)), (expected, got)
    assert all(g is not None and torch.equal(a, g) for a, g in zip(expected_grads, got_grads))
    assert float(expected[1]) > 0
    assert (float(expected[2]) > 0) == physics
