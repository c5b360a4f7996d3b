"""The kNN gate's decision along one rollout, from the scan of an earlier step: what the
eager validation rollouts use.

A rollout step needs only the decision d_kNN(z) <= threshold of `KNNGate`, and successive
steps' features z move little. `RolloutGate` keeps, for every row, an anchor a (F,) where
the gate's own scan (`KNNGate.distance`) gave the distance D(a). d_kNN, a mean of order
statistics of Euclidean distances, moves by at most |z - a| (the triangle inequality), and
the scan's |q|^2 + |b|^2 - 2 q.b differs from the exact distance by at most
e(q) = sqrt(2 (F + 4) eps (|q|^2 + max |b|^2)) (the bound `sysid.fast.knn_index` uses), so

    D(z) <= D(a) + |z - a| + e(a) + e(z)   and   D(z) >= D(a) - |z - a| - e(a) - e(z).

A row is "on" where the first bound, plus a relative margin of 1e4 eps of the threshold,
is at or below the threshold, "off" where the second, less that margin, is above it: the
decision the scan would take. Where neither decides, the mean distance from z to the k
bank points nearest to a (k distinct points, so at least d_kNN(z); by differences, not
the scan's product), plus e(z) and the margin, at or below the threshold decides "on".
The other rows (and every row at the first step, or when the number of rows changes) are
scanned, and their features become their anchors. The decision is the gate's; the
distance returned is the scan's where a row was scanned, else the bound on the side
decided.

Along the 827 validation windows of 30 s of hybrid D2 (128 features, dt 1 s), the first
step scans every row and the later ones a few rows each.
"""
from __future__ import annotations

import copy

import torch
from torch import nn

from sysid.hybrid.knn_gate import KNNGate, nearest


class RolloutGate(nn.Module):
    """A fitted `KNNGate` for the eager steps of one rollout (a fresh one per rollout: it
    keeps each row's anchor between calls); ``forward(z (..., F))`` -> (distance (...,),
    in_distribution (...,)), the same decision as the gate's."""

    def __init__(self, gate: KNNGate):
        super().__init__()
        self.gate = gate
        eps = torch.finfo(gate.bank.dtype).eps
        self.margin = 1e4 * eps
        self.rounding = 2.0 * (gate.bank.shape[1] + 4) * eps
        self.bank_sq_max = float(gate.per_bank("bank_sq_max", lambda: (gate.bank * gate.bank).sum(1).max()))
        self.anchor: torch.Tensor | None = None  # (B, F) features where each row was scanned
        self.distance: torch.Tensor | None = None  # (B,) the scan's distance there
        self.slack: torch.Tensor | None = None  # (B,) its round-off bound e(anchor)
        self.neighbours: torch.Tensor | None = None  # (B, k) the bank rows nearest to the anchor

    @property
    def threshold(self) -> torch.Tensor:
        return self.gate.threshold

    @property
    def bank(self) -> torch.Tensor:
        return self.gate.bank

    def round_off(self, flat: torch.Tensor) -> torch.Tensor:
        """e(q) (B,): how far the scan's distance at features flat (B, F) can be from the exact one."""
        return (self.rounding * ((flat * flat).sum(1) + self.bank_sq_max)).sqrt()

    def _scan(self, flat: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`KNNGate.distance` of flat (B, F) (its chunks, its numbers) and the k nearest bank rows (B, k)."""
        gate = self.gate
        k, bank_sq = min(gate.k, gate.bank.shape[0]), gate._bank_sq()
        found = [nearest(flat[lo:lo + gate.chunk], gate.bank, bank_sq, k) for lo in range(0, flat.shape[0], gate.chunk)]
        return torch.cat([d.mean(1) for d, _ in found]), torch.cat([rows for _, rows in found])

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        shape = z.shape[:-1]
        flat = z.detach().reshape(-1, z.shape[-1]).to(self.gate.bank.dtype)
        threshold = self.gate.threshold
        if self.anchor is None or self.anchor.shape != flat.shape or flat.shape[0] == 0:
            d, self.neighbours = self._scan(flat)
            self.anchor, self.distance, self.slack = flat.clone(), d, self.round_off(flat)
            return d.reshape(shape), (d <= threshold).reshape(shape)
        assert self.distance is not None and self.slack is not None and self.neighbours is not None
        margin = self.margin * threshold.abs()
        step = torch.linalg.vector_norm(flat - self.anchor, dim=1)
        reach = step + self.slack + self.round_off(flat) + margin
        on = self.distance + reach <= threshold
        off = self.distance - reach > threshold
        d = torch.where(on, self.distance + step, self.distance - step)
        rows = (~(on | off)).nonzero().squeeze(1)
        if rows.numel():  # the mean distance to the anchor's k nearest bank points
            z = flat[rows]
            near = torch.linalg.vector_norm(z[:, None, :] - self.gate.bank[self.neighbours[rows]], dim=2).mean(1)
            sure = near + self.round_off(z) + margin <= threshold
            on[rows[sure]] = True
            d[rows[sure]] = near[sure]
            rows = rows[~sure]
        if rows.numel():
            fresh, neighbours = self._scan(flat[rows])
            on[rows] = fresh <= threshold
            d[rows] = fresh
            self.anchor[rows] = flat[rows]
            self.distance[rows] = fresh
            self.slack[rows] = self.round_off(flat[rows])
            self.neighbours[rows] = neighbours
        return d.reshape(shape), on.reshape(shape)


def with_rollout_gate(model: nn.Module) -> nn.Module:
    """`model` with its fitted kNN gate replaced by a fresh `RolloutGate` (a shallow copy;
    the model itself is untouched), or `model` itself when it has no fitted gate; a
    mean-of-members ensemble (``members``) with each member's gate replaced. For one
    rollout without gradient."""
    members = getattr(model, "members", None)
    if isinstance(members, nn.ModuleList):
        gated = [with_rollout_gate(m) for m in members]
        if all(g is m for g, m in zip(gated, members)):
            return model
        rollout = copy.copy(model)
        rollout._modules = dict(model._modules)
        rollout._modules["members"] = nn.ModuleList(gated)
        return rollout
    gate = getattr(model, "gate", None)
    if not isinstance(gate, KNNGate) or gate.bank.shape[0] <= gate.k:
        return model
    rollout = copy.copy(model)
    rollout._modules = dict(model._modules)
    rollout._modules["gate"] = RolloutGate(gate)
    return rollout
