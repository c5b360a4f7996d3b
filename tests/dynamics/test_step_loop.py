"""The one step loop (`step_loop`, `run_steps`, `rollout`), its chunking driver
(`run_in_chunks`) and the closed loop on top of them, against the loops they replaced,
written out here as they were: the same states bit for bit."""
import math

import pytest
import torch

from sysid import MMG, load_ship
from sysid.config.choices import Method
from sysid.dynamics.equations import lean_derivative
from sysid.dynamics.integrators import STEP_RULES, rollout, run_in_chunks, run_steps, step_loop
from sysid.fast.stepper import Step
from sysid.maneuvers import Conditions, TurningCircle, ZigZag
from sysid.maneuvers.closed_loop import RECORD, ClosedLoopStep, run_eager
from sysid.maneuvers.simulate import _start


@pytest.fixture(scope="module")
def case():
    """The Esso Osaka MMG, 5 ships at 0.3-0.35 m/s and 10 steps of random revolutions and
    rudder."""
    g = torch.Generator().manual_seed(1)
    x0 = torch.zeros(5, 6, dtype=torch.float64)
    x0[:, 1] = 0.3 + 0.05 * torch.rand(5, generator=g, dtype=torch.float64)
    inputs = torch.zeros(11, 5, 4, dtype=torch.float64)
    inputs[..., 0] = 8.0 + torch.rand(11, 5, generator=g, dtype=torch.float64)
    inputs[..., 1] = 0.3 * torch.randn(11, 5, generator=g, dtype=torch.float64)
    return MMG(load_ship("esso_osaka")), x0, inputs


def _classical_rk4(f, x, dt):  # the textbook rule, written out
    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + (k1 + 2.0 * (k2 + k3) + k4) * (dt / 6.0)


@pytest.mark.parametrize("method", [Method.EULER, Method.RK4, Method.RK4_38])
def test_rollout_is_the_plain_step_loop(case, method):
    """`rollout` equals the loop it replaced (a list of states, one rule step each) bit for
    bit; with classical RK4 also the textbook rule written out here."""
    model, x0, inputs = case
    rule = STEP_RULES[method]

    def rhs(x, u):
        return lean_derivative(model, x, u)
    with torch.no_grad():
        ours = rollout(rhs, x0, inputs, 0.5, method)
        states = [x0]
        for k in range(inputs.shape[0] - 1):
            u = inputs[k]
            states.append(rule(lambda x: rhs(x, u), states[-1], 0.5))  # noqa: B023
        assert torch.equal(ours, torch.stack(states))
        if method == Method.RK4:
            x = x0
            for k in range(3):
                x = _classical_rk4(lambda y: rhs(y, inputs[k]), x, 0.5)  # noqa: B023
            assert torch.equal(ours[3], x)
    assert ours.shape == (11, 5, 6) and torch.isfinite(ours).all()


def test_chunks_of_a_loop_are_the_whole_loop(case):
    """`run_in_chunks` of eager step loops of 4 steps (the last call 2) equals one
    `run_steps` over all 10 bit for bit; no steps: the head alone."""
    model, x0, inputs = case
    step = Step(model, Method.RK4, 0.5)
    calls = []

    def call(x, done, n):
        calls.append(n)
        states = run_steps(step, x, inputs[done:done + n + 1])[1:]
        return states, states[-1]
    with torch.no_grad():
        whole = run_steps(step, x0, inputs)
        chunked = run_in_chunks(call, x0, 10, 4, head=x0[None])
    assert calls == [4, 4, 2]
    assert torch.equal(chunked, whole)
    assert torch.equal(run_in_chunks(call, x0, 0, 4, head=x0[None]), x0[None])


def test_the_closed_loop_is_the_loop_it_replaced():
    """`run_eager` (the closed loop through `step_loop`) equals the preallocated loop it
    replaced bit for bit: a 35 deg turning circle and a 20/20 zig-zag, 30 RK4 steps."""
    model = MMG(load_ship("esso_osaka"))
    maneuvers = [TurningCircle(35.0), ZigZag(20.0, 20.0)]
    conditions = Conditions(0.35, 8.85, 24.1, 0.1, 3.0)
    x0, orders0, parameters = _start(maneuvers, conditions)
    ours = run_eager(model, x0, orders0, parameters, conditions.steps, conditions.dt, conditions.method)
    step = ClosedLoopStep(model, conditions.method)
    dt = torch.tensor(conditions.dt, dtype=x0.dtype)
    out = torch.empty((conditions.steps, 2, RECORD), dtype=x0.dtype)
    x, o = x0, orders0
    with torch.no_grad():
        for k in range(conditions.steps):
            x, o, u, g = step(x, o, parameters, dt * k, dt)
            out[k] = torch.cat((x, o, u, g), -1)
    assert torch.equal(ours[..., :12], out[..., :12]) and torch.isnan(ours[..., 12]).all()  # no gate: NaN
    assert ours[-1, 0, 5] > 0 and abs(ours[-1, 0, 9]) == pytest.approx(math.radians(35.0))  # 35 deg rudder held: turning


def test_step_loop_hands_each_step_the_carry_of_the_one_before():
    """`step_loop`: rows k = 0 .. steps-1 of advance(k, carry), the carry passed on."""
    rows = step_loop(lambda k, c: (torch.tensor([k, c]), c + k), 10, 4)
    assert [r.tolist() for r in rows] == [[0, 10], [1, 10], [2, 11], [3, 13]]
