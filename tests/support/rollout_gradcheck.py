"""gradcheck of a training right-hand side's calls as a rollout takes them: several calls
sharing one plan (`sysid.hybrid.fused_rate`'s), each call's parameter gradients summed by
autograd, and a last call whose outputs reach nothing."""
from __future__ import annotations

import torch


def rollout_case(states: torch.Tensor, inputs: torch.Tensor, members: int) -> tuple[torch.Tensor, list]:
    """(start state (rows, 6), or (K, rows / K, 6) with K = `members` > 1, requiring gradient;
    the four calls' inputs of that shape) from windows' states (T + 1, N, 6) and inputs
    (T + 1, N, 4), float64: 15 windows of the first 60, every 4th."""
    state = states[3, :60:4].reshape(members, -1, 6) if members > 1 else states[3, :60:4]
    state = state.clone().requires_grad_(True)
    return state, [inputs[1 + k, :60:4].reshape(state.shape[:-1] + (4,)) for k in range(4)]


def gradcheck_of_a_rollout(rate, plan_of, state: torch.Tensor, inputs: list, parameters: list,
                           forces: int) -> bool:
    """gradcheck (float64) of three Euler steps x + 0.5 dx/dt through ``rate(x, u, plan) ->
    (dx/dt, force, ...)`` with one plan ``plan_of(state, parameters)`` shared by every call, and
    a fourth call whose outputs reach nothing, with respect to the start state and `parameters`;
    the first `forces` forces of each call are outputs too."""

    def rollout(state, *parameters):
        plan = plan_of(state, parameters)
        x, outputs = state, []
        for u in inputs[:3]:
            dx, *calls = rate(x, u, plan)
            outputs += calls[:forces]
            x = x + 0.5 * dx
        rate(x, inputs[3], plan)  # reaches no output
        return x, *outputs
    return torch.autograd.gradcheck(rollout, (state, *parameters))
