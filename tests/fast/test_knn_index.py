"""The leaf-indexed kNN gate decides exactly as the gate's whole-bank scan (`KNNGate`)."""
import math

import pytest
import torch

from sysid.fast.knn_index import AnchoredGate, IndexedGate, indexed_gate, k_smallest_means, leaf_partition, neighbourhood_groups
from sysid.hybrid.knn_gate import KNNGate


def k_smallest_mean(d2, k):
    """`k_smallest_means` without a cap: the mean of sqrt of the k smallest of d2 per row."""
    return k_smallest_means(d2, k, torch.full(d2.shape[:1], math.inf, dtype=d2.dtype))[0]


@pytest.fixture(scope="module")
def gate_and_queries():
    """A gate on 3000 points of a curved 2-d sheet in 9-d (as standardised inputs are:
    few degrees of freedom), and queries near it, between and far off it."""
    g = torch.Generator().manual_seed(4)
    t = torch.rand(3000, 2, generator=g, dtype=torch.float64) * 4 - 2
    basis = torch.randn(4, 9, generator=g, dtype=torch.float64)
    sheet = lambda p: torch.cat((p, torch.sin(p)), 1) @ basis
    bank = sheet(t) + 0.01 * torch.randn(3000, 9, generator=g, dtype=torch.float64)
    gate = KNNGate(k=10, alpha=0.95, features=9, dtype=torch.float64).fit(bank)
    tq = torch.rand(600, 2, generator=g, dtype=torch.float64) * 6 - 3  # partly beyond the sheet
    queries = sheet(tq) + 0.05 * torch.randn(600, 9, generator=g, dtype=torch.float64)
    return gate, queries


@pytest.fixture(scope="module")
def feature_gate_and_queries():
    """A gate on 4000 points of a curved 3-d manifold in 64-d (as an FNN's tanh features
    of few-degree-of-freedom inputs), and queries on it, beside it and far off it."""
    g = torch.Generator().manual_seed(7)
    weights = torch.randn(3, 64, generator=g, dtype=torch.float64)
    features = lambda p: torch.tanh(p @ weights)
    bank = features(torch.rand(4000, 3, generator=g, dtype=torch.float64) * 2 - 1)
    bank = bank + 0.01 * torch.randn(4000, 64, generator=g, dtype=torch.float64)
    gate = KNNGate(k=10, alpha=0.95, features=64, dtype=torch.float64).fit(bank)
    p = torch.rand(500, 3, generator=g, dtype=torch.float64) * 3 - 1.5  # 70 % of the cube beyond the bank
    queries = features(p) + 0.02 * torch.randn(500, 64, generator=g, dtype=torch.float64)
    return gate, queries


def test_leaves_cover_the_bank_once_and_respect_the_size():
    points = torch.randn(1000, 5, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    leaves = leaf_partition(points, 64)
    assert max(len(i) for i in leaves) <= 64
    assert torch.equal(torch.sort(torch.cat(leaves)).values, torch.arange(1000))


@pytest.mark.slow
def test_decisions_equal_the_whole_bank_scan(gate_and_queries):
    gate, queries = gate_and_queries
    index = IndexedGate(gate, leaf=64, probe=8)
    exact_d, exact_on = gate(queries)
    assert 0.2 < exact_on.double().mean() < 0.9  # both decisions occur
    _, on = index(queries)  # a batch: falls back to the scan if any row is open
    assert torch.equal(on, exact_on)
    rows = [index(q[None]) for q in queries]  # one ship at a time, as in a prediction
    assert torch.equal(torch.cat([r[1] for r in rows]), exact_on)
    # the tier-1 bound is above the exact distance and decides most admitted rows alone
    upper = index._upper(queries)
    assert bool((upper >= exact_d * (1 - 1e-12)).all())
    tol = index.margin * gate.threshold
    open_rows = ~(upper <= gate.threshold - tol)
    assert open_rows.double().mean() < (~exact_on).double().mean() + 0.2


def test_tier_two_bounds_hold_the_whole_bank_distance(gate_and_queries):
    """The nearest boxes' bounds bracket d_kNN of the whole bank, and equal it when every
    leaf is searched; a box's bound is below the distance to each of its points."""
    gate, queries = gate_and_queries
    whole = k_smallest_mean((queries[:, None, :] - gate.bank).pow(2).sum(2), gate.k)
    for leaf, boxes in ((16, 4), (64, 8), (64, 1000)):
        index = IndexedGate(gate, leaf=leaf, boxes=boxes)
        upper, lower = index._box_bounds_tier(queries)
        assert bool((lower <= whole * (1 + 1e-12)).all()) and bool((upper >= whole * (1 - 1e-12)).all())
    torch.testing.assert_close(upper, whole, rtol=1e-13, atol=0)  # all leaves searched: exact
    torch.testing.assert_close(lower, whole, rtol=1e-13, atol=0)
    index = IndexedGate(gate, leaf=64)
    slots = index.points_t.transpose(1, 2)  # (C, S, F), padding far away
    d2 = (queries[:20, None, None, :] - slots).pow(2).sum(3)  # (20, C, S)
    assert bool((index.box_bounds(queries[:20])[:, :, None] <= d2 * (1 + 1e-12)).all())


def test_k_smallest_means_cap_each_value(gate_and_queries):
    g = torch.Generator().manual_seed(2)
    d2 = torch.rand(50, 40, generator=g, dtype=torch.float64)
    cap = torch.rand(50, generator=g, dtype=torch.float64) * 0.3
    mean, capped = k_smallest_means(d2, 5, cap)
    smallest = torch.sort(d2, 1).values[:, :5]
    torch.testing.assert_close(mean, smallest.sqrt().mean(1), rtol=1e-15, atol=0)
    torch.testing.assert_close(capped, torch.minimum(smallest, cap[:, None]).sqrt().mean(1), rtol=1e-15, atol=0)


def test_tier_one_groups_hold_distinct_bank_points(gate_and_queries):
    """Each of the k groups of a neighbourhood has a real point, and no point is in two."""
    gate, queries = gate_and_queries
    index = IndexedGate(gate, leaf=64, probe=3)
    far = index.points_t.max()
    points = index.points_t.transpose(1, 2).reshape(-1, gate.bank.shape[1])  # (C * S, F) slots
    for leaf in range(index.points_t.shape[0]):
        groups = neighbourhood_groups(index, leaf)
        assert len(groups) == gate.k
        slots = torch.cat(groups)
        assert slots.numel() == torch.unique(slots).numel()
        assert all(bool((points[g] < far).all(1).any()) for g in groups)
    # the bound is the mean over groups of each group's nearest distance
    z = queries[:7]
    nearest = (z[:, :, None] - index.centres_t).pow(2).sum(1).argmin(1)
    expected = torch.stack([torch.stack([(points[g] - q).pow(2).sum(1).min().sqrt()
                                         for g in neighbourhood_groups(index, int(j))]).mean()
                            for q, j in zip(z, nearest)])
    torch.testing.assert_close(index._upper(z), expected, rtol=1e-13, atol=0)


def test_k_smallest_mean_counts_ties_as_a_sort_does():
    g = torch.Generator().manual_seed(1)
    d2 = torch.randint(0, 6, (200, 30), generator=g).double()  # many ties
    d2[:5, 3:] = math.inf  # rows with fewer than k finite values
    for k in (1, 4, 10):
        expected = torch.sort(d2, 1).values[:, :k].sqrt().mean(1)
        torch.testing.assert_close(k_smallest_mean(d2, k), expected, rtol=1e-15, atol=0)


def test_open_rows_use_the_exact_scan(gate_and_queries):
    gate, queries = gate_and_queries
    index = IndexedGate(gate, leaf=64, probe=4, margin=math.inf)  # bounds never decide
    d, on = index(queries[:50])
    exact_d, exact_on = gate(queries[:50])
    assert torch.equal(on, exact_on)
    torch.testing.assert_close(d, exact_d, rtol=0, atol=0)


class _Decision(torch.nn.Module):
    """The gate's distance, signed by its decision (+ on, - off): one tensor to compile."""

    def __init__(self, gate):
        super().__init__()
        self.gate = gate

    def forward(self, z):
        d, on = self.gate(z)
        return torch.where(on, d, -d)


@pytest.mark.slow
def test_compiled_index_decides_as_the_gate_scan(gate_and_queries):
    """The tiers compiled (AOTInductor, one row per call, as in a prediction) give the
    decisions of the gate's whole-bank scan, row by row; the scan tier compiled alone too."""
    from sysid.fast.compiled import compile_cached
    gate, queries = gate_and_queries
    index = IndexedGate(gate)
    fn = compile_cached(_Decision(index), (queries[:1],), "test-gate")
    if fn is None:
        pytest.skip("compilation unavailable here")
    exact_d, exact_on = gate(queries)
    signed = torch.cat([fn(q[None]) for q in queries])
    assert torch.equal(signed > 0, exact_on)
    upper = index._upper(queries)
    tol = index.margin * gate.threshold
    assert (upper <= gate.threshold - tol).any() and (upper > gate.threshold).any()  # tier 1 and beyond
    scan = compile_cached(_Decision(IndexedGate(gate, margin=math.inf)), (queries[:1],), "test-gate")  # tier 3 only
    signed = torch.cat([scan(q[None]) for q in queries[:100]])
    assert torch.equal(signed > 0, exact_on[:100])


def test_principal_boxes_bound_every_distance_in_many_dimensions(feature_gate_and_queries):
    """In 64 features the boxes are taken in principal components and the remainder's
    norm: each box's bound is below the distance to each of its leaf's points, and the
    nearest boxes' bounds bracket d_kNN of the whole bank (equal when all are searched)."""
    gate, queries = feature_gate_and_queries
    index = IndexedGate(gate, leaf=64)
    assert index.projected and index.box_low_t.shape[0] == 17
    slots = index.points_t.transpose(1, 2)  # (C, S, F), padding far away
    d2 = (queries[:40, None, None, :] - slots).pow(2).sum(3)  # (40, C, S)
    assert bool((index.box_bounds(queries[:40])[:, :, None] <= d2 * (1 + 1e-12)).all())
    whole = gate.distance(queries)
    for boxes in (4, 16, 1000):
        upper, lower = IndexedGate(gate, leaf=64, boxes=boxes)._box_bounds_tier(queries)
        assert bool((lower <= whole * (1 + 1e-12)).all()) and bool((upper >= whole * (1 - 1e-12)).all())
    torch.testing.assert_close(upper, whole, rtol=1e-12, atol=0)
    torch.testing.assert_close(lower, whole, rtol=1e-12, atol=0)


def test_decisions_in_many_dimensions_equal_the_scan_and_rarely_need_it(feature_gate_and_queries):
    """Decisions equal the whole-bank scan row by row; tier 2 (16 of about 64 leaves)
    decides almost every row tier 1 leaves open, the rows off the manifold included, so
    the scan runs for few."""
    gate, queries = feature_gate_and_queries
    index = IndexedGate(gate)
    exact_d, exact_on = gate(queries)
    assert 0.2 < exact_on.double().mean() < 0.8  # both decisions occur
    rows = [index(q[None]) for q in queries]
    assert torch.equal(torch.cat([r[1] for r in rows]), exact_on)
    threshold = gate.threshold
    upper = index._upper(queries)
    err = (index.rounding * ((queries * queries).sum(1) + index.bank_sq_max)).sqrt()
    tol = index.margin * threshold + err
    left = ~(upper <= threshold - tol)  # left open by tier 1
    near, lower = index._box_bounds_tier(queries[left])
    decided = (near <= threshold - tol[left]) | (lower > threshold + tol[left])
    assert int(left.sum()) > 100 and decided.double().mean() > 0.9


def test_the_index_is_built_once_per_bank(gate_and_queries):
    """A compiled maneuver asks for the index at every call: the same index until the
    gate's bank is refitted, then a new one that decides as the new bank's scan."""
    gate, queries = gate_and_queries
    gate = KNNGate(k=gate.k, alpha=gate.alpha, features=9, dtype=torch.float64).fit(gate.bank[:2000])
    first = indexed_gate(gate)
    assert indexed_gate(gate) is first
    gate.fit(gate.bank[:1500])
    again = indexed_gate(gate)
    assert again is not first and again.scan_bank.shape[0] == 1500
    assert torch.equal(torch.cat([again(q[None])[1] for q in queries[:100]]), gate(queries[:100])[1])


def test_anchored_decisions_along_a_path_equal_the_scan_and_mostly_skip_the_leaves(feature_gate_and_queries):
    """Two rows moving along smooth paths across the 64-d feature manifold, in and out of
    the bank (as a maneuver's stages): each call decides as the whole-bank scan, the
    distance where "on" is a bound at or above the exact one, and most calls are decided
    from the anchor kept from the call before (tier 0) without the index's tiers."""
    gate, _ = feature_gate_and_queries
    g = torch.Generator().manual_seed(11)
    weights = torch.randn(3, 64, generator=torch.Generator().manual_seed(7), dtype=torch.float64)  # the fixture's map
    t = torch.linspace(0, 1, 400, dtype=torch.float64)[:, None]
    paths = [torch.cat([1.6 * t - 0.8, 0.3 * torch.sin(6 * t), 0.2 + 0 * t], 1),  # through the bank
             torch.cat([2.4 * t - 0.6, 0.5 * torch.cos(4 * t), 1.2 * t], 1)]  # leaves it
    queries = torch.stack([torch.tanh(p @ weights) for p in paths], 1)  # (400, 2, 64)
    queries = queries + 0.002 * torch.randn(queries.shape, generator=g, dtype=torch.float64)
    index = IndexedGate(gate)
    anchored = AnchoredGate(index)
    calls = []
    index._upper = lambda flat, upper=index._upper: calls.append(1) or upper(flat)  # counts tier-1 runs
    exact_d, exact_on = gate(queries)
    d, on = zip(*(anchored(q) for q in queries))
    d, on = torch.stack(d), torch.stack(on)
    assert 0.1 < exact_on.double().mean() < 0.9  # both decisions occur
    assert torch.equal(on, exact_on)
    assert bool((d[on] >= exact_d[on] * (1 - 1e-12)).all())
    assert len(calls) < 0.5 * len(queries)
