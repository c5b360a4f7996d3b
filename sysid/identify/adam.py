"""Adam (Kingma and Ba 2015), the training loop's optimizer: torch.optim.Adam's algorithm
with its defaults (betas 0.9, 0.999, eps 1e-8, no weight decay, no amsgrad) in its
multi-tensor operations, so the same numbers to the last bit, without the ``torch.optim``
machinery (whose first step imports ``torch._dynamo``, about a second per process).

The interface is the part of torch's Adam that training uses: ``step``, ``zero_grad``,
``param_groups`` (one group; a schedule changes its ``"lr"``), ``state`` (per parameter:
``"step"``, a float32 tensor, ``"exp_avg"``, ``"exp_avg_sq"``), ``state_dict`` and
``load_state_dict`` in torch's layout, so a checkpoint written with either resumes with
the other.
"""
from __future__ import annotations

from typing import Any, Iterable

import torch

from sysid.errors import CheckpointError


class Adam:
    """Adam on `params` with learning rate `lr`: m <- beta1 m + (1 - beta1) g,
    v <- beta2 v + (1 - beta2) g^2, theta <- theta - lr / (1 - beta1^t) m /
    (sqrt(v) / sqrt(1 - beta2^t) + eps). Parameters without a gradient are left alone.
    """

    betas = (0.9, 0.999)
    eps = 1e-8

    def __init__(self, params: Iterable[torch.Tensor], lr: float):
        self.params = list(params)
        if not self.params:
            raise ValueError("Adam: no parameters to optimize")
        self.param_groups: list[dict[str, Any]] = [{"params": self.params, "lr": float(lr), "betas": self.betas, "eps": self.eps,
                              "weight_decay": 0, "amsgrad": False, "maximize": False, "foreach": True,
                              "capturable": False, "differentiable": False, "fused": None,
                              "decoupled_weight_decay": False}]
        self.state: dict[torch.Tensor, dict[str, torch.Tensor]] = {}
        self._one = torch.tensor(1.0)

    def zero_grad(self) -> None:
        """Every parameter's gradient to None (torch's ``set_to_none``)."""
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter that has a gradient (torch's ``_multi_tensor_adam``
        without weight decay, amsgrad, maximize or capturable: the same operations)."""
        group = self.param_groups[0]
        lr, (beta1, beta2), eps = group["lr"], group["betas"], group["eps"]
        params = [p for p in self.params if p.grad is not None]
        if not params:
            return
        if len(params) == 1 and params[0].device.type == "cpu":  # one tensor (the warm start's flat vector)
            self._step_one(params[0], lr, beta1, beta2, eps)
            return
        grads, exp_avgs, exp_avg_sqs, steps = [], [], [], []
        for p in params:
            state = self._state_of(p)
            grads.append(p.grad)
            exp_avgs.append(state["exp_avg"])
            exp_avg_sqs.append(state["exp_avg_sq"])
            steps.append(state["step"])
        torch._foreach_add_(steps, self._one, alpha=1.0)
        torch._foreach_lerp_(exp_avgs, grads, 1 - beta1)
        torch._foreach_mul_(exp_avg_sqs, beta2)
        torch._foreach_addcmul_(exp_avg_sqs, grads, grads, 1 - beta2)
        step_size = [(lr / (1 - beta1 ** s.item())) * -1 for s in steps]
        bias_correction2_sqrt = [(1 - beta2 ** s.item()) ** 0.5 for s in steps]
        denominator = torch._foreach_sqrt(exp_avg_sqs)
        torch._foreach_div_(denominator, bias_correction2_sqrt)
        torch._foreach_add_(denominator, eps)
        torch._foreach_addcdiv_(params, exp_avgs, denominator, step_size)

    def _state_of(self, p: torch.Tensor) -> dict[str, torch.Tensor]:
        state = self.state.get(p)
        if state is None:
            state = self.state[p] = {"step": torch.tensor(0.0),
                                     "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                                     "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format)}
        return state

    def _step_one(self, p: torch.Tensor, lr: float, beta1: float, beta2: float, eps: float) -> None:
        """`step` of one parameter: each multi-tensor operation as its one-tensor operation
        (what torch's multi-tensor kernels run per tensor on the CPU), the same numbers."""
        state, grad = self._state_of(p), p.grad
        step, exp_avg, exp_avg_sq = state["step"], state["exp_avg"], state["exp_avg_sq"]
        step.add_(self._one, alpha=1.0)
        exp_avg.lerp_(grad, 1 - beta1)
        exp_avg_sq.mul_(beta2)
        exp_avg_sq.addcmul_(grad, grad, value=1 - beta2)
        t = step.item()
        denominator = torch.sqrt(exp_avg_sq)
        denominator.div_((1 - beta2 ** t) ** 0.5)
        denominator.add_(eps)
        p.addcdiv_(exp_avg, denominator, value=(lr / (1 - beta1 ** t)) * -1)

    def state_dict(self) -> dict:
        """torch.optim.Adam's layout: ``state`` by parameter index, ``param_groups``."""
        group = {k: v for k, v in self.param_groups[0].items() if k != "params"}
        group["params"] = list(range(len(self.params)))
        return {"state": {i: dict(self.state[p]) for i, p in enumerate(self.params) if p in self.state},
                "param_groups": [group]}

    def load_state_dict(self, state_dict: dict) -> None:
        """The state `state_dict` (this class's or torch.optim.Adam's, one group of as many
        parameters with the same options); a `CheckpointError` line otherwise."""
        groups = state_dict.get("param_groups")
        if not isinstance(groups, list) or len(groups) != 1 or len(groups[0].get("params", ())) != len(self.params):
            raise CheckpointError("training checkpoint: its optimizer state is not one Adam group of "
                                  f"{len(self.params)} parameters; delete it to start afresh")
        group = groups[0]
        for key in ("weight_decay", "amsgrad", "maximize"):
            if group.get(key, self.param_groups[0][key]) != self.param_groups[0][key]:
                raise CheckpointError(f"training checkpoint: its Adam has {key} = {group[key]!r}, not "
                                      f"{self.param_groups[0][key]!r}; delete it to start afresh")
        self.param_groups[0]["lr"] = float(group["lr"])
        self.param_groups[0]["betas"] = tuple(float(b) for b in group.get("betas", self.betas))
        self.param_groups[0]["eps"] = float(group.get("eps", self.eps))
        self.state = {}
        for index, p in zip(group["params"], self.params):
            saved = state_dict["state"].get(index)
            if saved is None:
                continue
            self.state[p] = {"step": saved["step"].detach().to(torch.float32, copy=True).cpu(),
                             "exp_avg": saved["exp_avg"].detach().to(p.dtype, copy=True).to(p.device),
                             "exp_avg_sq": saved["exp_avg_sq"].detach().to(p.dtype, copy=True).to(p.device)}
