"""kNN out-of-distribution gate (paper section 3.4.3, Eqs. 18-21).

d_kNN(z) = mean Euclidean distance from feature z (the FNN's last hidden activations) to
its k nearest training features; the threshold is the alpha-quantile of the training
distances (each training feature scored leave-one-out); F_NN is switched off where
d_kNN exceeds it.
"""
from __future__ import annotations

import math

import torch
from torch import nn


def squared_distances(q: torch.Tensor, bank: torch.Tensor, bank_sq: torch.Tensor,
                      out: torch.Tensor | None = None) -> torch.Tensor:
    """|q - b|^2 (B, N) from q (B, F) to every bank row b (N, F) as |q|^2 + |b|^2 - 2 q.b
    (bank_sq = |b|^2, (N,)): one matrix product. Eager, the product accumulates into the
    (B, N) sum in place (one (B, N) buffer and one pass fewer), held in `out` (at least
    (B, N), reused across chunks) when given; compiled, as a plain difference."""
    if out is not None and not torch.compiler.is_compiling():
        d2 = torch.add((q * q).sum(1, keepdim=True), bank_sq, out=out[:q.shape[0]])
    else:
        d2 = (q * q).sum(1, keepdim=True) + bank_sq
    if torch.compiler.is_compiling():
        return d2 - 2.0 * q @ bank.t()  # t(): a traceable op, not an attribute
    return d2.addmm_(q, bank.t(), alpha=-2.0)


def nearest(q: torch.Tensor, bank: torch.Tensor, bank_sq: torch.Tensor, k: int,
            out: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """The k smallest Euclidean distances (B, k), ascending, from q (B, F) to bank (N, F),
    and the bank rows they are to (B, k): the k smallest of `squared_distances`."""
    found = torch.topk(squared_distances(q, bank, bank_sq, out), k, dim=1, largest=False)
    return found.values.clamp_min(0.0).sqrt(), found.indices


def nearest_distances(q: torch.Tensor, bank: torch.Tensor, bank_sq: torch.Tensor, k: int,
                      out: torch.Tensor | None = None) -> torch.Tensor:
    """`nearest`'s distances (B, k) alone: the same numbers, their k smallest by `smallest`
    (eager; compiled, by the top-k)."""
    d2 = squared_distances(q, bank, bank_sq, out)
    if torch.compiler.is_compiling():
        return torch.topk(d2, k, dim=1, largest=False).values.clamp_min(0.0).sqrt()
    return smallest(d2, k).clamp_min(0.0).sqrt()


GROUPS = 8  # strided column groups of `smallest`


def smallest(d2: torch.Tensor, k: int) -> torch.Tensor:
    """The k smallest values of every row of d2 (B, N), ascending: the values of
    ``torch.topk(d2, k, largest=False)``, the same numbers, found in about half its time.

    The first 8 W columns (W = N // 8) as W sets {j, j + W, ..., j + 7 W}: their minima in one
    elementwise pass over 8 rows of W, the k sets of smallest minima (largest of them m) by a
    top-k over W. Every value below m lies in those sets (any other set's values are >= m),
    and they hold k values <= m, so the k smallest of their 8 k values and the N - 8 W columns
    left over are the row's k smallest. Rows of fewer than 8 k columns, and a chunk with a NaN
    (which a minimum would carry), take the top-k over all columns."""
    rows, n = d2.shape
    width = n // GROUPS
    if width < k or rows == 0:
        return torch.topk(d2, k, dim=1, largest=False).values
    full = width * GROUPS
    minima = d2[:, :full].view(rows, GROUPS, width).amin(1)  # (B, W): set j's minimum
    rest = d2[:, full:]
    if minima.isnan().any() or rest.isnan().any():
        return torch.topk(d2, k, dim=1, largest=False).values
    sets = torch.topk(minima, k, dim=1, largest=False, sorted=False).indices  # (B, k)
    columns = (sets.unsqueeze(2) + width * torch.arange(GROUPS, device=d2.device)).reshape(rows, -1)
    candidates = torch.cat([torch.gather(d2, 1, columns), rest], 1)  # (B, 8 k + N - 8 W)
    return torch.topk(candidates, k, dim=1, largest=False).values


class KNNGate(nn.Module):
    """Feature bank, k, alpha and threshold; `fit` returns self.

    Attributes (after `fit`)
    ------------------------
    bank : (N, F) training features; threshold : () delta_kNN; train_distances : (N,).
    """

    def __init__(self, k: int = 10, alpha: float = 0.9995, features: int = 64,
                 dtype: torch.dtype = torch.float32, chunk: int = 4096):
        super().__init__()
        if k < 1 or not 0.0 < alpha < 1.0:
            raise ValueError(f"kNN gate: need k >= 1 and 0 < alpha < 1, got k={k}, alpha={alpha}")
        self.k, self.alpha, self.chunk = int(k), float(alpha), int(chunk)
        self.register_buffer("bank", torch.zeros(0, features, dtype=dtype))
        self.register_buffer("threshold", torch.tensor(math.inf, dtype=dtype))
        self.register_buffer("train_distances", torch.zeros(0, dtype=dtype))

    def per_bank(self, name: str, build):
        """`build()`, kept under `name` until the bank tensor is replaced or modified."""
        cache = self.__dict__.setdefault("_per_bank", {})
        cached = cache.get(name)  # (bank tensor, its version, value)
        if cached is None or cached[0] is not self.bank or cached[1] != self.bank._version:
            cached = cache[name] = (self.bank, self.bank._version, build())
        return cached[2]

    def _bank_sq(self) -> torch.Tensor:
        """|b|^2 of every bank vector (N,), cached for the current bank."""
        return self.per_bank("bank_sq", lambda: (self.bank * self.bank).sum(1))

    def _distances(self, z: torch.Tensor, exclude_self: bool) -> torch.Tensor:
        flat = z.reshape(-1, z.shape[-1]).to(self.bank.dtype)
        k = min(self.k + (1 if exclude_self else 0), self.bank.shape[0])
        bank_sq = self._bank_sq()
        out = []
        # one (chunk, N) buffer of squared distances for every chunk: reusing it spares each
        # new allocation's page faults (the products and their numbers are the same)
        d2 = flat.new_empty(min(self.chunk, flat.shape[0]), self.bank.shape[0])
        for lo in range(0, flat.shape[0], self.chunk):
            nearest = nearest_distances(flat[lo:lo + self.chunk], self.bank, bank_sq, k, d2)
            if exclude_self:  # drop the point itself (distance 0)
                nearest = nearest[:, 1:]
            out.append(nearest.mean(1))
        return torch.cat(out).reshape(z.shape[:-1]) if out else flat.new_zeros(z.shape[:-1])

    @torch.no_grad()
    def fit(self, features: torch.Tensor) -> "KNNGate":
        """Store the training features and set the threshold (Eqs. 19-20, leave-one-out)."""
        if features.shape[0] <= self.k:
            raise ValueError(f"kNN gate: need more than k={self.k} training features, got {features.shape[0]}")
        self.bank = features.detach().to(self.bank.dtype).clone()  # type: ignore[has-type]
        d = self._distances(self.bank, exclude_self=True)
        self.train_distances = d
        ordered = torch.sort(d).values
        index = max(0, math.ceil(self.alpha * len(ordered)) - 1)  # inf{x : F(x) >= alpha}
        self.threshold = ordered[index].clone()
        return self

    def distance(self, z: torch.Tensor) -> torch.Tensor:
        """d_kNN (...,) of features z (..., F)."""
        return self._distances(z, exclude_self=False)

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(d_kNN, in_distribution) for features z (..., F); in_distribution is boolean."""
        d = self.distance(z.detach())
        return d, d <= self.threshold
