"""`knn_gate.smallest` gives torch.topk's k smallest values to the bit (ties, duplicates,
NaN, rows too short for its groups), and the gate's leave-one-out fit gives the distances
of a plain top-k over the same squared distances."""
import math

import pytest
import torch

from sysid.hybrid.knn_gate import GROUPS, KNNGate, smallest, squared_distances


def _topk(d2: torch.Tensor, k: int) -> torch.Tensor:
    return torch.topk(d2, k, dim=1, largest=False).values


@pytest.mark.parametrize("n, k", [(1037, 11), (800, 10), (88, 11), (87, 11), (40, 3), (12, 1)])
def test_smallest_equals_topk_bit_for_bit(n, k):
    g = torch.Generator().manual_seed(n + k)
    d2 = torch.rand(64, n, generator=g)
    # ties and duplicates: a coarse grid of values, the same minimum in several sets
    d2[:16] = torch.round(d2[:16] * 8) / 8
    d2[16, :] = 0.5
    d2[17, ::GROUPS] = 0.0
    d2[18, -(n % GROUPS or 1):] = -1.0  # the smallest values in the columns left over
    got = smallest(d2, k)
    assert got.shape == (64, k)
    assert torch.equal(got, _topk(d2, k))


def test_a_nan_takes_the_full_topk():
    d2 = torch.rand(4, 200, generator=torch.Generator().manual_seed(0))
    d2[1, 7] = math.nan
    assert torch.equal(smallest(d2, 5), _topk(d2, 5))
    d2[1, 7], d2[2, 199] = 0.3, math.nan  # in the columns left over (200 = 8 * 25)
    assert torch.equal(smallest(d2, 5), _topk(d2, 5))


def test_leave_one_out_fit_matches_the_plain_topk():
    """The gate's training distances and threshold against the same squared distances with
    torch.topk over every column, in one chunk and in chunks of 700 rows."""
    g = torch.Generator().manual_seed(3)
    features = torch.tanh(torch.randn(1500, 16, generator=g))
    features[100] = features[7]  # a duplicate: a distance of (about) 0 besides the point itself
    for chunk in (4096, 700):
        gate = KNNGate(k=10, alpha=0.99, features=16, chunk=chunk).fit(features)
        bank_sq = (features * features).sum(1)
        expected = []
        for lo in range(0, len(features), chunk):
            d2 = squared_distances(features[lo:lo + chunk], features, bank_sq)
            expected.append(_topk(d2, 11).clamp_min(0.0).sqrt()[:, 1:].mean(1))
        expected = torch.cat(expected)
        assert torch.equal(gate.train_distances, expected)
        ordered = torch.sort(expected).values
        assert torch.equal(gate.threshold, ordered[math.ceil(0.99 * 1500) - 1])
