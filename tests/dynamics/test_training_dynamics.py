"""The training rollout's right-hand side (`TrainingDynamics`) against the one it replaced,
written out here (every step's rate times dt), through torchdiffeq's Euler, and against Euler
written out, x_k+1 = x_k + 1 * (rate(x_k, u_k) dt): the same states and parameter gradients
bit for bit, where dt in the rate's dtype is 1 (the recorded grid's 0.99999999999998 s in
float32: the rate itself is returned, the product with 1 left out) and where it is not (0.5 s;
the grid's dt in float64)."""
import pytest
import torch

from sysid.dynamics.equations import TrainingDynamics, integrate_training

GRID_DT = 0.9999999999999787  # the recorded data's step [s] as the windows carry it


class _Rate:
    """A force model's ``training_rate`` stand-in: dx/dt (..., 6) = tanh(x A + u B + c), F_NN and
    F_MMG its first and last three channels; A, B, c the parameters."""

    def __init__(self, dtype):
        g = torch.Generator().manual_seed(3)
        self.A = (0.3 * torch.randn(6, 6, generator=g, dtype=dtype)).requires_grad_()
        self.B = (0.3 * torch.randn(4, 6, generator=g, dtype=dtype)).requires_grad_()
        self.c = torch.rand(6, generator=g, dtype=dtype).requires_grad_()

    def training_rate(self):
        def rate(state, inputs):
            out = torch.tanh(state @ self.A + inputs @ self.B + self.c)
            return out, out[..., :3], out[..., 3:]
        return rate

    def parameters(self):
        return [self.A, self.B, self.c]


class _WithProduct(TrainingDynamics):
    """`TrainingDynamics` as it was: every step's rate times dt (a 0-d tensor of its dtype)."""

    def forward(self, tau, state):
        k = min(max(int(tau), 0), self.inputs.shape[0] - 1)
        rate, f_nn, f_mmg = self.rate(state, self.inputs[k])
        self.f_nn.append(f_nn)
        self.f_mmg.append(f_mmg)
        return rate * torch.tensor(self.dt, dtype=rate.dtype)


def _with_product(model, x0, inputs, dt):
    from torchdiffeq import odeint
    tau = torch.arange(inputs.shape[0], dtype=x0.dtype)
    return odeint(_WithProduct(model.training_rate(), inputs, dt), x0, tau, method="euler")


def _written_out(model, x0, inputs, dt):
    rate = model.training_rate()
    dt_t = torch.tensor(dt, dtype=x0.dtype)
    one = torch.ones((), dtype=x0.dtype)  # torchdiffeq's step in step time
    states = [x0]
    for k in range(inputs.shape[0] - 1):
        states.append(states[-1] + one * (rate(states[-1], inputs[k])[0] * dt_t))
    return torch.stack(states)


@pytest.mark.parametrize("dtype,dt,product", [(torch.float32, GRID_DT, False), (torch.float32, 1.0, False),
                                              (torch.float32, 0.5, True), (torch.float64, GRID_DT, True)])
def test_a_training_rollout_equals_euler_written_out(dtype, dt, product):
    model = _Rate(dtype)
    g = torch.Generator().manual_seed(4)
    x0 = torch.randn(7, 6, generator=g, dtype=dtype)
    inputs = torch.randn(11, 7, 4, generator=g, dtype=dtype)
    weights = torch.randn(11, 7, 6, generator=g, dtype=dtype)
    results = []
    for roll in (integrate_training, _with_product):
        for p in model.parameters():
            p.grad = None
        states = roll(model, x0, inputs, dt)
        states = states[0] if isinstance(states, tuple) else states
        (states * weights).sum().backward()
        results.append((states.detach(), [p.grad.clone() for p in model.parameters()]))
    (got, got_grads), (expected, expected_grads) = results
    assert torch.equal(got, expected)
    assert all(torch.equal(a, b) for a, b in zip(got_grads, expected_grads))
    with torch.no_grad():
        assert torch.equal(got, _written_out(model, x0, inputs, dt))
    # the rate itself where dt is 1 in the rate's dtype, else the rate times dt
    rhs = TrainingDynamics(model.training_rate(), inputs, dt)
    out = rhs(torch.zeros((), dtype=dtype), x0)
    assert (type(out.grad_fn).__name__ == "MulBackward0") == product
