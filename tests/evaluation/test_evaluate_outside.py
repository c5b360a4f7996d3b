"""`sysid evaluate RUN` says how much of each log's prediction lies outside the training data:
the kNN gate's off share per file and horizon (the metrics CSV's ``gate_off_share`` and one
line each), against a brute-force numpy kNN over the run's own feature bank (knn.pt) at the
predicted states; a log with the propeller 1.5 times as fast as recorded is further out."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import torch

from cli_fixtures import sysid  # noqa: F401 (fixture)
from sysid.data.recordings import HEADER, read_run
from sysid.evaluation.evaluate import predict_windows
from sysid.hybrid.correction import correction_inputs
from sysid.mmg.wind import relative_wind
from sysid.runs.layout import load_model


def _brute_force_off_share(run_dir, log, horizon: float) -> float:
    """Share of the window points (start and predicted states) whose mean distance to their
    k nearest bank vectors exceeds the gate's threshold, by numpy over every bank vector."""
    exp, model = load_model(run_dir)
    bank = torch.load(run_dir / "knn.pt", weights_only=True)
    bank = (bank["bank"] if isinstance(bank, dict) else bank).double().numpy()
    pred = predict_windows(model, [read_run(log)], horizon)[0]
    x, u = pred.predicted.reshape(-1, 6), pred.inputs.reshape(-1, 4)
    wind = torch.stack(relative_wind(x[:, 1], x[:, 3], x[:, 4], u[:, 2], u[:, 3]), -1)
    with torch.no_grad():
        z = model.gate_coordinates(correction_inputs(x, u, wind)).double().numpy()
    d = np.sort(np.sqrt(((z[:, None] - bank[None]) ** 2).sum(-1)), 1)[:, :exp.gate.k].mean(1)
    return float((d > float(model.gate.threshold)).mean())


def test_evaluate_states_the_share_outside_the_training_data(sysid, trained, files, tmp_path):  # noqa: F811
    wide = tmp_path / "fast_propeller.csv"
    frame = pd.read_csv(files["test"])
    frame[HEADER["n_prop"]] *= 1.5
    frame.to_csv(wide, index=False)
    out = tmp_path / "metrics.csv"
    outcome = sysid("evaluate", trained, "--data", files["test"], wide, "--horizon", "30", "-o", out)
    assert outcome.code == 0, outcome.err
    table = pd.read_csv(out).set_index("file")
    for log in (files["test"], wide):
        share = table.at[log.stem, "gate_off_share"]
        assert share == pytest.approx(_brute_force_off_share(trained, log, 30.0), abs=1e-6)  # the CSV's 6 digits
        assert f"{log.stem} at 30 s: gate off on {100 * share:.1f} % of the window points" in outcome.out
    assert table.at[wide.stem, "gate_off_share"] > table.at[files["test"].stem, "gate_off_share"]
    assert not math.isnan(table.at[wide.stem, "gate_off_share"])


def test_a_log_shorter_than_the_horizon_has_no_share(sysid, trained, files, tmp_path):  # noqa: F811
    """A log of 50 s beside the 127-s test log holds no window of 100 s: its gate_off_share
    is empty and its line says so (it printed "gate off on nan %"); its 30-s share is the
    brute-force kNN's."""
    short = tmp_path / "short.csv"
    pd.read_csv(files["test"]).iloc[:500].to_csv(short, index=False)   # 10 Hz: 50 s
    out = tmp_path / "metrics.csv"
    outcome = sysid("evaluate", trained, "--data", files["test"], short, "--horizon", "30", "--horizon", "100",
                    "-o", out)
    assert outcome.code == 0, outcome.err
    table = pd.read_csv(out).set_index(["file", "horizon_s"])
    assert table.at[("short", 100.0), "n_windows"] == 0 and math.isnan(table.at[("short", 100.0), "gate_off_share"])
    assert table.at[("short", 30.0), "gate_off_share"] == pytest.approx(
        _brute_force_off_share(trained, short, 30.0), abs=1e-6)
    assert "short at 100 s: no window (the log is shorter than the horizon)" in outcome.out
    assert "nan %" not in outcome.out
