"""A mean-of-seeds ensemble of ``sysid reproduce --seeds N`` records its verdict against its
physics baseline, the same one ``sysid compare RUN --against baseline`` gives (an independent
path: the compare command's own model loading, predictions and pairing)."""
from __future__ import annotations

import math

import pandas as pd
import pytest
import torch

from sysid.evaluation.comparison import BASELINE, compare
from sysid.evaluation.evaluate import evaluate_model
from sysid.evaluation.verdict import SHIP_FILE_MMG, BaselineVerdict
from sysid.hybrid.force_models import build_model
from sysid.hybrid.knn_gate import KNNGate
from sysid.protocol.reproduce import protocol_experiment
from sysid.protocol.seed_runs import SeedGroup, write_ensemble
from sysid.runs.layout import write_run
from sysid.runs.rundir import RunDir
from tests.support.synthetic_rundir import measured_runs


def _member(exp, seed: int, scale: float):
    """An untrained hybrid of `exp` whose FNN's output is scaled to `scale` [N, N, N m]: a
    correction of known size on top of the ship file's MMG."""
    torch.manual_seed(seed)
    model = build_model(exp)
    model.correction_net.set_standardization(torch.zeros(9, dtype=torch.float64), torch.full((9,), 3.0, dtype=torch.float64),
                                             torch.zeros(3, dtype=torch.float64),
                                             torch.tensor([scale, scale, 10 * scale], dtype=torch.float64))
    model.gate = KNNGate(3, 0.9, model.gate_width, torch.float64).fit(torch.randn(200, model.gate_width,
                                                                                dtype=torch.float64))
    model.gate_enabled = True
    return model


@pytest.mark.parametrize("scale", [1e-3, 0.5])
def test_ensemble_verdict_equals_compare_against_baseline(tmp_path, scale):
    """Two hybrid seeds written as run directories, their ensemble written by the protocol's
    step: its summary.json verdict (test logs, against the ship file's MMG with the hybrid's
    overrides) has the outcome, overall change and 95 % interval that `compare` finds for the
    ensemble run against its physics baseline. A negligible correction (1e-3 N) cannot be told
    apart from the MMG; one of 0.5 N, 5 N m (random in sign) is worse than it."""
    from sysid.cli.compare_commands import _contenders

    exp = protocol_experiment("hybrid_D2").replace(evaluation={"horizons": (30.0,)})
    tests = list(measured_runs(scale=0.5).values())
    for seed in (0, 1):
        member = _member(exp, seed, scale)
        run = exp.replace(experiment={"seed": seed})
        write_run(tmp_path / "runs" / "hybrid_D2" / f"seed{seed}", run, member,
                  evaluate_model(member, tests, (30.0,), traces=False))
    name, _, path = write_ensemble("hybrid_D2", exp, SeedGroup("hybrid_D2", [0, 1], pd.DataFrame(), {}, None, 0.0),
                                   tmp_path, tests, threads=1)
    assert name == "hybrid_ensemble_D2"
    summary = RunDir(path).read_summary()
    assert summary.verdict is not None
    recorded = BaselineVerdict.from_dict(summary.verdict.to_json())
    assert recorded.decided_on == "test" and recorded.baselines == (SHIP_FILE_MMG,)
    ours = recorded.judgements[SHIP_FILE_MMG]

    contenders = _contenders([str(path)])
    assert [c.label for c in contenders][1:] == ["MMG (ship file)"] and contenders[0].baseline == "MMG (ship file)"
    theirs = compare(contenders, tests, (30.0,), BASELINE).verdicts[contenders[0].label]
    assert ours.outcome is theirs.outcome
    assert (ours.n_logs, ours.n_windows, ours.n_members) == (theirs.n_logs, theirs.n_windows, theirs.n_members)
    for a, b in ((ours.change, theirs.change), (ours.change_low, theirs.change_low),
                 (ours.change_high, theirs.change_high)):
        assert math.isclose(a, b, rel_tol=1e-4, abs_tol=1e-6), (a, b)
    assert ours.outcome.name.lower() == ("not_distinguishable" if scale < 0.1 else "worse")
    assert recorded.statement().startswith("The hybrid ensemble (the mean of 2 seeds' forces) ")
    assert "1 seed" not in ours.sentence and "one model (the ensemble: no spread)" in ours.sentence
