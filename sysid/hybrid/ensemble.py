"""The mean-of-seeds ensemble: N models of one experiment trained with different seeds,
their forces averaged.

For the hybrid, whose MMG is the same in every member, this is F_MMG + (1/N) sum_k g_k F_NN,k:
the average of the N networks' (gated) corrections. Members with identified MMG
coefficients average their whole forces, component by component.
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import torch
from torch import nn

from sysid.config.choices import GateSpace
from sysid.hybrid.correction import correction_inputs
from sysid.hybrid.force_models import _EOM_ROWS, CorrectedModel
from sysid.mmg import native
from sysid.mmg.coefficient_lookup import coefficient_matrix
from sysid.mmg.model import ForceBreakdown
from sysid.mmg.vjp import force_rate, rate_of_force
from sysid.mmg.wind import relative_wind


class _Members(nn.Module):
    """Models of one structure (``members``): the first one's mass terms and kind."""

    members: nn.ModuleList

    @property
    def coefficients(self):
        return self.members[0].coefficients

    @property
    def kind(self) -> str:
        return getattr(self.members[0], "kind", "mmg")

    def eager_rate(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None] | None:
        """(dx/dt (..., 6), the gate's decision (...,) or None) at state (..., 6) with inputs
        (..., 4) without gradient where `no_grad_rate` applies, else None (then `forward` and
        the equations of motion, which this equals to round-off)."""
        if torch.is_grad_enabled():
            return None
        # looked up once while the members, their gates and parameters stay as they are (a rollout's steps)
        key = (state.dtype, tuple(id(m.__dict__.get("_modules", {}).get("gate")) for m in self.members),
               tuple((id(t), t._version) for t in (*self.parameters(), *self.buffers())))
        found = self.__dict__.get("_eager_rate")
        if found is None or found[0] != key:
            found = self.__dict__["_eager_rate"] = (key, self.no_grad_rate(state))
        rate = found[1]
        return rate(state, inputs) if rate is not None else None

    def no_grad_rate(self, like: torch.Tensor):
        """A function (state, inputs) -> (dx/dt, the gate's decision or None) without gradient,
        or None where there is none (each kind of members says how)."""
        raise NotImplementedError

    def _own_rates(self, like: torch.Tensor) -> list | None:
        """The members' own `no_grad_rate`s in `like`'s dtype; None unless every member is a
        `CorrectedModel` whose own one applies and the members share the mass terms
        (`_common_mass`)."""
        rates = [m.no_grad_rate(like) if isinstance(m, CorrectedModel) else None for m in self.members]
        if any(r is None for r in rates) or not _common_mass(self.members, like):
            return None
        return rates


class SeedEnsemble(_Members):
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
        decision (...,) or None) without gradient (the eager steps of maneuvers and
        predictions): dx/dt of `forward`'s mean force, to round-off. The K members' FNNs run
        side by side as one batched product on the member axis (`_members_rate`) where every
        member is one network of one shape; else the mean of the members' own
        `no_grad_rate`s. dx/dt is affine in the force, so either is the rate of the mean
        force where the members share the mass terms of the equations of motion (hybrids of
        one MMG, or of MMGs whose identified hull coefficients differ; NN-only); the gate
        on where at least half of the members apply their correction, as `forward`. None
        unless every member's own `no_grad_rate` applies and they share the mass terms."""
        rates = self._own_rates(like)
        if rates is None:
            return None
        batched = _members_rate(self.members, like, self._shared_mmg)
        if batched is not None:
            return batched

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
    ship = dataclasses.replace(first.ship, source="")   # one ship, wherever each member read it (its run's copy)
    for m in members[1:]:
        mine = m.mmg.state_dict()
        if (dataclasses.replace(m.mmg.ship, source="") != ship or m.mmg.quadrature != first.quadrature
                or mine.keys() != reference.keys()
                or any(not torch.equal(mine[k], reference[k]) for k in reference)):
            return False
    return True


def _common_mass(members: Sequence[nn.Module], like: torch.Tensor) -> bool:
    """True when every member's equations of motion have the same matrix (the mass terms,
    `sysid.mmg.vjp.RATE_ROWS`) in `like`'s dtype: dx/dt is then affine in the force with
    one slope, and the mean of the members' rates is the rate of their mean force."""
    with torch.no_grad():
        first, *rest = (coefficient_matrix(m.coefficients.values_view(like.dtype), _EOM_ROWS, like) for m in members)
        return all(torch.equal(first, other) for other in rest)



def _members_rate(members: Sequence[nn.Module], like: torch.Tensor, shared_mmg: bool, side_by_side: bool = False):
    """`SeedEnsemble.no_grad_rate` with the K members' FNNs side by side: each step the MMG's
    rate and the FNN's inputs s from one native call (hybrids of one MMG; of MMGs with their
    own identified coefficients, one call each, their rates averaged), s standardised by
    each member's statistics (K, B, 9), the K networks as batched products on the member
    axis (`torch.baddbmm`), each member's kNN gate on its own features (its gate as the
    member holds it: the rollout's), the gated forces averaged over the members and added
    through the shared mass terms. None where it does not apply: a member with several
    networks, networks of different shapes or dtypes, gates of different spaces.

    `side_by_side` (`MembersSideBySide`): the rows are K + 1 blocks of B rows, block k
    member k's own (its own F_NN, MMG and gate decision), the last the ensemble's (as
    above); each member's network and gate take its own block and the ensemble's as one
    batch of 2 B rows."""
    first = members[0]
    nets = [m.correction_net for m in members]
    if (any(n.members != 1 for n in nets) or len({tuple(w.shape for w in n.weights) for n in nets}) != 1
            or len({(m.physics, m.gate_space) for m in members}) != 1
            or len({n.input_mean.dtype for n in nets}) != 1):
        return None
    physics, inputs_space = first.physics, first.gate_space is GateSpace.INPUTS
    with torch.no_grad():
        weights = [torch.stack([n.weights[i][0] for n in nets]) for i in range(len(first.correction_net.weights))]
        biases = [torch.stack([n.biases[i][0] for n in nets]).unsqueeze(1) for i in range(len(weights))]
        mean = torch.stack([n.input_mean for n in nets]).unsqueeze(1)  # (K, 1, 9)
        std = torch.stack([n.input_std for n in nets]).unsqueeze(1)
        scale = torch.stack([n.output_std for n in nets]).unsqueeze(1)  # (K, 1, 3)
        shift = torch.stack([n.output_mean for n in nets]).unsqueeze(1)
        coefficients = [m.mmg.coefficients.values_view(like.dtype) for m in (members[:1] if shared_mmg else members)]
        families = native.families_of(first.mmg) if physics else None
        mass = force_rate(coefficients[0], like)  # (3, 6), the members' (`_common_mass`)
    gates = [m.gate if m.gate is not None and m.gate_enabled and m.gate.bank.shape[0] > 0 else None
             for m in members]
    gated = all(g is not None for g in gates)
    if not gated and any(g is not None for g in gates):
        return None
    dtype = mean.dtype

    def rate(state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        k = len(members)
        flat_state, flat_inputs = state.reshape(-1, 6), inputs.reshape(-1, 4)
        if physics:
            outs = [native.rate(flat_state, flat_inputs, c, families) for c in coefficients]
            s = outs[0][:, 9:]
            if len(outs) == 1:
                rate_mmg = outs[0][:, :6]
            elif side_by_side:  # member j's MMG on its block; the ensemble's: the mean of theirs
                b = flat_state.shape[0] // (k + 1)
                rate_mmg = torch.cat([o[j * b:(j + 1) * b, :6] for j, o in enumerate(outs)]
                                     + [torch.stack([o[k * b:, :6] for o in outs]).mean(0)])
            else:
                rate_mmg = torch.stack([o[:, :6] for o in outs]).mean(0)
        else:  # NN-only: s through torch, dx/dt of F_NN alone
            wind = relative_wind(flat_state[:, 1], flat_state[:, 3], flat_state[:, 4], flat_inputs[:, 2],
                                 flat_inputs[:, 3])
            s = correction_inputs(flat_state, flat_inputs, torch.stack(wind, -1))
        s = s.to(dtype)
        if side_by_side:  # (K, 2B, 9): member j's own block, then the ensemble's
            blocks = s.view(k + 1, -1, s.shape[-1])
            rows = torch.cat((blocks[:k], blocks[k:].expand(k, -1, -1)), 1)
        else:
            rows = s.unsqueeze(0)
        z = (rows - mean) / std  # (K, rows, 9)
        h = z
        for w, b in zip(weights[:-1], biases[:-1]):
            h = torch.tanh(torch.baddbmm(b, h, w))
        f = torch.baddbmm(biases[-1], h, weights[-1]) * scale + shift  # (K, rows, 3)
        decisions = None
        if gated:
            decisions = torch.stack([g(z[i] if inputs_space else h[i])[1] for i, g in enumerate(gates)])  # (K, rows)
            f = torch.where(decisions[..., None], f, torch.zeros_like(f))
        if side_by_side:
            b = f.shape[1] // 2
            force = torch.cat((f[:, :b].reshape(-1, 3), f[:, b:].mean(0))).to(state.dtype)  # (R, 3)
            on = None if decisions is None else torch.cat(
                (decisions[:, :b].reshape(-1), decisions[:, b:].to(state.dtype).mean(0) >= 0.5))
        else:
            force = f.mean(0).to(state.dtype)  # (B, 3)
            on = None if decisions is None else decisions.to(state.dtype).mean(0) >= 0.5
        on = None if on is None else on.view(state.shape[:-1])
        if not physics:
            return rate_of_force(flat_state, force, coefficients[0]).view(state.shape), on
        return torch.addmm(rate_mmg, force, mass).view(state.shape), on
    return rate


class MembersSideBySide(_Members):
    """K members of a `SeedEnsemble` and the ensemble itself predicting side by side, one
    batched rollout for all of them (no gradient): a batch of R = (K + 1) B rows is K + 1
    blocks of B rows, block k driven by member k alone (its own forces, gate and MMG), the
    last block by the ensemble's mean force. Rows do not interact, so each block equals
    its model's own rollout to round-off (`no_grad_rate`); only the eager no-grad steps
    (`eager_rate`, ``no_grad_rate``) are defined, None where the ensemble's batched rate
    does not apply."""

    def __init__(self, ensemble: SeedEnsemble):
        super().__init__()
        self.members = ensemble.members
        self._shared_mmg = ensemble._shared_mmg

    @property
    def mmg(self):
        return self.members[0].mmg

    def no_grad_rate(self, like: torch.Tensor):
        """As `SeedEnsemble.no_grad_rate`, block by block (the class docstring); None where
        the batched rate does not apply or the rows are not K + 1 equal blocks."""
        rows = like.reshape(-1, like.shape[-1]).shape[0]
        if rows % (len(self.members) + 1):
            return None
        if self._own_rates(like) is None:
            return None
        return _members_rate(self.members, like, self._shared_mmg, side_by_side=True)

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        raise NotImplementedError("members side by side step without gradient only (eager_rate)")
