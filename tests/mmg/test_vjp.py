"""The MMG part of the hybrid's training right-hand side with its hand-derived VJP
(`sysid.mmg.vjp`, `sysid.mmg.tangents`) against autograd through the MMG, the FNN's inputs
and the equations of motion: finite differences (gradcheck, float64) on rows that take every
branch, autograd's own choice at the branch switches, the same forward values in float64
and float32 on real data, and the boundary where autograd is used instead."""
from __future__ import annotations

import subprocess
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from sysid.dynamics.equations import integrate_training
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember
from sysid.mmg.model import MMG
from sysid.mmg.propeller import propeller_inflow
from sysid.mmg.rudder import rudder_inflow
from sysid.mmg.ship import load_ship
from sysid.mmg.tangents import forces_with_tangents, supported
from sysid.mmg import native
from sysid.mmg.vjp import mmg_rate
from mmg_rows import ESSO, branch_rows as _branch_rows, reference as _reference, switch_rows as _switch_rows

C = ESSO.coefficients.values_view(torch.float64)


@pytest.fixture(autouse=True)
def _torch_path():
    """These are tests of the VJP written out in torch, the native kernel's fallback (the
    kernel itself: tests/mmg/test_native.py)."""
    with native.torch_path():
        yield


def test_the_rows_take_every_branch():
    state, inputs = _branch_rows()
    u, v, r, n, delta = state[:, 1], state[:, 3], state[:, 5], inputs[:, 0], inputs[:, 1]
    prop = propeller_inflow(u, v, r, n, C)
    rud = rudder_inflow(u, v, r, n, delta, C, prop)
    b = torch.stack([r * C.C_rY, r * C.C_rN], -1)
    ahead, moving = n >= 0, u >= 0
    yoshimura = ahead & (prop.K_T > 0)
    u_p = u * prop.one_minus_wP
    s = (C.eps2_one_minus_eta * u_p * u_p + C.eps2_eta * (u_p + n * torch.sqrt(prop.K_T.abs() * C.kitagawa_jet_eps2))
         * (u_p + n * torch.sqrt(prop.K_T.abs() * C.kitagawa_jet_eps2)).abs() + C.C_PR * u * u)
    branches = {
        "crossing": (v.abs()[:, None] < b.abs() * C.half_L).any(-1),
        "no crossing": (v.abs()[:, None] >= b.abs() * C.half_L).all(-1),
        "Q1": ahead & moving & (n != 0), "Q2": ahead & ~moving, "reverse": ~ahead, "n = 0": n == 0,
        "J_s < -0.35": ~ahead & (prop.J_s < -0.35), "J_s in [-0.35, -0.06]": ~ahead & (prop.J_s.abs() <= 0.35)
        & (prop.J_s <= -0.06), "J_s > -0.06": ~ahead & (prop.J_s > -0.06),
        "J_s >= C10": ~ahead & (prop.J_s >= C.C10), "J_s < C10": ~ahead & (prop.J_s < C.C10),
        "wake clamped": (u > 0) & (prop.one_minus_wP < 1e-15), "wake free": (u > 0) & (prop.one_minus_wP > 1e-15),
        "Yoshimura": yoshimura, "Kitagawa s > 0": ~yoshimura & moving & (s > 0),
        "Kitagawa s < 0": ~yoshimura & moving & (s < 0), "u_R = u": ~yoshimura & ~moving,
        "gamma_P": v + C.x_R * r >= 0, "gamma_N": v + C.x_R * r < 0,
        "calm": inputs[:, 2] == 0, "wind": inputs[:, 2] > 0, "u_R > 0": rud.u_R > 0,
    }
    missing = [name for name, taken in branches.items() if not bool(taken.any())]
    assert not missing, f"no row takes {missing}"


def test_gradcheck_float64_on_every_branch():
    """Row by row (each row's Jacobian against finite differences at its own scale; the fast
    mode compares random projections of it)."""
    state, inputs = _branch_rows()
    for i in range(len(state)):
        x = state[i:i + 1].clone().requires_grad_(True)
        assert torch.autograd.gradcheck(lambda z: mmg_rate(z, inputs[i:i + 1], C), (x,), eps=1e-7, atol=1e-7,
                                        rtol=1e-6, fast_mode=True), f"row {i}"


@pytest.mark.parametrize("rows", [_branch_rows, _switch_rows])
def test_the_vjp_equals_autograds_on_branches_and_at_the_switches(rows):
    state, inputs = rows()
    gen = torch.Generator().manual_seed(0)
    weights = torch.randn(len(state), 18, generator=gen, dtype=torch.float64)
    x_new = state.clone().requires_grad_(True)
    x_old = state.clone().requires_grad_(True)
    out = mmg_rate(x_new, inputs, C)
    ref = _reference(x_old, inputs)
    torch.testing.assert_close(out, ref, rtol=1e-12, atol=1e-12)
    (out * weights).sum().backward()
    (ref * weights).sum().backward()
    assert torch.isfinite(x_new.grad).all()
    torch.testing.assert_close(x_new.grad, x_old.grad, rtol=1e-9, atol=1e-9)


def _real_windows(dataset_dir, dtype, count=128, length=11):
    from sysid.data.recordings import read_run, stack_windows
    from tiny_experiment import TRAIN_FILES
    run = read_run(dataset_dir / "berthing" / TRAIN_FILES[0])
    starts = np.linspace(0, len(run) - length - 1, count).astype(int)
    return stack_windows(run, starts, length, dtype)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_forward_values_equal_the_autograd_path_on_real_data(dataset_dir, dtype):
    states, inputs = _real_windows(dataset_dir, dtype)
    mmg = MMG(load_ship("esso_osaka"), dtype=dtype)
    state, inp = states.reshape(-1, 6), inputs.reshape(-1, 4)
    out = mmg_rate(state, inp, mmg.coefficients.values_view(dtype))
    ref = _reference(state, inp, mmg)
    scale = ref.abs().amax(0) + 1e-12
    tolerance = 1e-12 if dtype == torch.float64 else 2e-6
    assert float(((out - ref).abs() / scale).max()) < tolerance


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_a_training_rollout_equals_the_autograd_rollout(dataset_dir, dtype):
    """States, F_NN, F_MMG and the network's gradients of a T = 10 Euler rollout of a hybrid
    (two FNN members) through `training_rate` and through autograd."""
    states, inputs = _real_windows(dataset_dir, dtype, count=64)
    torch.manual_seed(0)
    net = ForceCorrection((16, 16), dtype, members=2)
    net.set_standardization(states.reshape(-1, 6).mean(0).repeat(2)[:9], states.reshape(-1, 6).std(0).repeat(2)[:9],
                            torch.zeros(3), torch.tensor([2.0, 3.0, 1.5]))
    model = PerMember(CorrectedModel(MMG(load_ship("esso_osaka"), dtype=dtype), net))
    x0 = states[0].unsqueeze(0).expand(2, -1, -1)
    u = inputs.unsqueeze(1).expand(-1, 2, -1, -1)
    results = []
    for fast in (True, False):
        net.zero_grad()
        pred, f_nn, f_mmg = integrate_training(model, x0, u, 0.1, fast=fast)
        (pred.square().sum() + f_nn.square().sum() + f_mmg.square().sum()).backward()
        results.append([pred, f_nn, f_mmg] + [p.grad.clone() for p in net.parameters()])
    rtol = 1e-10 if dtype == torch.float64 else 1e-4
    for new, old in zip(*results):
        torch.testing.assert_close(new, old, rtol=rtol, atol=rtol * float(old.detach().abs().max()))


def test_the_boundary_standard_families_trainable_coefficients_and_simpson_use_autograd():
    assert supported(ESSO)
    assert not supported(MMG(load_ship("kvlcc2_l7")))
    identified = MMG(load_ship("esso_osaka"), trainable=["X_vr"])
    assert not supported(identified)                      # being identified: autograd
    assert supported(identified.requires_grad_(False))    # frozen for the hybrid: constants
    assert not supported(MMG(load_ship("esso_osaka"), quadrature="simpson"))
    net = ForceCorrection((8,), torch.float64)
    # standard families: the native kernel's training rate (`sysid.mmg.native.families_of`)
    assert CorrectedModel(MMG(load_ship("kvlcc2_l7")), net).training_rate() is not None
    assert CorrectedModel(MMG(load_ship("esso_osaka"), quadrature="simpson"), net).training_rate() is None
    assert CorrectedModel(ESSO, net, physics=False).training_rate() is not None  # NN-only: `fused_rate.nn_rate`
    assert CorrectedModel(ESSO, net).training_rate() is not None
    with torch.no_grad():
        assert CorrectedModel(ESSO, net).training_rate() is None


def test_a_standard_ship_trains_with_the_same_rollout():
    """kvlcc2 (standard families): integrate_training gives integrate_with_forces' numbers,
    through the native kernel to round-off and, where the kernel does not apply, through
    autograd over the forward."""
    from sysid.dynamics.equations import integrate_with_forces
    mmg = MMG(load_ship("kvlcc2_l7"))
    model = CorrectedModel(mmg, ForceCorrection((8,), torch.float64))
    state, inputs = _branch_rows()
    u = inputs.expand(4, -1, -1)
    reference = integrate_with_forces(model, state, u, 0.5)
    with native.torch_path():
        pred, f_nn, f_mmg = integrate_training(model, state, u, 0.5)
    torch.testing.assert_close(pred, reference.states, rtol=1e-13, atol=0)
    torch.testing.assert_close(f_mmg, reference.forces.mmg, rtol=1e-13, atol=1e-9)
    pred, f_nn, f_mmg = integrate_training(model, state, u, 0.5)
    torch.testing.assert_close(pred, reference.states, rtol=1e-11, atol=0)
    torch.testing.assert_close(f_mmg, reference.forces.mmg, rtol=1e-11, atol=1e-9)


def test_frozen_identified_coefficients_are_read_as_constants():
    """A hybrid on an identified MMG (coefficients assigned, then frozen) gets the values and
    the VJP of that MMG, not of the ship file's."""
    mmg = MMG(load_ship("esso_osaka"), trainable=["X_vr", "C_D"], bounds={"C_D": (0.0, 5.0)})
    mmg.coefficients.assign({"X_vr": 0.45, "C_D": 1.3})
    mmg.requires_grad_(False)
    state, inputs = _branch_rows()
    weights = torch.randn(len(state), 18, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    x_new, x_old = state.clone().requires_grad_(True), state.clone().requires_grad_(True)
    out = mmg_rate(x_new, inputs, mmg.coefficients.values_view(torch.float64))
    ref = _reference(x_old, inputs, mmg)
    torch.testing.assert_close(out, ref, rtol=1e-12, atol=1e-12)
    assert not torch.allclose(ref, _reference(state, inputs))  # the assigned values matter
    (out * weights).sum().backward()
    (ref * weights).sum().backward()
    torch.testing.assert_close(x_new.grad, x_old.grad, rtol=1e-9, atol=1e-9)


# the last commit of `forces_with_tangents` in one piece
ONE_PIECE = "95543ca"


def _one_piece_tangents():
    """`sysid.mmg.tangents` as of `ONE_PIECE` (`git show`), as a module of its own."""
    root = Path(__file__).resolve().parents[2]
    source = subprocess.run(["git", "-C", str(root), "show", f"{ONE_PIECE}:sysid/mmg/tangents.py"], check=True,
                            capture_output=True, text=True).stdout
    module = types.ModuleType("one_piece_tangents")
    exec(compile(source, "one_piece_tangents.py", "exec"), module.__dict__)
    return module


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("wind", [True, False])
def test_the_parts_give_the_one_piece_functions_numbers_bit_for_bit(dtype, wind):
    """`forces_with_tangents` in named parts (hull, propeller, rudder, wind) gives the same
    bits as the one function of `ONE_PIECE` on every branch and at the switches."""
    old = _one_piece_tangents()
    c = ESSO.coefficients.values_view(dtype)
    for state, inputs in (_branch_rows(), _switch_rows()):
        state, inputs = state.to(dtype), inputs.to(dtype)
        with torch.no_grad():
            new, before = forces_with_tangents(state, inputs, c, wind), old.forces_with_tangents(state, inputs, c, wind)
        for a, b in zip(new, before):
            assert a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b)
