"""The leaf-indexed kNN gate decides exactly as the gate's whole-bank scan (`KNNGate`)."""
import math

import pytest
import torch

from sysid.knn_index import IndexedGate, k_smallest_mean, leaf_partition
from sysid.ood import KNNGate


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


def test_leaves_cover_the_bank_once_and_respect_the_size():
    points = torch.randn(1000, 5, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    leaves = leaf_partition(points, 64)
    assert max(len(i) for i in leaves) <= 64
    assert torch.equal(torch.sort(torch.cat(leaves)).values, torch.arange(1000))


def test_decisions_equal_the_whole_bank_scan(gate_and_queries):
    gate, queries = gate_and_queries
    index = IndexedGate(gate, leaf=64, probe=4)
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
