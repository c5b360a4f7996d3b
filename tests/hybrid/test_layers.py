"""The FNN's layers as one autograd Function (`sysid.hybrid.layers`) against autograd through
`ForceCorrection.layers` (torch.tanh): gradcheck in float64 for one network (2-d products)
and for members side by side; the same forces and gradients to round-off; tanh as
2 sigmoid(2 a) - 1 within its stated error of the exact tanh."""
from __future__ import annotations

import pytest
import torch

from sysid.hybrid import layers
from sysid.hybrid.correction import ForceCorrection


def _network(members: int, dtype=torch.float64, hidden=(16, 12)) -> ForceCorrection:
    torch.manual_seed(members)
    net = ForceCorrection(hidden, dtype, members)
    return net.set_standardization(torch.rand(9), torch.rand(9) + 0.5, torch.randn(3) * 100, torch.rand(3) * 1e3 + 1)


def _autograd_forces(net: ForceCorrection, z: torch.Tensor) -> torch.Tensor:
    """sigma_F y + mu_F of every member through autograd (torch.tanh), (K, ..., 3)."""
    return net.layers(z)[0] * net.output_std + net.output_mean


@pytest.mark.parametrize("members", [1, 3])
def test_gradcheck_of_the_layers_in_float64(members):
    net = _network(members)
    z = torch.randn(members, 7, 9, dtype=torch.float64, requires_grad=True)
    weights, biases = list(net.weights), list(net.biases)

    def forces(z, *parameters):
        flat = z[0] if members == 1 else z
        return layers.forces(flat, parameters[:3], parameters[3:], net.output_std, net.output_mean)
    assert torch.autograd.gradcheck(forces, (z, *weights, *biases))


@pytest.mark.parametrize("members,per_member", [(1, True), (1, False), (3, True), (3, False)])
def test_forces_and_gradients_equal_autograds(members, per_member):
    """`evaluate_standardized` (the Function) against autograd through `layers`, float64: the
    forces, the input's gradient and every parameter's, to round-off (tanh's formulas differ)."""
    net = _network(members)
    shape = (members, 5, 4, 9) if per_member else (5, 4, 9)
    z = torch.randn(shape, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(shape[:-1] + (3,), dtype=torch.float64)

    def run(evaluate):
        net.zero_grad()
        z.grad = None
        force = evaluate()
        (force * weight).sum().backward()
        return [force.detach(), z.grad.clone()] + [p.grad.clone() for p in net.parameters()]
    new = run(lambda: net.evaluate_standardized(z, per_member=per_member))
    if per_member:
        old = run(lambda: _autograd_forces(net, z))
    else:
        old = run(lambda: _autograd_forces(net, z.expand(members, *shape)).mean(0))
    assert new[0].shape == old[0].shape == shape[:-1] + (3,)
    for a, b in zip(new, old):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12 * float(b.abs().max()))


def test_float32_forces_equal_torch_tanhs_to_round_off():
    """The training network's size in float32: the Function's forces against torch.tanh's,
    relative to the largest force, within a few float32 ulps."""
    net = _network(1, torch.float32, (128, 128))
    z = torch.randn(256, 9)
    with torch.no_grad():
        new = net.evaluate_standardized(z)
        old = _autograd_forces(net, z.unsqueeze(0))[0]
    assert float((new - old).abs().max() / old.abs().max()) < 2e-6


@pytest.mark.parametrize("dtype,bound", [(torch.float32, 2.0e-7), (torch.float64, 4.0e-16)])
def test_tanh_within_its_stated_error(dtype, bound):
    """2 sigmoid(2 a) - 1 against tanh in float64 (for the float32 grid: the exact tanh to
    1e-16; for float64, torch.tanh's own rounding included), on a in [-20, 20]; it saturates
    to exactly +-1 and gives exactly 0 at 0."""
    a = torch.linspace(-20.0, 20.0, 2_000_001, dtype=dtype)
    error = (layers.tanh(a).double() - torch.tanh(a.double())).abs().max()
    assert float(error) < bound
    ends = layers.tanh(torch.tensor([-60.0, 0.0, 60.0], dtype=dtype))
    assert ends.tolist() == [-1.0, 0.0, 1.0]


def test_one_networks_inputs_are_rows():
    net = _network(1)
    weights, biases = list(net.weights), list(net.biases)
    with pytest.raises(ValueError, match="rows, n"):
        layers.forces(torch.zeros(1, 4, 9, dtype=torch.float64), weights, biases, net.output_std, net.output_mean)
