"""`RolloutGate`: along a rollout, the kNN gate's own decisions (the whole-bank scan's) at
every step, from scans of few rows after the first step."""
from __future__ import annotations

import torch

from sysid.hybrid.knn_gate import KNNGate
from sysid.hybrid.rollout_gate import RolloutGate, with_rollout_gate


def _bank_and_paths(dtype):
    """A bank of 3000 tanh features (32) of a 3-d manifold, and 200 rows moving along smooth
    paths through it and out of it (as a rollout's steps), one of them NaN from step 20."""
    g = torch.Generator().manual_seed(5)
    weights = torch.randn(3, 32, generator=g, dtype=torch.float64)
    bank = torch.tanh((torch.rand(3000, 3, generator=g, dtype=torch.float64) * 2 - 1) @ weights)
    gate = KNNGate(k=10, alpha=0.99, features=32, dtype=dtype).fit(bank.to(dtype))
    t = torch.linspace(0, 1, 60, dtype=torch.float64)[:, None, None]
    start = torch.rand(200, 3, generator=g, dtype=torch.float64) * 2 - 1
    velocity = torch.randn(200, 3, generator=g, dtype=torch.float64)
    paths = torch.tanh((start + t * velocity + 0.1 * torch.sin(9 * t) * velocity.roll(1, 1)) @ weights)
    paths[20:, 7] = float("nan")
    return gate, paths.to(dtype)  # (60, 200, 32)


def test_rollout_gate_decides_as_the_scan_at_every_step_scanning_few_rows():
    for dtype in (torch.float32, torch.float64):
        gate, paths = _bank_and_paths(dtype)
        rollout = RolloutGate(gate)
        scanned: list[int] = []
        rollout._scan = lambda flat, scan=rollout._scan, scanned=scanned: scanned.append(flat.shape[0]) or scan(flat)  # type: ignore[method-assign]
        decisions = []
        for z in paths:
            d, on = rollout(z)
            exact_d, exact_on = gate(z)
            assert torch.equal(on, exact_on)
            # the distance: the scan's, or a bound on the side decided
            assert bool((d[on] >= exact_d[on] - 1e-4).all()) and bool((d[~on & ~exact_d.isnan()] >= gate.threshold).all())
            decisions.append(on)
        share_on = torch.stack(decisions).double().mean()
        assert 0.3 < share_on < 0.97, share_on  # both decisions occur
        assert scanned[0] == 200 and sum(scanned[1:]) < 0.5 * 200 * (len(paths) - 1), scanned


def test_with_rollout_gate_leaves_the_model_alone():
    gate, _ = _bank_and_paths(torch.float32)
    model = torch.nn.Module()
    model.gate = gate
    rollout = with_rollout_gate(model)
    assert isinstance(rollout.gate, RolloutGate) and rollout.gate.gate is gate and model.gate is gate
    bare = torch.nn.Module()
    bare.gate = None
    assert with_rollout_gate(bare) is bare
