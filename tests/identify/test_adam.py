"""The training loop's Adam and plateau schedule against torch.optim's, to the bit, and
their checkpoint layouts in both directions."""
from __future__ import annotations

import pytest
import torch

from sysid.errors import CheckpointError
from sysid.identify.adam import Adam
from sysid.identify.plateau import Plateau


def _parameters(seed: int) -> list[torch.nn.Parameter]:
    """An FNN's shapes in float32 and two MMG-like coefficients in float64."""
    gen = torch.Generator().manual_seed(seed)
    shapes = [((2, 9, 16), torch.float32), ((2, 16, 3), torch.float32), ((2, 1, 16), torch.float32),
              ((2, 1, 3), torch.float32), ((), torch.float64), ((4,), torch.float64)]
    return [torch.nn.Parameter(torch.randn(shape, generator=gen, dtype=torch.float64).to(dtype))
            for shape, dtype in shapes]


def _gradients(params, gen: torch.Generator, skip: int | None = None) -> None:
    """Gradients of very different scales (1e-7 to 10); parameter `skip` gets none."""
    for i, p in enumerate(params):
        scale = 10.0 ** float(torch.randint(-7, 2, (), generator=gen))
        p.grad = None if i == skip else (torch.randn(p.shape, generator=gen, dtype=torch.float64) * scale).to(p.dtype)


def _steps(ours, theirs, ours_params, their_params, gen_seed: int, steps: int) -> None:
    gen = torch.Generator().manual_seed(gen_seed)
    for n in range(steps):
        _gradients(ours_params, gen, skip=5 if n < 2 else None)  # one parameter joins late
        for p, q in zip(ours_params, their_params):
            q.grad = None if p.grad is None else p.grad.clone()
        ours.step()
        theirs.step()


def test_adam_is_torch_adam_to_the_bit():
    ours_params, their_params = _parameters(0), _parameters(0)
    ours = Adam(ours_params, 3e-3)
    theirs = torch.optim.Adam(their_params, lr=3e-3, foreach=True)
    _steps(ours, theirs, ours_params, their_params, 1, 12)
    ours.param_groups[0]["lr"] = theirs.param_groups[0]["lr"] = 1e-3  # a schedule's change
    _steps(ours, theirs, ours_params, their_params, 2, 5)
    for p, q in zip(ours_params, their_params):
        assert torch.equal(p.detach(), q.detach())
    assert not torch.equal(ours_params[0].detach(), _parameters(0)[0].detach())
    for p, q in zip(ours_params, their_params):
        mine, torch_state = ours.state[p], theirs.state[q]
        assert float(mine["step"]) == float(torch_state["step"]) == (17.0 if p is not ours_params[5] else 13.0)  # 2 + 2 steps without a gradient
        assert torch.equal(mine["exp_avg"], torch_state["exp_avg"])
        assert torch.equal(mine["exp_avg_sq"], torch_state["exp_avg_sq"])
    ours.zero_grad()
    assert all(p.grad is None for p in ours_params)


def test_adam_of_one_tensor_is_torch_adam_to_the_bit():
    """One flat float32 parameter (as the warm start's), gradients from 1e-7 to 10, a change
    of the learning rate: parameter and moments equal torch's multi-tensor Adam's."""
    gen = torch.Generator().manual_seed(5)
    ours_p = torch.nn.Parameter(torch.randn(18179, generator=gen))
    their_p = torch.nn.Parameter(ours_p.detach().clone())
    ours, theirs = Adam([ours_p], 3e-3), torch.optim.Adam([their_p], lr=3e-3, foreach=True)
    for n in range(20):
        if n == 12:
            ours.param_groups[0]["lr"] = theirs.param_groups[0]["lr"] = 1e-3
        scale = 10.0 ** float(torch.randint(-7, 2, (), generator=gen))
        ours_p.grad = torch.randn(18179, generator=gen) * scale
        their_p.grad = ours_p.grad.clone()
        ours.step()
        theirs.step()
    assert torch.equal(ours_p.detach(), their_p.detach())
    assert not torch.equal(ours_p.detach(), torch.randn(18179, generator=torch.Generator().manual_seed(5)))
    mine, torch_state = ours.state[ours_p], theirs.state[their_p]
    assert float(mine["step"]) == float(torch_state["step"]) == 20.0
    assert torch.equal(mine["exp_avg"], torch_state["exp_avg"])
    assert torch.equal(mine["exp_avg_sq"], torch_state["exp_avg_sq"])


@pytest.mark.parametrize("direction", ["torch to ours", "ours to torch"])
def test_adam_resumes_from_the_other_ones_state_dict(tmp_path, direction):
    """A checkpoint (torch.save, weights_only load) of one continues with the other to the
    same numbers as an uninterrupted torch Adam."""
    reference_params, first_params = _parameters(3), _parameters(3)
    reference = torch.optim.Adam(reference_params, lr=2e-3, foreach=True)
    first = (torch.optim.Adam(first_params, lr=2e-3, foreach=True) if direction == "torch to ours"
             else Adam(first_params, 2e-3))
    _steps(first, reference, first_params, reference_params, 4, 6)
    torch.save({"optimizer": first.state_dict(), "model": [p.detach() for p in first_params]}, tmp_path / "c.pt")
    saved = torch.load(tmp_path / "c.pt", weights_only=True)
    second_params = [torch.nn.Parameter(p.clone()) for p in saved["model"]]
    second = Adam(second_params, 1.0) if direction == "torch to ours" else \
        torch.optim.Adam(second_params, lr=1.0, foreach=True)
    second.load_state_dict(saved["optimizer"])
    assert second.param_groups[0]["lr"] == 2e-3
    _steps(second, reference, second_params, reference_params, 5, 6)
    for p, q in zip(second_params, reference_params):
        assert torch.equal(p.detach(), q.detach())


def test_adam_refuses_another_optimizers_state():
    params = _parameters(0)
    other = torch.optim.Adam(params[:3], lr=1e-3).state_dict()
    with pytest.raises(CheckpointError, match="not one Adam group of 6 parameters"):
        Adam(params, 1e-3).load_state_dict(other)
    decayed = torch.optim.Adam(params, lr=1e-3, weight_decay=0.1).state_dict()
    with pytest.raises(CheckpointError, match="weight_decay = 0.1"):
        Adam(params, 1e-3).load_state_dict(decayed)


def test_plateau_is_torch_reduce_lr_on_plateau():
    ours_params, their_params = _parameters(0), _parameters(0)
    ours_opt, their_opt = Adam(ours_params, 3e-3), torch.optim.Adam(their_params, lr=3e-3)
    ours = Plateau(ours_opt, 0.5, 2)
    theirs = torch.optim.lr_scheduler.ReduceLROnPlateau(their_opt, factor=0.5, patience=2)
    # falls, a tie within the relative threshold (not better), plateaus, falls again
    losses = [1.0, 0.9, 0.89995, 0.95, 0.92, 0.91, 0.5, 0.6, 0.6, 0.6, 0.6, 0.6, 0.6, 0.6]
    rates = []
    for n, loss in enumerate(losses):
        ours.step(loss)
        theirs.step(loss)
        rates.append(ours_opt.param_groups[0]["lr"])
        assert ours_opt.param_groups[0]["lr"] == their_opt.param_groups[0]["lr"], n
        assert (ours.best, ours.num_bad_epochs) == (theirs.best, theirs.num_bad_epochs), n
    # the third bad epoch in a row (patience 2) halves the rate: at 0.92, the 3rd and 6th 0.6
    assert rates == [3e-3] * 4 + [1.5e-3] * 5 + [7.5e-4] * 3 + [3.75e-4] * 2
    # each resumes from the other's state
    resumed = Plateau(ours_opt, 0.5, 2)
    resumed.load_state_dict(theirs.state_dict())
    back = torch.optim.lr_scheduler.ReduceLROnPlateau(their_opt, factor=0.5, patience=2)
    back.load_state_dict(ours.state_dict())
    for loss in (0.6, 0.4, 0.45):
        resumed.step(loss)
        back.step(loss)
        assert (resumed.best, resumed.num_bad_epochs, resumed.last_epoch) == \
            (back.best, back.num_bad_epochs, back.last_epoch)
