"""The eager MMG forward: its operation count (the eager path is dispatch-bound: its speed is
the number of torch operations per call), and the cached values view of the coefficients
(constants computed once, stale never)."""
from collections import Counter

import pytest
import torch
from torch.func import functional_call, jacfwd
from torch.utils._python_dispatch import TorchDispatchMode

from sysid import MMG, load_ship
from sysid.dynamics.equations import derivative
from sysid.mmg.coefficients import Coefficients

# one recorded-like state and inputs: ahead, turning, wind on the bow
STATE = [[0.0, 0.35, 0.0, 0.01, 0.2, 0.01]]
INPUTS = [[10.0, 0.35, 2.0, 1.0]]


class _Operations(TorchDispatchMode):
    """Counts the aten operations run inside it; `constant_only` counts those whose tensor
    arguments are all 0-d (operations between coefficients)."""

    def __init__(self):
        super().__init__()
        self.count = Counter()
        self.constant_only = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        tensors = [a for a in args if isinstance(a, torch.Tensor)]
        if tensors and all(t.dim() == 0 for t in tensors):
            self.constant_only += 1
        self.count[str(func.overloadpacket)] += 1
        return func(*args, **(kwargs or {}))


def _operations(model, state, inputs):
    with torch.no_grad():
        derivative(model, state, inputs)  # builds the values view
        with _Operations() as ops:
            derivative(model, state, inputs)
    return ops


# Budget of one right-hand side call (lean derivative: the forward's speed, drift angle and
# constants computed once (`sysid.mmg.motion`), forces by component as (..., 3) lanes, the
# equations of motion as one product), by the design of the forward: Esso Osaka (Yoshimura
# hull with both cross-flow integrals in one 2-lane pass and one (8, 3) coefficient product;
# four-quadrant propeller with Y/N lanes; four-quadrant rudder with (X, Y, N) lanes; relative
# wind; Fujiwara wind as one (8, 3) harmonic product). Measured: Esso Osaka 148, KVLCC2 88
# (before: 568 and 339, then 352 and 253).
BUDGET = {"esso_osaka": 155, "configs/ships/kvlcc2_l7.toml": 95}


@pytest.mark.parametrize("ship", sorted(BUDGET))
def test_one_forward_stays_within_its_operation_budget(ship):
    model = MMG(load_ship(ship))
    ops = _operations(model, torch.tensor(STATE, dtype=torch.float64), torch.tensor(INPUTS, dtype=torch.float64))
    total = sum(ops.count.values())
    assert total <= BUDGET[ship], f"{total} operations: {ops.count.most_common(8)}"
    # no operation between coefficients alone (constants are computed once, when cached),
    # no cast and no tensor made from a Python number inside the forward, no host sync
    assert ops.constant_only == 0
    for name in ("aten._to_copy", "aten.to", "aten.scalar_tensor", "aten.lift_fresh", "aten._local_scalar_dense"):
        assert ops.count[name] == 0, f"{name}: {ops.count[name]}"


def _forces(model, dtype=torch.float64):
    state = torch.tensor(STATE, dtype=dtype)
    inputs = torch.tensor(INPUTS, dtype=dtype)
    return model(state, inputs).total


def test_cached_view_follows_assign_load_and_dtype():
    model = MMG(load_ship("esso_osaka"))
    before = _forces(model)
    model.coefficients.assign({"Y_v": float(model.coefficients.Y_v) * 1.5})
    changed = _forces(model)
    assert not torch.equal(before, changed)
    fresh = MMG(load_ship("esso_osaka"))
    fresh.coefficients.assign({"Y_v": float(fresh.coefficients.Y_v) * 1.5})
    assert torch.equal(changed, _forces(fresh))       # same as computed from scratch
    fresh.load_state_dict(MMG(load_ship("esso_osaka")).state_dict())
    assert torch.equal(_forces(fresh), before)         # load_state_dict is seen
    # a float32 model on float64 states and the other way: the states' dtype wins
    m32 = MMG(load_ship("esso_osaka"), dtype=torch.float32)
    assert _forces(m32, torch.float64).dtype == torch.float64
    assert _forces(model, torch.float32).dtype == torch.float32
    assert _forces(m32.double()).dtype == torch.float64


def test_trainable_coefficients_keep_their_gradient_and_see_optimizer_steps():
    ship = load_ship("esso_osaka")
    model = MMG(ship, trainable=["Y_v", "N_r"], bounds={"Y_v": (-1.0, 0.0)})
    loss = _forces(model).square().sum()
    loss.backward()
    grads = [p.grad for p in model.parameters()]
    assert all(g is not None and torch.isfinite(g).all() and g.abs().sum() > 0 for g in grads)
    # the same gradient by central differences of the raw parameter of Y_v
    raw = model.coefficients.raw_Y_v
    h = 1e-6
    with torch.no_grad():
        raw += h
        up = _forces(model).square().sum()
        raw -= 2 * h
        down = _forces(model).square().sum()
        raw += h
    assert float(raw.grad) == pytest.approx(float((up - down) / (2 * h)), rel=1e-5)
    # an in-place step on a trainable coefficient is seen by the cached view (no_grad)
    with torch.no_grad():
        first = _forces(model)
        raw.add_(0.1)
        assert not torch.equal(first, _forces(model))


def test_functional_call_and_jacfwd_see_swapped_coefficients():
    model = MMG(load_ship("esso_osaka"))
    state, inputs = torch.tensor(STATE, dtype=torch.float64), torch.tensor(INPUTS, dtype=torch.float64)
    y_v = model.coefficients.Y_v.clone()

    def forces(value):
        return functional_call(model, {"coefficients.Y_v": value}, (state, inputs)).total

    with torch.no_grad():
        _forces(model)  # a cached view exists
        swapped = forces(y_v * 2.0)
        reference = MMG(load_ship("esso_osaka"))
        reference.coefficients.assign({"Y_v": float(y_v) * 2.0})
        assert torch.equal(swapped, reference(state, inputs).total)
        assert torch.equal(_forces(model), MMG(load_ship("esso_osaka"))(state, inputs).total)  # restored
    jac = jacfwd(forces)(y_v)
    h = 1e-7 * abs(float(y_v))
    fd = (forces(y_v + h) - forces(y_v - h)) / (2 * h)
    torch.testing.assert_close(jac, fd, rtol=1e-5, atol=1e-3)


def test_view_of_a_coefficients_module_matches_its_attributes():
    coefficients = Coefficients(load_ship("esso_osaka"))
    view = coefficients.values_view()
    for name in coefficients.names:
        assert float(getattr(view, name)) == float(getattr(coefficients, name))
    assert float(view.q) == float(0.5 * coefficients.rho * coefficients.L_pp * coefficients.d)


def _made_anew(self, dtype):
    """The values view made anew on every call (no kept parts): the reference."""
    from sysid.mmg.coefficients import coefficient_view
    return coefficient_view({name: getattr(self, name) for name in self.names}, dtype)


def _identification_steps(model, dtype, assign_between=None):
    """Three Adam steps on the loss of a 5-step Euler rollout from two states (parameters
    carry gradient: the live values view), the losses and the raw parameters after each."""
    state = torch.tensor(STATE + [[0.0, 0.6, 0.0, -0.02, 0.1, -0.004]], dtype=dtype)
    inputs = torch.tensor(INPUTS + [[8.0, -0.2, 5.0, 2.5]], dtype=dtype)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    out = []
    for step in range(3):
        x = state
        for _ in range(5):
            x = x + 0.1 * derivative(model, x, inputs)
        loss = (x - state).square().sum()
        optimizer.zero_grad()
        loss.backward()
        out.append((loss.detach().clone(), [p.grad.clone() for p in model.parameters()]))
        optimizer.step()
        if assign_between is not None and step == 0:
            model.coefficients.assign(assign_between)
    return out + [[p.detach().clone() for p in model.parameters()]]


@pytest.mark.parametrize("trainable", [("X_vr", "Y_v", "Y_r", "N_v", "N_r"), ("Y_v", "t_P")])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_identification_steps_equal_views_made_anew_to_the_bit(trainable, dtype, monkeypatch):
    # the live view keeps the constants (and the derived constants of a trainable t_P are
    # made anew); an assigned constant (the mass) after the first step is seen
    bounds = {"Y_v": (-1.0, 0.0)}
    kept = _identification_steps(MMG(load_ship("esso_osaka"), trainable, bounds), dtype, {"m": 3.0e5})
    monkeypatch.setattr(Coefficients, "_live_view", _made_anew)
    anew = _identification_steps(MMG(load_ship("esso_osaka"), trainable, bounds), dtype, {"m": 3.0e5})
    for (loss_k, grads_k), (loss_a, grads_a) in zip(kept[:-1], anew[:-1]):
        assert torch.equal(loss_k, loss_a)
        assert all(torch.equal(g, h) for g, h in zip(grads_k, grads_a))
    assert all(torch.equal(p, q) for p, q in zip(kept[-1], anew[-1]))
    assert not torch.equal(kept[0][0], kept[1][0])  # the steps moved the coefficients


def test_the_live_view_sees_a_frozen_trainable_coefficient_change(monkeypatch):
    # t_P trainable but without gradient: its derived constants (1 - t_P ...) are kept while
    # Y_v is identified, and made anew when t_P changes in place
    model = MMG(load_ship("esso_osaka"), ("Y_v", "t_P"), {"Y_v": (-1.0, 0.0)})
    model.coefficients.raw_t_P.requires_grad_(False)
    first = _forces(model)
    with torch.no_grad():
        model.coefficients.raw_t_P.mul_(0.5)
    second = _forces(model)
    assert not torch.equal(first, second)
    monkeypatch.setattr(Coefficients, "_live_view", _made_anew)
    assert torch.equal(second, _forces(model))
