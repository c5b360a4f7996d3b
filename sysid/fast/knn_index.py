"""The kNN gate's decision from a leaf index of the bank: what compiled steps use.

A step needs only the decision d_kNN(z) <= threshold of `sysid.hybrid.knn_gate.KNNGate`, not the
distance. `IndexedGate` partitions the bank into leaves of at most `leaf` points
(recursive median splits along each node's widest principal direction) and decides in up
to three tiers, each only where the one before leaves the decision open:

1. an upper bound from the neighbourhood of the leaf whose centre is nearest to z (in the
   box coordinates of tier 2; that leaf and its `probe` - 1 nearest leaves, precomputed):
   its points fall into k disjoint groups (slot s of a leaf in group s mod k), and the
   mean over groups of the distance to each group's nearest point is the mean distance to
   k distinct bank points, so at least d_kNN(z). At or below the threshold: on. One
   nearest-centre search and one minimum per group, contiguous over each leaf's points, so
   compiled code runs it as a few vectorized loops with few buffers; in distribution it
   decides almost every row;
2. bounds from the `boxes` leaves nearest to z by their bounding boxes (each leaf's
   coordinate-wise minimum and maximum, a lower bound on the distance to any of its
   points): the mean distance to the k nearest points among them is an upper bound, and
   with every other point at least L away (the next box's bound) the mean of min(n_i, L)
   over their k smallest distances n_i is a lower bound (the whole bank's i-th nearest
   distance is below L only if the i nearest all lie in the chosen leaves). Upper bound at
   or below the threshold: on; lower bound above it: off. Both equal d_kNN when L is past
   the k-th distance. In more than `BOX_DIMENSIONS` coordinates (the FNN's 64 or 128
   features), where boxes in the features bound loosely, the boxes are taken in
   `PRINCIPAL` leading principal components of the bank plus the norm of the remainder: an
   orthogonal projection shortens every distance, and two remainders' norms differ by at
   most their distance, so these boxes bound too, and tightly where the bank has few
   degrees of freedom (a 35 deg turning circle and a 20/20 zig-zag of the shipped hybrid
   D2, 128 features, dt 1 s: 1.5 % of the stages left open for the scan, the rest decided
   from 16 of 256 leaves);
3. the gate's own scan (`KNNGate.distance`, a matrix product), for rows tier 2 leaves
   open (bounds either side of the threshold, or within round-off of it).

A margin (relative, plus a bound on the round-off of `KNNGate`'s own |q|^2 + |b|^2 - 2 q.b)
keeps round-off from deciding in tiers 1 and 2, so the decision always equals `KNNGate`'s.
Tiers 2 and 3 run under `torch.cond`, only when some row needs them. Tier 1 is
elementwise operations and min reductions only, which compiled code fuses into a few
vectorized loops; tier 2 finds the nearest boxes and the k smallest distances by partial
sorts (`torch.topk`: 31 us per call of the compiled gate against 45 us by passes of argmin
and min, measured side by side on a recorded zigzag's stage inputs). The distance returned
is the tier-1 upper bound, the tier-2 upper bound, or the scan's.
"""
from __future__ import annotations

import copy
import math

import torch
from torch import nn

from sysid.hybrid.knn_gate import KNNGate, nearest_distances


def k_smallest_means(d2: torch.Tensor, k: int, cap: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(mean of sqrt of the k smallest of d2 (B, M) [squared distances] along dim 1, the
    same mean with each value first capped at cap (B,)), each (B,); +inf with fewer than k
    finite values. One partial sort (`torch.topk`), smallest first."""
    if d2.shape[1] < k:
        inf = torch.full(d2.shape[:1], math.inf, dtype=d2.dtype, device=d2.device)
        return inf, inf
    near = torch.topk(d2.clamp_min(0.0), k, dim=1, largest=False, sorted=True).values  # (B, k)
    return near.sqrt().mean(1), torch.minimum(near, cap[:, None]).sqrt().mean(1)


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
        sample = p[: 4096]
        direction = torch.linalg.eigh(sample.T @ sample).eigenvectors[:, -1]  # (F,): the leading right singular vector
        order = torch.argsort(p @ direction)
        half = idx.numel() // 2
        todo += [idx[order[:half]], idx[order[half:]]]
    return out


def smallest_leaves(values: torch.Tensor, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The n leaves (B, n) with the smallest of values (B, C) per row (one partial sort,
    `torch.topk`), and the smallest value of the other leaves (B,) (+inf where none is left).
    No slicing of the sort's output: inside a `torch.cond` AOTInductor would run the slice
    through its slow proxy executor."""
    chosen = torch.topk(values, n, dim=1, largest=False, sorted=True).indices  # (B, n)
    taken = (torch.arange(values.shape[1], device=values.device) == chosen[:, :, None]).any(1)  # (B, C)
    return chosen, torch.where(taken, math.inf, values).amin(1)


BOX_DIMENSIONS = 16  # up to this many coordinates, boxes in the features themselves (in 64 they bound loosely)
PRINCIPAL = 16  # beyond: boxes in this many principal components of the bank and the remainder's norm
# Tier-1 neighbourhood beyond BOX_DIMENSIONS features: one leaf, its nearest centre found in the
# box coordinates. On the shipped hybrid D2's gate (128 features, 256 leaves) along a turning
# circle and two zig-zags (20 007 stages) it decides "on" for 90.3 % of the stages against
# 90.7 % with 8 leaves and the centre found in the features, at a sixth of the operations.
PROBE_MANY = 1


def principal_frame(bank: torch.Tensor, count: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(origin (F,), directions (F, count)): the bank's mean and its `count` leading
    principal directions (orthonormal columns), from at most 4096 of its rows."""
    origin = bank.mean(0)
    sample = bank[:: max(1, bank.shape[0] // 4096)] - origin
    return origin, torch.linalg.svd(sample, full_matrices=False).Vh[:count].T.contiguous()


def _squared_distances(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """sum over the coordinates (dim -2 of both) of (a - b)^2, broadcast; in up to
    `BOX_DIMENSIONS` coordinates as a sum of one elementwise term per coordinate (see
    `IndexedGate._upper`)."""
    features = max(a.shape[-2], b.shape[-2])
    if features > BOX_DIMENSIONS:
        return (a - b).pow(2).sum(-2)
    return sum((a.select(-2, f if a.shape[-2] > 1 else 0) - b.select(-2, f if b.shape[-2] > 1 else 0)).pow(2)
               for f in range(features))


class IndexedGate(nn.Module):
    """Drop-in for a fitted `KNNGate` in compiled steps: same decision, leaf-pruned scan.

    Parameters
    ----------
    gate : the fitted gate (bank (N, F), k, threshold); shared, not copied.
    leaf : points per leaf (at most).
    probe : leaves in a tier-1 neighbourhood (a leaf and its nearest leaves by centre);
        default 8 in up to `BOX_DIMENSIONS` features, 1 beyond (see `PROBE_MANY`).
    boxes : leaves searched in tier 2 (those with the nearest bounding boxes).
    margin : relative margin below which bounds do not decide (the exact scan does).
    """

    def __init__(self, gate: KNNGate, leaf: int = 64, probe: int | None = None, boxes: int = 16,
                 margin: float | None = None):
        super().__init__()
        self.gate = gate
        self.k = gate.k
        bank = gate.bank.detach()
        dtype = bank.dtype
        leaves = leaf_partition(bank.double(), leaf)
        size = math.ceil(max(len(i) for i in leaves) / self.k) * self.k  # slots per leaf: k groups of size / k
        self.projected = bank.shape[1] > BOX_DIMENSIONS  # boxes in principal components and the remainder
        self.probe = min(probe or (PROBE_MANY if self.projected else 8), len(leaves))
        self.boxes = min(boxes, len(leaves))
        far = (torch.finfo(dtype).max / (4 * bank.shape[1])) ** 0.5  # padding: far, d^2 still finite
        points = torch.full((len(leaves), size, bank.shape[1]), far, dtype=dtype)
        centres = torch.zeros(len(leaves), bank.shape[1], dtype=torch.float64)
        for j, idx in enumerate(leaves):
            members = bank[idx]
            points[j, : len(idx)] = members
            centres[j] = members.double().mean(0)
        eps = torch.finfo(dtype).eps
        self.margin = float(margin if margin is not None else 1e4 * eps)
        self.rounding = 2.0 * (bank.shape[1] + 4) * eps
        self.register_buffer("bank_sq", (bank * bank).sum(1))  # as KNNGate computes it
        self.register_buffer("scan_bank", bank.clone())  # the gate's bank, as a buffer of this module
        self.register_buffer("bank_sq_max", self.bank_sq.max())
        self.register_buffer("points_t", points.transpose(1, 2).contiguous())  # (C, F, S)
        self.register_buffer("neighbours", torch.cdist(centres, centres).argsort(1)[:, : self.probe])  # (C, probe)
        if self.projected:
            origin, directions = principal_frame(bank.double(), min(PRINCIPAL, bank.shape[1]))
            self.register_buffer("box_origin", origin.to(dtype))  # (F,)
            self.register_buffer("box_directions", directions.to(dtype))  # (F, P)
            self.register_buffer("box_directions_t", directions.T.to(dtype).contiguous())  # (P, F), its own
            # buffer: a transposed view of one would alias it inside torch.cond
        # leaf centres in the box coordinates: tier 1 picks the nearest there
        self.register_buffer("centres_t", self.box_coordinates(centres.to(dtype)).T.contiguous())  # (F or P + 1, C)
        box = self.box_coordinates(bank)  # (N, F) or (N, P + 1)
        self.register_buffer("box_low_t", torch.stack([box[i].amin(0) for i in leaves], 1))  # (F or P + 1, C)
        self.register_buffer("box_high_t", torch.stack([box[i].amax(0) for i in leaves], 1))

    @property
    def threshold(self) -> torch.Tensor:
        return self.gate.threshold

    @property
    def bank(self) -> torch.Tensor:
        return self.gate.bank

    def _upper(self, z: torch.Tensor) -> torch.Tensor:
        """Upper bound (B,) of the mean k-nearest distance of z (B, F) (tier 1): the mean
        over k groups of points of the nearest leaf's neighbourhood (slot s of every leaf
        in group s mod k) of the distance to each group's nearest point: k distinct bank
        points (`neighbourhood_groups` lists them).

        In up to `BOX_DIMENSIONS` coordinates the sums over them are written out term by
        term: elementwise expressions, which compiled code can fold into the loops that
        reduce them (it does for the argmin over the (B, C) squared centre distances: one
        row, one allocation of 2 kB fewer per call)."""
        nearest = _squared_distances(self.box_coordinates(z)[:, :, None], self.centres_t).argmin(1)  # (B,)
        points = self.points_t[self.neighbours[nearest]]  # (B, probe, F, S), S contiguous
        d2 = _squared_distances(z[:, None, :, None], points)  # (B, probe, S) squared
        groups = d2.reshape(d2.shape[0], -1, self.k)  # (B, probe S / k, k): group = slot mod k
        return groups.amin(1).clamp_min(0.0).sqrt().mean(1)

    def box_coordinates(self, z: torch.Tensor) -> torch.Tensor:
        """The coordinates boxes are taken in, of z (B, F): z itself in up to
        `BOX_DIMENSIONS` features; else (B, P + 1), the components along the bank's P
        principal directions (from its mean) and the norm of what they leave. Any
        distance in them is at most the distance in the features."""
        if not self.projected:
            return z
        offset = z - self.box_origin
        along = offset @ self.box_directions  # (B, P)
        remainder = (offset - along @ self.box_directions_t).pow(2).sum(1, keepdim=True).sqrt()  # (B, 1)
        return torch.cat([along, remainder], 1)

    def box_bounds(self, z: torch.Tensor) -> torch.Tensor:
        """Squared lower bound (B, C) of the distance from z (B, F) to any point of each
        leaf: the squared distance to the leaf's bounding box in `box_coordinates`."""
        z = self.box_coordinates(z)[:, :, None]
        outside = (self.box_low_t - z).clamp_min(0.0) + (z - self.box_high_t).clamp_min(0.0)  # one is 0
        return outside.pow(2).sum(1)

    def _box_bounds_tier(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(upper, lower) bounds (B,) of the mean k-nearest distance of z (B, F) (tier 2),
        from the points of the `boxes` leaves with the nearest bounding boxes; both are
        d_kNN when no other box is nearer than the k-th of those points."""
        chosen, rest = smallest_leaves(self.box_bounds(z), self.boxes)  # rest (B,) squared: every point
        # outside the chosen leaves is at least this far
        points = self.points_t[chosen]  # (B, boxes, F, S)
        d2 = (z[:, None, :, None] - points).pow(2).sum(2)  # (B, boxes, S) squared
        return k_smallest_means(d2.flatten(1), self.k, rest)

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(distance, in_distribution) for z (..., F), as `KNNGate.forward` decides."""
        flat = z.detach().reshape(-1, z.shape[-1]).to(self.points_t.dtype)
        upper = self._upper(flat)
        threshold = self.gate.threshold
        tol = self.tolerance(flat)
        on = upper <= threshold - tol
        k = min(self.k, self.bank_sq.shape[0])
        if not torch.compiler.is_compiling():  # eager: the same tiers as plain branches
            d, admitted = self._eager_tiers(flat, upper, on, threshold, tol, k)[:2]
            return d.reshape(z.shape[:-1]), admitted.reshape(z.shape[:-1])

        def bounded(flat, upper, threshold, tol):  # tier 2, and tier 3 where it leaves rows open
            near, lower = self._box_bounds_tier(flat)

            def gate_scan(flat, near, threshold, tol):  # KNNGate.distance, exactly (tier 3)
                scan = nearest_distances(flat, self.scan_bank, self.bank_sq, k).mean(1)
                return scan, scan <= threshold

            def decided(flat, near, threshold, tol):
                return near.clone(), near <= threshold - tol

            open_rows = (near > threshold - tol) & (lower <= threshold + tol)
            return torch.cond(open_rows.any(), gate_scan, decided, (flat, near, threshold, tol))

        def neighbourhood(flat, upper, threshold, tol):
            return upper.clone(), upper <= threshold - tol

        d, admitted = torch.cond((~on).any(), bounded, neighbourhood, (flat, upper, threshold, tol))
        return d.reshape(z.shape[:-1]), admitted.reshape(z.shape[:-1])

    def _eager_tiers(self, flat, upper, on, threshold, tol, k):
        """`forward`'s tiers 2 and 3 as Python branches (eager: `torch.cond` outside a
        compiled program costs a trace per call); the same numbers and decisions. Returns
        (distance (B,), in_distribution (B,), upper (B,), lower (B,)): bounds of d_kNN at
        flat (B, F) that `AnchoredGate` keeps: upper, the smallest of the tier bounds taken
        (tier 1's, and tier 2's where it ran), each the mean distance to k distinct bank
        points; lower, tier 2's lower bound (-inf where only tier 1 ran)."""
        if bool(on.all()):
            return upper, on, upper, torch.full_like(upper, -math.inf)
        near, lower = self._box_bounds_tier(flat)
        bound = torch.minimum(upper, near)
        open_rows = (near > threshold - tol) & (lower <= threshold + tol)
        if bool(open_rows.any()):
            scan = nearest_distances(flat, self.scan_bank, self.bank_sq, k).mean(1)
            return scan, scan <= threshold, bound, lower
        return near, near <= threshold - tol, bound, lower

    def tolerance(self, flat: torch.Tensor) -> torch.Tensor:
        """(B,) what a bound at features flat (B, F) must stay below the threshold by to
        decide "on": the relative `margin` plus the round-off of `KNNGate`'s own distance."""
        # |q|^2 + |b|^2 - 2 q.b, as KNNGate computes d^2, is off by at most about
        # 2 (F + 4) eps (|q|^2 + |b|^2), so its distances by at most the root of that
        err = (self.rounding * ((flat * flat).sum(1) + self.bank_sq_max)).sqrt()  # (B,)
        return self.margin * self.gate.threshold.abs() + err


class AnchoredGate(nn.Module):
    """An `IndexedGate` for the eager steps of one rollout (a fresh one per rollout: it
    keeps state between calls), deciding most calls from the call before: the same
    decisions as `KNNGate`, with about a fifth of the operations where successive
    features are close (the stages and steps of a maneuver).

    Tier 0: for each row it keeps an anchor a (F,) where the index's tiers took bounds
    L(a) <= d_kNN(a) <= U(a), U the mean distance from a to k distinct bank points
    (`IndexedGate._eager_tiers`). The mean distance from z to the same k points is at most
    U(a) + |z - a| (the triangle inequality), and d_kNN, a mean of order statistics of
    distances, moves by at most |z - a|: L(a) - |z - a| <= d_kNN(z) <= U(a) + |z - a|. The
    tiers decide "on" where an upper bound is at or below threshold - tol(z), "off" where
    a lower bound is above threshold + tol(z) (`IndexedGate.tolerance`: a relative margin
    plus the round-off of `KNNGate`'s distance, which grows with |z| <= |a| + |z - a|), so
    each row has two reaches, taken once at its anchor: "on" while |z - a| <= R_on - E,
    R_on = threshold - margin |threshold| - U(a), E the round-off term at |z| = |a| + R_on
    (then |z - a| <= R_on, tol(z) <= margin |threshold| + E and U(a) + |z - a| <= threshold
    - tol(z)); "off" while |z - a| < R_off - E, R_off = L(a) - threshold - margin
    |threshold|, alike. A call decided for every row costs a difference, a norm and a
    comparison; where rows stay open the call runs the index's tiers for those rows alone
    (whose own decision stands) and their bounds at z become those rows' anchors. Along a 690 s turning circle and
    20/20 zig-zag of a hybrid D2 (128 features, 27 600 stages) tier 0 decided 99.5 % of
    the calls.

    ``forward(z (..., F))`` -> (distance (...,), in_distribution (...,)): the distance is
    tier 0's bound that decided (upper where on, lower where off), else what
    `IndexedGate.forward` returns.
    """

    def __init__(self, index: IndexedGate):
        super().__init__()
        self.index = index
        self.anchor: torch.Tensor | None = None  # (B, F) features where the bounds were taken
        self.upper: torch.Tensor | None = None  # (B,) bounds of d_kNN there
        self.lower: torch.Tensor | None = None
        self.reach_on: torch.Tensor | None = None  # (B,) |z - anchor| up to which a row is "on"
        self.reach_off: torch.Tensor | None = None  # (B,) below which it is off

    @property
    def threshold(self) -> torch.Tensor:
        return self.index.threshold

    @property
    def bank(self) -> torch.Tensor:
        return self.index.bank

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        index, shape = self.index, z.shape[:-1]
        flat = z.detach().reshape(-1, z.shape[-1])
        if flat.dtype != index.points_t.dtype:
            flat = flat.to(index.points_t.dtype)
        if self.anchor is not None and self.anchor.shape == flat.shape:
            step = torch.linalg.vector_norm(flat - self.anchor, dim=1)
            on = step <= self.reach_on
            if bool(on.all()):
                return (self.upper + step).reshape(shape), on.reshape(shape)
            decided = on | (step < self.reach_off)
            d = torch.where(on, self.upper + step, self.lower - step)
            if bool(decided.all()):
                return d.reshape(shape), on.reshape(shape)
            rows = (~decided).nonzero().squeeze(1)  # the index's tiers for these rows alone: their anchors move
            d[rows], on[rows] = self._anchor(flat[rows], rows)
            return d.reshape(shape), on.reshape(shape)
        self.anchor = flat.clone()
        self.upper, self.lower, self.reach_on, self.reach_off = (torch.empty_like(flat[:, 0]) for _ in range(4))
        d, on = self._anchor(flat, slice(None))
        return d.reshape(shape), on.reshape(shape)

    def _anchor(self, flat: torch.Tensor, rows) -> tuple[torch.Tensor, torch.Tensor]:
        """(distance, in_distribution) of flat (B', F) by the index's tiers, whose bounds there
        become the anchors of `rows` (indices, or every row)."""
        index = self.index
        threshold = index.gate.threshold
        tol = index.tolerance(flat)
        upper = index._upper(flat)
        d, on, bound, lower = index._eager_tiers(flat, upper, upper <= threshold - tol, threshold, tol,
                                                 min(index.k, index.bank_sq.shape[0]))
        size = torch.linalg.vector_norm(flat, dim=1)
        margin = index.margin * threshold.abs()
        self.anchor[rows], self.upper[rows], self.lower[rows] = flat, bound, lower
        self.reach_on[rows] = self._reach(threshold - margin - bound, size)
        self.reach_off[rows] = self._reach(lower - threshold - margin, size)
        return d, on

    def _reach(self, room: torch.Tensor, size: torch.Tensor) -> torch.Tensor:
        """room (B,) less the round-off term of `IndexedGate.tolerance` at |z| = size + room
        (size (B,): |anchor|); negative (never reached) where room is."""
        far = size + room.clamp_min(0.0)
        return room - (self.index.rounding * (far * far + self.index.bank_sq_max)).sqrt()


def neighbourhood_groups(index: "IndexedGate", leaf: int) -> list[torch.Tensor]:
    """The k point groups of leaf `leaf`'s tier-1 neighbourhood, as flat slot numbers
    (leaf * S + slot) into `IndexedGate.points_t`: slot s of every neighbouring leaf is in
    group s mod k (padding slots included). For checks; `IndexedGate._upper` takes the
    groups' minima by a reshape."""
    size = index.points_t.shape[2]
    slots = (index.neighbours[leaf][:, None] * size + torch.arange(size)).reshape(-1)
    return [slots[g::index.k] for g in range(index.k)]


MAX_INDEXED_BATCH = 256  # beyond it the whole-bank scan (one matrix product) is as quick


def with_indexed_gate(model: nn.Module, batch: int, anchored: bool = False) -> nn.Module:
    """`model` with its fitted kNN gate replaced by an `IndexedGate` (a shallow copy; the
    model itself is untouched), or `model` when it has no gate or the batch is large.
    `anchored`: by a fresh `AnchoredGate` around it (eager steps of one rollout)."""
    gate = getattr(model, "gate", None)
    if not isinstance(gate, KNNGate) or gate.bank.shape[0] <= gate.k or batch > MAX_INDEXED_BATCH:
        return model
    fast = copy.copy(model)
    fast._modules = dict(model._modules)
    index = indexed_gate(gate)
    fast._modules["gate"] = AnchoredGate(index) if anchored else index
    return fast


def indexed_gate(gate: KNNGate) -> IndexedGate:
    """The `IndexedGate` of `gate`, built once per bank (kept on the gate until its bank is
    replaced or modified): building one partitions the bank, about 1 s for the shipped
    hybrid D2's 10 k features of 128, which every compiled maneuver would otherwise pay."""
    return gate.per_bank("indexed", lambda: IndexedGate(gate))
