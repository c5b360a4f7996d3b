"""The identification's right-hand side with a hand-derived VJP with respect to the state and
the identified hull coefficients (`sysid.mmg.vjp.identified_rate`): the hull's linear terms
against the paper's formulas, finite differences (gradcheck, float64) with respect to the
state and the coefficients, autograd over the forward on rollouts, the boundary where autograd
is used instead, and a float32 identification of mmg_identified_D2 on the real data equal to
the autograd path's to round-off."""
from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
import torch

from sysid.dynamics.equations import derivative
from sysid.mmg import native, vjp
from sysid.mmg.coefficients import derived_constants
from sysid.mmg.model import MMG
from sysid.mmg.ship import load_ship
from sysid.mmg.tangents import HULL_LINEAR
from mmg_rows import branch_rows

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("X_vr", "Y_v", "Y_r", "N_v", "N_r")
BOUNDS = {"X_vr": (-2.0, 2.0), "Y_v": (-5.0, 5.0), "Y_r": (-5.0, 5.0), "N_v": (-5.0, 5.0), "N_r": (-5.0, 5.0)}


def _identified(dtype=torch.float64, names=NAMES, ship="esso_osaka", **kw) -> MMG:
    return MMG(load_ship(ship), names, {k: v for k, v in BOUNDS.items() if k in names}, dtype=dtype, **kw)


def _autograd(mmg: MMG) -> MMG:
    mmg.identified_rate = lambda state, inputs: None  # the torch path: autograd over the forward
    return mmg


def test_the_linear_terms_are_the_papers():
    """X_H = q (... + X_vr v r L), Y_H = q (Y_v v |u| + Y_r r L u - ...), N_H = q L (N_v v u
    + N_r r L |u| - ...) (paper Eq. 26): each coefficient's product and other factors, read
    off the hull's table; C_D, C_rY, C_rN (cross-flow) and X_0F (resistance) are not linear
    terms of a product."""
    assert HULL_LINEAR == {"X_vr": (2, 0, ("q", "L_pp")), "Y_v": (1, 1, ("q",)), "Y_r": (3, 1, ("q", "L_pp")),
                           "N_v": (0, 2, ("qL",)), "N_r": (4, 2, ("qL", "L_pp"))}


def test_no_derived_constant_depends_on_the_linear_coefficients():
    """The mass terms and every other derived constant are the same with each coefficient
    moved: dx/dt is affine in F with constant matrices."""
    mmg = MMG(load_ship("esso_osaka"))
    view = mmg.coefficients.values_view(torch.float64)
    names = mmg.coefficients.names
    base = derived_constants(view, names)
    for name in HULL_LINEAR:
        moved = dict(view.__dict__)
        moved[name] = view.__dict__[name] * 1.5 + 0.1
        other = derived_constants(type(view)(**moved), names)
        assert all(torch.equal(other[k], base[k]) for k in base), name


def _function(mmg: MMG, inputs: torch.Tensor):
    """(state, theta) -> dx/dt through `_IdentifiedRate` with the coefficients set to theta."""
    names = mmg.coefficients.trainable_names

    def rate(state, theta):
        mmg.coefficients.assign(dict(zip(names, theta.detach().tolist())))
        with torch.no_grad():
            c = mmg.coefficients.values_view(state.dtype)
            slope = vjp._slopes(c, tuple(names), state)
        return vjp._IdentifiedRate.apply(state, inputs, theta, c, True, tuple(HULL_LINEAR[n][0] for n in names),
                                         slope)
    return rate


@pytest.mark.parametrize("kernel", ["native", "torch"])
def test_gradcheck_float64_state_and_coefficients(kernel):
    if kernel == "native" and not native.available():
        pytest.skip("the native kernel is not built here")
    state, inputs = branch_rows()
    mmg = _identified()
    theta0 = torch.tensor([-0.3, -0.25, 0.05, -0.09, -0.05], dtype=torch.float64)
    with native.torch_path() if kernel == "torch" else contextlib.nullcontext():
        for i in range(len(state)):
            x = state[i:i + 1].clone().requires_grad_(True)
            theta = theta0.clone().requires_grad_(True)
            r = _function(mmg, inputs[i:i + 1])
            assert torch.autograd.gradcheck(r, (x, theta), eps=1e-7, atol=1e-7, rtol=1e-6, fast_mode=True), f"row {i}"


@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
def test_a_rollouts_gradients_equal_autograds(dtype, rtol):
    """A 5-step Euler rollout of the branch rows and its loss: states, the state's and the raw
    coefficients' gradients equal autograd's over the forward, to round-off."""
    state, inputs = (t.to(dtype) for t in branch_rows())
    results = []
    for mmg in (_identified(dtype), _autograd(_identified(dtype))):
        x0 = state.clone().requires_grad_(True)
        x = x0
        for _ in range(5):
            x = x + 0.5 * derivative(mmg, x, inputs)
        x[..., [1, 3, 5]].square().sum().backward()
        results.append([x.detach(), x0.grad] + [p.grad for p in mmg.parameters()])
    assert vjp.identified_rate(_identified(dtype), state, inputs) is not None
    for new, old in zip(*results):
        torch.testing.assert_close(new, old, rtol=rtol, atol=rtol * float(old.abs().max()))


def test_the_boundary_other_coefficients_families_and_transforms_use_autograd():
    state, inputs = branch_rows()
    assert vjp.identified_rate(_identified(), state, inputs) is not None
    assert vjp.identified_rate(_identified(names=("Y_v", "N_r")), state, inputs) is not None
    # a coefficient out of scope makes the whole rollout autograd's: t_P (derived constants
    # depend on it), C_D (non-linear through the cross-flow), a standard hull's X_vr
    assert vjp.identified_rate(MMG(load_ship("esso_osaka"), ["Y_v", "t_P"], {"Y_v": (-5.0, 5.0)}),
                               state, inputs) is None
    assert vjp.identified_rate(MMG(load_ship("esso_osaka"), ["X_vr", "C_D"], {"X_vr": (-2.0, 2.0)}),
                               state, inputs) is None
    assert vjp.identified_rate(MMG(load_ship("kvlcc2_l7"), ["X_vr"]), state, inputs) is None
    assert vjp.identified_rate(_identified(quadrature="simpson"), state, inputs) is None
    assert vjp.identified_rate(MMG(load_ship("esso_osaka")), state, inputs) is None
    assert vjp.identified_rate(_identified().requires_grad_(False), state, inputs) is None
    with torch.no_grad():
        assert vjp.identified_rate(_identified(), state, inputs) is None
    mmg = _identified()
    seen = []
    torch.func.jacfwd(lambda s: (seen.append(vjp.identified_rate(mmg, s, inputs[:1])),
                                 derivative(mmg, s, inputs[:1]))[1])(state[:1])
    assert seen == [None]                                  # a torch.func transform (the sigma's)

    # the fallback's gradient is autograd's over the forward: with t_P trainable beside Y_v,
    # the derivative's gradients equal those of an explicit autograd model
    def grads(mmg):
        x0 = state.clone().requires_grad_(True)
        derivative(mmg, x0, inputs).square().sum().backward()
        return [x0.grad] + [p.grad for p in mmg.parameters()]
    bounds = {"Y_v": (-5.0, 5.0), "t_P": (0.0, 0.9)}
    for new, old in zip(grads(MMG(load_ship("esso_osaka"), ["Y_v", "t_P"], bounds)),
                        grads(_autograd(MMG(load_ship("esso_osaka"), ["Y_v", "t_P"], bounds)))):
        assert torch.equal(new, old)


def test_a_float32_identification_equals_the_autograd_path(dataset_dir, monkeypatch):
    """mmg_identified_D2, seed 0, 3 identification epochs in float32 on the real data: the
    identified coefficients and val_loss_multistep of the VJP path equal autograd's to
    round-off."""
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import Trainer
    from sysid.runs.lifecycle import training_runs
    base = load_experiment(ROOT / "configs" / "experiments" / "mmg_identified_D2.toml")
    exp = base.replace(identify={"epochs": 3}, training={"threads": 1})
    runs = training_runs(base, None)
    assert exp.training.dtype.value == "float32"
    calls = []
    original = vjp.identified_rate
    monkeypatch.setattr(vjp, "identified_rate", lambda *a: calls.append(1) or original(*a))
    fit = Trainer(exp, progress=False, log=lambda _: None).fit(runs)
    assert len(calls) > 0
    monkeypatch.setattr(MMG, "identified_rate", lambda self, state, inputs: None)
    reference = Trainer(exp, progress=False, log=lambda _: None).fit(runs)
    for name in NAMES:
        assert fit.summary_.identified[name] == pytest.approx(reference.summary_.identified[name], rel=1e-5)
    assert fit.summary_.val_loss_multistep == pytest.approx(reference.summary_.val_loss_multistep, rel=1e-5)
    assert fit.summary_.identified != dict.fromkeys(NAMES, 0.0)
