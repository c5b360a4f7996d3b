"""The mean-of-seeds ensemble: N models of one experiment trained with different seeds,
their forces averaged.

For the hybrid, whose MMG is the same in every member, this is F_MMG + (1/N) sum_k g_k F_NN,k:
the average of the N networks' (gated) corrections. Members with identified MMG
coefficients average their whole forces, component by component.
"""
from __future__ import annotations

from typing import Sequence

import torch
from torch import nn

from sysid.mmg.model import ForceBreakdown


class SeedEnsemble(nn.Module):
    """Forces [N, N, N m] averaged over `members` (trained models of one structure).

    ``ood_distance`` is the members' mean kNN distance; ``gate_on`` holds where at least half
    of the members apply their correction.
    """

    def __init__(self, members: Sequence[nn.Module]):
        super().__init__()
        if not members:
            raise ValueError("a seed ensemble needs at least one member")
        self.members = nn.ModuleList(members)

    @property
    def coefficients(self):
        return self.members[0].coefficients

    @property
    def kind(self) -> str:
        return getattr(self.members[0], "kind", "mmg")

    def gate_decision(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor | None:
        """(...,) True where at least half of the members apply their correction (as
        `forward`'s ``gate_on``); None unless every member has a gate."""
        decisions = [getattr(m, "gate_decision", lambda *a: None)(state, inputs) for m in self.members]
        if any(d is None for d in decisions):
            return None
        return torch.stack(decisions).to(state.dtype).mean(0) >= 0.5

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        parts = [m(state, inputs) for m in self.members]

        def mean(name: str) -> torch.Tensor:
            return torch.stack([getattr(p, name) for p in parts]).mean(0)

        forces = ForceBreakdown(mean("hull"), mean("propeller"), mean("rudder"), mean("wind"),
                                mean("correction"), parts[0].relative_wind)
        if all(p.gate_on is not None for p in parts):
            forces.ood_distance = mean("ood_distance")
            forces.gate_on = torch.stack([p.gate_on for p in parts]).to(state.dtype).mean(0) >= 0.5
        return forces
