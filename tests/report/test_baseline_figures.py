"""A single learned run's report shows its physics baseline beside it: the baseline's traces
that `sysid train` stores (baseline_traces/) are the ship file's MMG on the run's own windows,
and the error, state and trajectory figures draw them, named in legend and caption."""
from __future__ import annotations

import re

import numpy as np
import pytest
import torch

from sysid import MMG, load_ship
from sysid.data.recordings import read_runs
from sysid.evaluation.evaluate import predict_windows
from sysid.evaluation.verdict import SHIP_FILE_MMG
from sysid.records.summary import RunSummary
from sysid.report import build_report
from sysid.report.build import ship_size
from sysid.report.figure_plan import baseline_label, figure_plan
from sysid.report.source import read_source
from sysid.runs.rundir import RunDir


@pytest.fixture(scope="module")
def plan(trained):
    source = read_source(trained)
    return figure_plan(source, ship_size(source))


def _pooled_rmse(frame) -> np.ndarray:
    """RMSE of u, v_m [m/s] and r [rad/s] pooled over every point of a trace's windows."""
    return np.array([np.sqrt(np.mean((frame[f"pred_{c}"] - frame[f"obs_{c}"]) ** 2)) for c in "uvr"])


def _traces_of(spec):
    return spec.factory.args[0]   # every trace figure's factory: partial(figure, traces, ...)


def test_the_baseline_in_the_figures_is_the_ship_file_mmg_on_the_same_windows(trained, plan, files):
    """The error figure's baseline trace: its pooled RMSE equals baseline_metrics.csv, and
    equals the ship file's MMG predicted independently on the run's test log; its windows
    start where the learned model's do."""
    box = next(f for f in plan.figures if f.key.startswith("box_"))
    model, base = _traces_of(box)
    assert (model.baseline, base.baseline) == (False, True)
    assert base.label == baseline_label(SHIP_FILE_MMG)

    recorded = RunDir(trained).read_baseline_metrics()
    row = recorded[(recorded.baseline == SHIP_FILE_MMG) & ((recorded.horizon_s - 30.0).abs() < 0.5)].iloc[0]
    np.testing.assert_allclose(_pooled_rmse(base.frame), row[["rmse_u", "rmse_v", "rmse_r"]].to_numpy(float),
                               rtol=1e-4)

    summary = RunSummary.read(RunDir(trained).summary)
    ship = load_ship(RunDir(trained).ship_copy(summary.ship))
    (pred,) = predict_windows(MMG(ship).double(), read_runs([files["test"]]), 30.0)
    np.testing.assert_allclose(_pooled_rmse(base.frame), pred.rmse(), rtol=1e-5)
    assert not torch.allclose(pred.predicted, pred.observed)   # the baseline predicts: it is not the record
    np.testing.assert_allclose(base.frame.groupby("window")["t"].min().to_numpy(),
                               model.frame.groupby("window")["t"].min().to_numpy())
    np.testing.assert_allclose(base.frame["obs_u"].to_numpy(), model.frame["obs_u"].to_numpy())


def test_every_trace_figure_draws_the_baseline(plan):
    """Error, state and trajectory figures hold the learned model and its baseline."""
    keyed = [f for f in plan.figures if f.key.split("_")[0] in ("box", "inputs", "states", "track")]
    assert {f.key.split("_")[0] for f in keyed} >= {"box", "states"}, [f.key for f in plan.figures]
    for spec in keyed:
        assert [t.baseline for t in _traces_of(spec)] == [False, True], spec.key
        assert f"physics baseline {SHIP_FILE_MMG}" in spec.caption, spec.caption


def test_the_report_names_the_baseline_in_captions_and_legends(trained, tmp_path):
    from html import unescape

    paths = build_report(trained, tmp_path / "report")
    html = unescape(paths.html.read_text())
    figures = re.findall(r"<figure.*?</figure>", html, flags=re.S)
    errors = [f for f in figures if "Absolute error" in f]
    assert errors
    for figure in errors:
        caption = re.search(r"<figcaption>(.*?)</figcaption>", figure, flags=re.S).group(1)
        assert "Hatched grey: the learned model's physics baseline MMG (ship file)" in caption
        assert baseline_label(SHIP_FILE_MMG) in figure   # the legend's text (SVG text kept as text)
    assert not [n for n in paths.notes if "physics baseline" in n or "failed" in n], paths.notes


def test_a_run_without_baseline_traces_says_so(trained, tmp_path):
    """A run written before sysid kept its baseline's traces: drawn alone, with a note."""
    import shutil

    from sysid.store.manifest import write_manifest

    old = tmp_path / "old"
    shutil.copytree(trained, old)
    shutil.rmtree(old / "baseline_traces")
    write_manifest(old, "run")
    source = read_source(old)
    plan = figure_plan(source, ship_size(source))
    box = next(f for f in plan.figures if f.key.startswith("box_"))
    assert [t.baseline for t in _traces_of(box)] == [False]
    assert "physics baseline" not in box.caption
    assert any("baseline_traces/" in n for n in plan.notes), plan.notes
