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


def test_a_finite_prediction_far_beyond_the_training_range_is_diverged_by_every_path(tmp_path, capsys):
    """One divergence rule (`sysid.evaluation.divergence`): two hybrid seeds whose FNN adds a
    correction of 100 N, 1000 N m turn the ship 10 to 20 times faster than any training or
    recorded sample (|r| > 3 x the range) while every state stays finite. The seeds' runs, the
    ensemble's own evaluation, its summary.json verdict, ``sysid evaluate RUN``'s verdict and
    ``sysid compare`` all call it DIVERGED on the same logs; judged on non-finite states alone it would not be."""
    from sysid.cli.compare_commands import _contenders
    from sysid.evaluation.comparison import Contender
    from sysid.evaluation.divergence import PhysicalRange
    from sysid.evaluation.judgement import Outcome
    from sysid.hybrid.ensemble import SeedEnsemble
    from sysid.evaluation.evaluate import predict_windows

    exp = protocol_experiment("hybrid_D2").replace(evaluation={"horizons": (30.0,)})
    tests = list(measured_runs(scale=0.5).values())
    limits = PhysicalRange.of_runs(tests)   # the training range of the seeds: the logs' own
    members = [_member(exp, seed, 100.0) for seed in (0, 1)]
    for seed, member in zip((0, 1), members):
        seed_eval = evaluate_model(member, tests, (30.0,), traces=False, limits=limits)
        assert seed_eval.divergences and seed_eval.metrics["diverged"].any()
        write_run(tmp_path / "runs" / "hybrid_D2" / f"seed{seed}", exp.replace(experiment={"seed": seed}), member,
                  seed_eval, limits=limits)
    ensemble = SeedEnsemble(members)
    evaluation = evaluate_model(ensemble, tests, (30.0,), traces=True, limits=limits)
    with torch.no_grad():
        assert all(torch.isfinite(p.predicted).all() for p in predict_windows(ensemble, tests, 30.0))
    assert evaluation.divergences and all(d.channel in ("speed", "r") for d in evaluation.divergences)
    _, _, path = write_ensemble("hybrid_D2", exp, SeedGroup("hybrid_D2", [0, 1], pd.DataFrame(), {}, None, 0.0),
                                tmp_path, tests, threads=1)
    recorded = BaselineVerdict.from_dict(RunDir(path).read_summary().verdict.to_json())
    assert recorded.outcome is Outcome.DIVERGED
    contenders = _contenders([str(path)])
    assert contenders[0].limits == limits
    theirs = compare(contenders, tests, (30.0,), BASELINE).verdicts[contenders[0].label]
    assert theirs.outcome is Outcome.DIVERGED
    assert {d.log for d in theirs.divergences} == {d.log for d in recorded.judgements[SHIP_FILE_MMG].divergences}
    # `sysid evaluate RUN`'s verdict beside its baseline: the run's training range, the same rule
    from sysid.cli.evaluate_commands import _beside_baselines
    from sysid.dynamics.integrators import EULER
    _beside_baselines(exp, ensemble, {SHIP_FILE_MMG: contenders[1].members[0]}, tests, (30.0,), EULER, limits)
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith("WARNING: The hybrid DIVERGED")
    # the same predictions judged on non-finite states alone (no training range): not diverged
    bare = compare([Contender("ensemble", (ensemble,), "hybrid", "ship"), Contender("ship", contenders[1].members)],
                   tests, (30.0,), BASELINE).verdicts["ensemble"]
    assert bare.outcome is not Outcome.DIVERGED
