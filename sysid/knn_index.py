"""The kNN gate's decision from a leaf index of the bank: what compiled steps use.

A step needs only the decision d_kNN(z) <= threshold of `sysid.ood.KNNGate`, not the
distance. `IndexedGate` partitions the bank into leaves of at most `leaf` points
(recursive median splits along each node's widest principal direction), with a centre
and a radius per leaf, scans only the `probe` leaves nearest to z, and decides from two
bounds on the true mean of the k nearest distances:

- upper: the mean of the k smallest distances among probed points (the true k nearest
  are at least as near) — at or below the threshold: the network is on;
- lower: every unprobed point is at least L = min over unprobed leaves of
  (|z - centre| - radius) away, so the true mean is at least the mean of the k smallest
  of (probed distances, L repeated k times) — above the threshold: off.

A relative margin keeps round-off from deciding; rows the bounds leave open (rare: z
within the margin of the threshold or between leaves) send the batch to the gate's own
exact scan (`torch.cond`), so the decision always equals `KNNGate`'s. The distance it
returns is the probed upper bound, or the exact one where the scan ran.
"""
from __future__ import annotations

import copy
import math

import torch
from torch import nn

from sysid.ood import KNNGate, nearest_distances


def leaf_partition(points: torch.Tensor, leaf: int) -> list[torch.Tensor]:
    """Index sets (each <= `leaf` rows) of `points` (N, F) by recursive median splits
    along the principal direction of each node."""
    out, todo = [], [torch.arange(points.shape[0])]
    while todo:
        idx = todo.pop()
        if idx.numel() <= leaf:
            out.append(idx)
            continue
        p = points[idx] - points[idx].mean(0)
        direction = torch.linalg.svd(p[: 4096], full_matrices=False).Vh[0]  # (F,)
        order = torch.argsort(p @ direction)
        half = idx.numel() // 2
        todo += [idx[order[:half]], idx[order[half:]]]
    return out


class IndexedGate(nn.Module):
    """Drop-in for a fitted `KNNGate` in compiled steps: same decision, leaf-pruned scan.

    Parameters
    ----------
    gate : the fitted gate (bank (N, F), k, threshold); shared, not copied.
    leaf : points per leaf (at most).
    probe : leaves scanned per query.
    margin : relative margin below which bounds do not decide (the exact scan does).
    """

    def __init__(self, gate: KNNGate, leaf: int = 128, probe: int = 8, margin: float | None = None):
        super().__init__()
        self.gate = gate
        self.k = gate.k
        bank = gate.bank.detach()
        dtype = bank.dtype
        leaves = leaf_partition(bank.double(), leaf)
        size = max(len(i) for i in leaves)
        self.probe = min(probe, len(leaves))
        points = torch.zeros(len(leaves), size, bank.shape[1], dtype=dtype)
        norms = torch.full((len(leaves), size), math.inf, dtype=dtype)  # padding: infinitely far
        centres = torch.zeros(len(leaves), bank.shape[1], dtype=torch.float64)
        radii = torch.zeros(len(leaves), dtype=torch.float64)
        for j, idx in enumerate(leaves):
            members = bank[idx]
            points[j, : len(idx)] = members
            norms[j, : len(idx)] = (members * members).sum(1)
            centres[j] = members.double().mean(0)
            radii[j] = (members.double() - centres[j]).norm(dim=1).max()
        eps = torch.finfo(dtype).eps
        self.margin = float(margin if margin is not None else 1e4 * eps)
        self.register_buffer("bank_sq", (bank * bank).sum(1))  # as KNNGate computes it
        self.register_buffer("points", points)
        self.register_buffer("norms", norms)
        self.register_buffer("centres", centres.to(dtype))
        self.register_buffer("radii", (radii * (1 + 1e3 * eps) + 1e3 * eps).to(dtype))

    @property
    def threshold(self) -> torch.Tensor:
        return self.gate.threshold

    @property
    def bank(self) -> torch.Tensor:
        return self.gate.bank

    def _bounds(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(upper, lower) bounds (B,) of the mean k-nearest distance of z (B, F)."""
        to_centre = (z.unsqueeze(1) - self.centres).pow(2).sum(-1).sqrt()  # (B, C), no cancellation
        near = torch.topk(to_centre, self.probe, dim=1, largest=False).indices  # (B, P)
        cand = self.points[near].flatten(1, 2)  # (B, P*S, F)
        cand_sq = self.norms[near].flatten(1)  # (B, P*S)
        d2 = (z * z).sum(1, keepdim=True) + cand_sq - 2.0 * (cand @ z.unsqueeze(-1)).squeeze(-1)
        nearest = torch.topk(d2, self.k, dim=1, largest=False).values.clamp_min(0.0).sqrt()  # (B, k)
        upper = nearest.mean(1)
        leaf_lower = (to_centre - self.radii).clamp_min(0.0)
        leaf_lower = leaf_lower.scatter(1, near, torch.full_like(leaf_lower, math.inf)[:, : self.probe])
        outside = leaf_lower.min(1, keepdim=True).values.expand(-1, self.k)  # (B, k)
        lower = torch.topk(torch.cat((nearest, outside), 1), self.k, dim=1, largest=False).values.mean(1)
        return upper, lower

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(distance, in_distribution) for z (..., F), as `KNNGate.forward` decides."""
        flat = z.detach().reshape(-1, z.shape[-1]).to(self.points.dtype)
        upper, lower = self._bounds(flat)
        threshold = self.gate.threshold
        tol = self.margin * threshold.abs()
        on = upper <= threshold - tol
        off = lower > threshold + tol
        open_rows = ~(on | off)

        k = min(self.k, self.bank_sq.shape[0])

        def scan(flat, upper, on, threshold):  # KNNGate.distance, exactly
            d = nearest_distances(flat, self.gate.bank, self.bank_sq, k).mean(1)
            return d, d <= threshold

        def bounded(flat, upper, on, threshold):
            return upper.clone(), on.clone()

        d, admitted = torch.cond(open_rows.any(), scan, bounded, (flat, upper, on, threshold))
        return d.reshape(z.shape[:-1]), admitted.reshape(z.shape[:-1])


MAX_INDEXED_BATCH = 256  # beyond it the whole-bank scan (one matrix product) is as quick


def with_indexed_gate(model: nn.Module, batch: int) -> nn.Module:
    """`model` with its fitted kNN gate replaced by an `IndexedGate` (a shallow copy; the
    model itself is untouched), or `model` when it has no gate or the batch is large."""
    gate = getattr(model, "gate", None)
    if not isinstance(gate, KNNGate) or gate.bank.shape[0] <= gate.k or batch > MAX_INDEXED_BATCH:
        return model
    fast = copy.copy(model)
    fast._modules = dict(model._modules)
    fast._modules["gate"] = IndexedGate(gate)
    return fast
