"""`sysid compare`'s contenders (`sysid.cli.compare_commands._contenders`): a ship file's MMG
that is a learned run's physics baseline is judged against the run's training range whether
the user names the ship file or compare adds it (one divergence rule)."""
from __future__ import annotations

import torch

from sysid.cli.compare_commands import _contenders
from sysid.evaluation.divergence import PhysicalRange
from sysid.evaluation.evaluate import evaluate_model
from sysid.hybrid.force_models import build_model
from sysid.hybrid.knn_gate import KNNGate
from sysid.protocol.reproduce import protocol_experiment
from sysid.runs.layout import write_run
from sysid.runs.rundir import RunDir
from tests.support.synthetic_rundir import measured_runs


def test_a_named_ship_file_is_judged_against_the_runs_training_range(tmp_path):
    """A hybrid run records its training range in summary.json: its ship file's MMG, added by
    compare or named by the user, diverges beyond 3 x that range (named, it was judged on
    non-finite states alone)."""
    exp = protocol_experiment("hybrid_D2").replace(evaluation={"horizons": (30.0,)})
    tests = list(measured_runs(scale=0.5).values())
    limits = PhysicalRange.of_runs(tests)
    model = build_model(exp)
    torch.manual_seed(0)
    model.gate = KNNGate(3, 0.9, model.gate_width, torch.float64).fit(torch.randn(50, model.gate_width,
                                                                                dtype=torch.float64))
    run = tmp_path / "hybrid"
    write_run(run, exp, model, evaluate_model(model, tests, (30.0,), traces=False), limits=limits)
    recorded = PhysicalRange.of_summary(RunDir(run).read_summary())
    assert recorded == limits
    added = {c.label: c for c in _contenders([str(run)])}
    named = {c.label: c for c in _contenders([str(run), exp.experiment.ship])}
    assert added["MMG (ship file)"].limits == recorded
    ship = next(c for label, c in named.items() if c.kind == "mmg")
    assert ship.label == named["hybrid"].baseline and ship.limits == recorded


def test_a_sweeps_point_folder_is_named_by_its_kind_and_seeds_not_by_its_point(tmp_path):
    """A seeds-only sweep writes its seeds to trials/base/seed{k}: compare names that folder
    "Hybrid (2 seeds)" (it said "base"), a varied point's "Hybrid lr=0.003 (2 seeds)"; a
    folder of seeds outside a sweep keeps its own name, and so does a folder named trials/
    in a directory that is no sweep."""
    exp = protocol_experiment("hybrid_D2").replace(evaluation={"horizons": (30.0,)})
    tests = list(measured_runs(scale=0.5).values())
    model = build_model(exp)
    torch.manual_seed(0)
    model.gate = KNNGate(3, 0.9, model.gate_width, torch.float64).fit(torch.randn(50, model.gate_width,
                                                                                dtype=torch.float64))
    metrics = evaluate_model(model, tests, (30.0,), traces=False)
    sweep, other = tmp_path / "sweeps" / "seeds", tmp_path / "notasweep"
    folders = [sweep / "trials" / "base", sweep / "trials" / "lr=0.003", tmp_path / "runs" / "hybrid_seeds",
               other / "trials" / "base"]
    for folder in folders:
        for k in (0, 1):
            write_run(folder / f"seed{k}", exp, model, metrics)
    (sweep / "sweep.json").write_text("{}")
    labels = [c.label for c in _contenders([str(f) for f in folders])]
    assert labels == ["Hybrid (2 seeds)", "Hybrid lr=0.003 (2 seeds)", "hybrid_seeds", "base",
                      "MMG (ship file)"]
