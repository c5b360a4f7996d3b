"""`euler_grid` against its peer, torchdiffeq's fixed-grid ``odeint(..., method="euler")``:
the same states, per-step forces and network gradients, bit for bit, for the training
rollout (a hybrid through its ``training_rate``) and for `integrate`'s right-hand side."""
from __future__ import annotations

import pytest
import torch
from torchdiffeq import odeint

from sysid.dynamics.equations import ShipDynamics, TrainingDynamics, euler_grid
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel
from sysid.mmg.model import MMG
from sysid.mmg.ship import load_ship


def _case(dtype):
    """A hybrid (9-16-16-3 FNN) on the Esso Osaka MMG, 8 ships at 0.3-0.4 m/s, 11 steps of
    random revolutions, rudder and wind."""
    g = torch.Generator().manual_seed(2)
    x0 = torch.zeros(8, 6, dtype=dtype)
    x0[:, 1] = 0.3 + 0.1 * torch.rand(8, generator=g, dtype=dtype)  # u [m/s] (state x, u, y, v, psi, r)
    x0[:, 3] = 0.02 * torch.randn(8, generator=g, dtype=dtype)      # v_m [m/s]
    inputs = torch.zeros(11, 8, 4, dtype=dtype)
    inputs[..., 0] = 8.0 + torch.rand(11, 8, generator=g, dtype=dtype)
    inputs[..., 1] = 0.3 * torch.randn(11, 8, generator=g, dtype=dtype)
    inputs[..., 2] = 5.0 * torch.rand(11, 8, generator=g, dtype=dtype)
    inputs[..., 3] = 6.0 * torch.rand(11, 8, generator=g, dtype=dtype)
    torch.manual_seed(3)
    net = ForceCorrection((16, 16), dtype)
    net.set_standardization(torch.zeros(9, dtype=dtype), torch.ones(9, dtype=dtype), torch.zeros(3, dtype=dtype),
                            torch.tensor([2.0, 3.0, 1.5], dtype=dtype))
    return CorrectedModel(MMG(load_ship("esso_osaka"), dtype=dtype), net), x0, inputs


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_training_rollout_is_torchdiffeqs_euler_to_the_bit(dtype):
    model, x0, inputs = _case(dtype)
    rate = model.training_rate()
    assert rate is not None
    tau = torch.arange(inputs.shape[0], dtype=dtype)
    results = []
    for solve in (euler_grid, lambda f, y, t: odeint(f, y, t, method="euler")):
        model.zero_grad()
        rhs = TrainingDynamics(rate, inputs, 0.5)
        states = solve(rhs, x0, tau)
        f_nn, f_mmg = torch.stack(rhs.f_nn), torch.stack(rhs.f_mmg)
        (states[1:, :, 1::2].square().sum() + 1e-6 * f_nn.square().sum()).backward()
        results.append([states, f_nn, f_mmg] + [p.grad.clone() for p in model.correction_net.parameters()])
    ours, peer = results
    assert float(ours[0][-1, :, 0].detach().min()) > 1.0  # the ships moved ahead [m]
    for a, b in zip(ours, peer, strict=True):
        assert torch.equal(a, b)


def test_integrates_rhs_is_torchdiffeqs_euler_to_the_bit():
    model, x0, inputs = _case(torch.float64)
    tau = torch.arange(inputs.shape[0], dtype=torch.float64)
    with torch.no_grad():
        ours = euler_grid(ShipDynamics(model, inputs, 0.5), x0, tau)
        peer = odeint(ShipDynamics(model, inputs, 0.5), x0, tau, method="euler")
    assert torch.equal(ours, peer) and ours.shape == (11, 8, 6)
