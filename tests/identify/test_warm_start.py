"""The warm start in closed form (`sysid.identify.warm_start.OneStepRegression`) against
autograd and torch's Adam on real data: its gradient equals autograd's (float64 to 1e-12,
float32 to round-off), its Adam step is torch.optim.Adam's to the last bit, and a short warm
start lands on the weights of the autograd warm start (the same batches, order and learning
rate, through torch's Adam) to float32 round-off."""
from __future__ import annotations

import pytest
import torch

from sysid.config.experiment import parse_experiment
from sysid.data.recordings import read_runs
from sysid.device import compute_threads
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, build_mmg
from sysid.identify.journal import TrainingJournal
from sysid.identify.losses import weight_norm
from sysid.identify.warm_start import OneStepRegression, standardize, warm_start
from sysid.identify.windowing import split_windows
from tiny_experiment import TRAIN_FILES

LAMBDA_L2 = 1e-4


def _experiment(hidden, members: int, epochs: int):
    return parse_experiment({"experiment": {"name": "warm", "model": "hybrid", "seed": 5},
                             "network": {"hidden": hidden, "members": members},
                             "training": {"warm_start_epochs": epochs, "lambda_L2": LAMBDA_L2}})


@pytest.fixture(scope="module")
def samples(dataset_dir):
    """Correction inputs s (N, 9) and implied residual forces (N, 3) of two real berthing logs
    (float64), as the trainer's stage 2 computes them."""
    runs = read_runs([dataset_dir / "berthing" / f for f in TRAIN_FILES])
    exp = _experiment([16], 1, 1)
    t = exp.training
    train = split_windows(runs, t.steps, t.stride_s, t.val_fraction, exp.data.exclude_suspect, torch.float64,
                          t.block_s, 0, torch.device("cpu"))[0]
    model = CorrectedModel(build_mmg(exp, torch.float64), ForceCorrection((16,), torch.float64), None, physics=True)
    return standardize(model, train, t.stride_s)


def _network(samples, hidden, members: int, dtype) -> ForceCorrection:
    s, residual = samples
    torch.manual_seed(11)
    net = ForceCorrection(hidden, dtype, members)
    return net.set_standardization(s.mean(0), s.std(0), residual.mean(0), residual.std(0))


def _batch(net, samples, rows: slice):
    s, residual = samples
    z = net.standardize_inputs(s[rows]).expand(net.members, -1, -1)
    target = ((residual[rows] - net.output_mean) / net.output_std).to(net.input_mean.dtype)
    return z, target


def _autograd(net, z, target):
    net.zero_grad()
    loss = ((net.layers(z)[0] - target) ** 2).mean() + LAMBDA_L2 * weight_norm(net)
    loss.backward()
    return loss.detach(), [q.grad.clone() for q in [*net.weights, *net.biases]]


@pytest.mark.parametrize("dtype, tolerance", [(torch.float64, 1e-12), (torch.float32, 2e-6)])
@pytest.mark.parametrize("hidden, members", [((128, 128), 1), ((16, 12, 8), 3)])
def test_closed_form_gradient_equals_autograd(samples, hidden, members, dtype, tolerance):
    net = _network(samples, hidden, members, dtype)
    z, target = _batch(net, samples, slice(40, 296))
    loss, expected = _autograd(net, z, target)
    regression = OneStepRegression(net, LAMBDA_L2, 3e-3)
    got = regression.gradient(z, target.T, loss=True)
    assert got is not None and float(got) == pytest.approx(float(loss), rel=tolerance)
    for a, b in zip(regression.grads, expected, strict=True):
        assert a.shape == b.shape
        assert float((a - b).abs().max()) <= tolerance * float(b.abs().max()), (hidden, members, dtype)
    assert regression.gradient(z, target.T) is None  # the loss only when asked


def test_adam_step_is_torch_adam_to_the_bit(samples):
    net = _network(samples, (32, 32), 2, torch.float32)
    regression = OneStepRegression(net, LAMBDA_L2, 3e-3)
    params = [*net.weights, *net.biases]
    torch_adam = torch.optim.Adam(params, lr=3e-3, foreach=True)
    gen = torch.Generator().manual_seed(3)
    for _ in range(7):
        for q, d in zip(params, regression.grads):
            d.copy_(torch.randn(q.shape, generator=gen) * 10.0 ** float(torch.randint(-6, 2, (), generator=gen)))
            q.grad = d.clone()
        regression.adam_step()
        torch_adam.step()
    assert all(torch.equal(q.detach(), v) for q, v in zip(params, regression.views))
    assert not torch.equal(params[0].detach(), _network(samples, (32, 32), 2, torch.float32).weights[0].detach())


def _autograd_warm_start(net, samples, epochs: int, seed: int) -> None:
    """The warm start through autograd and torch's Adam: its batches, order and learning rate."""
    z, target = _batch(net, samples, slice(None))
    opt = torch.optim.Adam(net.parameters(), lr=3e-3, foreach=True)
    gen = torch.Generator().manual_seed(seed + 2)
    for _ in range(epochs):
        order = torch.randperm(len(target), generator=gen)
        for lo in range(0, len(target), 256):
            rows = order[lo:lo + 256]
            opt.zero_grad()
            _autograd(net, z[:, rows], target[rows])
            opt.step()


def test_warm_start_lands_on_the_autograd_warm_starts_weights(samples):
    epochs = 4
    exp = _experiment([128, 128], 2, epochs)
    s, residual = samples[0].float(), samples[1].float()
    with compute_threads(1):
        closed = _network(samples, (128, 128), 2, torch.float32)
        lines: list[str] = []
        warm_start(closed, s, residual, "cpu", exp, TrainingJournal(lines.append, False))
        reference = _network(samples, (128, 128), 2, torch.float32)
        _autograd_warm_start(reference, samples, epochs, exp.experiment.seed)
    start = _network(samples, (128, 128), 2, torch.float32)
    for a, b, c in zip(closed.parameters(), reference.parameters(), start.parameters()):
        a, b, c = a.detach(), b.detach(), c.detach()
        moved = float((b - c).abs().max())
        assert moved > 1e-3  # the warm start moved every parameter
        # round-off of float32 over 4 epochs of Adam: far below what the warm start moved
        assert float((a - b).abs().max()) <= 2e-5 * float(b.abs().max())
    # a full and a partial minibatch an epoch; the epochs' losses logged
    assert len(s) > 256 and len(s) % 256 and any("warm start" in line for line in lines)
