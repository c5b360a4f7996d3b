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

from sysid.hybrid.force_models import CorrectedModel
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
        # hybrids of one MMG (coefficients not identified): F_MMG is computed once, not per member
        self._shared_mmg = _common_mmg(self.members)

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
        if self._shared_mmg:
            return self._shared_forward(state, inputs)
        parts = [m(state, inputs) for m in self.members]

        def mean(name: str) -> torch.Tensor:
            return torch.stack([getattr(p, name) for p in parts]).mean(0)

        forces = ForceBreakdown(mean("hull"), mean("propeller"), mean("rudder"), mean("wind"),
                                mean("correction"), parts[0].relative_wind)
        if all(p.gate_on is not None for p in parts):
            forces.ood_distance = mean("ood_distance")
            forces.gate_on = torch.stack([p.gate_on for p in parts]).to(state.dtype).mean(0) >= 0.5
        return forces

    def no_grad_rate(self, like: torch.Tensor):
        """A function (state (..., 6), inputs (..., 4)) -> (dx/dt (..., 6), the kNN gate's
        decision (...,) or None) without gradient (the closed-loop maneuvers' eager steps,
        `sysid.maneuvers.closed_loop.run_eager`): the mean of the members' own
        `no_grad_rate`s. dx/dt is affine in the force, with the mass terms of the one MMG
        the members share, so the mean of their rates is the rate of `forward`'s mean force,
        to round-off; the gate on where at least half of the members apply their correction,
        as `forward`. None unless the members are hybrids of one MMG whose every
        `no_grad_rate` applies (then the equations of motion over `forward`)."""
        if not self._shared_mmg:
            return None
        rates = [m.no_grad_rate(like) for m in self.members]
        if any(r is None for r in rates):
            return None

        def rate(state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
            parts = [r(state, inputs) for r in rates]
            dx = torch.stack([p[0] for p in parts]).mean(0)
            if any(p[1] is None for p in parts):
                return dx, None
            return dx, torch.stack([p[1] for p in parts]).to(state.dtype).mean(0) >= 0.5
        return rate

    def _shared_forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        """`forward` of hybrids that share their MMG: F_MMG once, the members' gated F_NN averaged."""
        forces = self.members[0].mmg(state, inputs)
        gated = [m._correction(state, inputs, forces.relative_wind) for m in self.members]
        forces.correction = torch.stack([g[0] for g in gated]).mean(0)
        if all(g[2] is not None for g in gated):
            forces.ood_distance = torch.stack([g[1] for g in gated]).mean(0)
            forces.gate_on = torch.stack([g[2] for g in gated]).to(state.dtype).mean(0) >= 0.5
        return forces


def _common_mmg(members: Sequence[nn.Module]) -> bool:
    """True when every member is a hybrid (`CorrectedModel` with physics) and their MMGs are
    one model: the same ship, quadrature and coefficient values."""
    if not all(isinstance(m, CorrectedModel) and m.physics for m in members):
        return False
    first = members[0].mmg
    reference = first.state_dict()
    for m in members[1:]:
        mine = m.mmg.state_dict()
        if (m.mmg.ship != first.ship or m.mmg.quadrature != first.quadrature or mine.keys() != reference.keys()
                or any(not torch.equal(mine[k], reference[k]) for k in reference)):
            return False
    return True
