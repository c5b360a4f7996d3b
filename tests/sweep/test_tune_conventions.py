"""Tune as Ray users know it, on a local Ray: every trial reports its validation loss every
epoch (``tune.ExperimentAnalysis`` on the output reads it back, equal to the runs' own
history.csv); ASHA stops a poor trial early (fewer epochs, same best); MLflow holds the
sweep and its trials, and ``sysid train --mlflow`` a run."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from tiny_experiment import tiny_experiment, tiny_test_file

ROOT = Path(__file__).resolve().parents[2]
CSV = 1e-5   # history.csv keeps 6 significant digits
EPOCHS = 3
GOOD, POOR = 3e-3, 1e-6   # learning rates: the poor one barely moves from the warm start


def _start(args: list[str], dataset_dir: Path, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SYSID_DATA": str(dataset_dir.parent), "SYSID_COMPILE": "0"}
    env.pop("RAY_ADDRESS", None)
    return subprocess.Popen([sys.executable, "-m", "sysid", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=cwd)


def _finish(proc: subprocess.Popen) -> str:
    """`proc`'s standard output, once it has exited with 0."""
    out, err = proc.communicate(timeout=1200)
    assert proc.returncode == 0, out[-3000:] + err[-3000:]
    return out


def _sysid(args: list[str], dataset_dir: Path, cwd: Path) -> str:
    return _finish(_start(args, dataset_dir, cwd))


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory, dataset_dir):
    """The same two-configuration sweep without a scheduler (tracked in MLflow) and with
    ASHA (Tune's experiment in --storage); one trial at a time, the good configuration first.
    The two sweeps run side by side, each on its own local Ray."""
    pytest.importorskip("ray.tune")
    pytest.importorskip("mlflow")
    tmp = tmp_path_factory.mktemp("tune")
    tiny_experiment(tmp / "base.toml", dataset_dir, seed=0, epochs=EPOCHS, warm_start_epochs=1)
    body = f"[sweep]\nbase = 'base.toml'\nseeds = [0]\n[vary]\n'training.learning_rate' = [{GOOD}, {POOR}]\n"
    (tmp / "plain.toml").write_text(body)
    (tmp / "asha.toml").write_text(body.replace("seeds = [0]\n", "seeds = [0]\nscheduler = 'asha'\n")
                                   + "[scheduler]\ngrace_period = 1\nreduction_factor = 2\n")
    running = {name: _start(["sweep", str(tmp / f"{name}.toml"), "-o", str(tmp / name), "--workers", "1", *extra],
                            dataset_dir, tmp)
               for name, extra in (("plain", ["--mlflow", str(tmp / "mlruns")]),
                                   ("asha", ["--storage", str(tmp / "store")]))}
    try:
        return tmp, {name: _finish(proc) for name, proc in running.items()}
    finally:
        for proc in running.values():
            if proc.poll() is None:
                proc.kill()


@pytest.mark.slow
def test_every_epoch_is_in_tune_experiment_analysis(sweeps):
    from ray import tune

    tmp, _ = sweeps
    out = tmp / "plain"
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["tune"] == "tune"   # inside the sweep directory: relative to it
    analysis = tune.ExperimentAnalysis(str(out / "tune"))
    frames = analysis.trial_dataframes
    assert len(frames) == 2
    for trial in analysis.trials:
        run = out / "trials" / f"learning_rate={trial.config['training__learning_rate']!r}" / "seed0"
        history = pd.read_csv(run / "history.csv")
        epochs = frames[trial.trial_id].dropna(subset=["epoch"])
        assert list(epochs.val_loss_multistep) == pytest.approx(list(history.early_stopping_loss), rel=CSV)
        assert list(epochs.training_iteration) == list(range(1, len(history) + 1))
        final = frames[trial.trial_id].final.fillna(False).astype(bool)
        assert final.sum() == 1 and frames[trial.trial_id][final].val_loss_multistep.iloc[0] == pytest.approx(
            json.loads((run / "summary.json").read_text())["val_loss_multistep"], rel=1e-12)
    best = analysis.get_best_config(metric="val_loss_multistep", mode="min", scope="last")
    assert best["training__learning_rate"] == summary["best"]["values"]["training.learning_rate"]


@pytest.mark.slow
def test_tuner_restore_gets_the_results(sweeps):
    import ray
    from ray import tune
    from sysid.sweep.trial import tune_trainable

    tmp, _ = sweeps
    out = tmp / "plain"
    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        grid = tune.Tuner.restore(str(out / "tune"), trainable=tune_trainable).get_results()
        best = grid.get_best_result(metric="val_loss_multistep", mode="min", scope="last")
    finally:
        ray.shutdown()
    assert len(grid) == 2 and all(len(r.metrics_dataframe) == EPOCHS + 1 for r in grid)
    summary = json.loads((out / "sweep.json").read_text())
    assert best.config["training__learning_rate"] == summary["best"]["values"]["training.learning_rate"]
    assert best.metrics["val_loss_multistep"] == pytest.approx(summary["best"]["val_loss_multistep_mean"], rel=1e-12)


@pytest.mark.slow
def test_asha_stops_the_poor_trial_early_with_the_same_best(sweeps):
    from ray import tune

    tmp, logs = sweeps
    epochs = {}
    assert json.loads((tmp / "asha" / "sweep.json").read_text())["tune"] == str(tmp / "store" / "asha")
    for name, where in (("plain", tmp / "plain" / "tune"), ("asha", tmp / "store" / "asha")):
        frames = tune.ExperimentAnalysis(str(where)).trial_dataframes.values()
        epochs[name] = sum(int(f.epoch.notna().sum()) for f in frames)
    assert epochs["plain"] == 2 * EPOCHS and epochs["asha"] < epochs["plain"]
    plain, asha = (json.loads((tmp / n / "sweep.json").read_text()) for n in ("plain", "asha"))
    assert asha["best"]["point"] == plain["best"]["point"] == f"learning_rate={GOOD!r}"
    assert asha["best"]["val_loss_multistep_mean"] == plain["best"]["val_loss_multistep_mean"]
    assert (asha["complete"], asha["stopped_early"]) == (1, 1) and (plain["complete"], plain["stopped_early"]) == (2, 0)
    table = pd.read_csv(tmp / "asha" / "results.csv").set_index("point")
    assert table.loc[f"learning_rate={POOR!r}", "status"] == "stopped early"
    assert "stopped early trials/learning_rate=1e-06/seed0" in logs["asha"]
    assert "1/2 trials complete, 1 stopped early by the asha scheduler" in logs["asha"]


@pytest.mark.slow
def test_the_sweep_and_its_trials_are_one_mlflow_experiment(sweeps, monkeypatch):
    import mlflow

    monkeypatch.setenv("MLFLOW_ALLOW_FILE_STORE", "true")  # MLflow 3 reads file stores only when asked

    tmp, _ = sweeps
    out = tmp / "plain"
    mlflow.set_tracking_uri((tmp / "mlruns").as_uri())
    runs = mlflow.search_runs(experiment_names=["plain"])
    parent = runs[runs["tags.sysid.kind"] == "sweep"]
    children = runs[runs["tags.mlflow.parentRunId"] == parent.run_id.iloc[0]]
    assert len(parent) == 1 and len(children) == 2 and set(runs.status) == {"FINISHED"}
    client = mlflow.tracking.MlflowClient()
    for _, child in children.iterrows():
        run = out / child["tags.mlflow.runName"]
        history = pd.read_csv(run / "history.csv")
        logged = sorted(client.get_metric_history(child.run_id, "val_loss"), key=lambda m: m.step)
        assert [m.value for m in logged] == pytest.approx(list(history.early_stopping_loss), rel=CSV)
        summary = json.loads((run / "summary.json").read_text())
        assert client.get_run(child.run_id).data.metrics["final_val_loss"] == pytest.approx(summary["val_loss_multistep"], rel=1e-12)
        # a sweep scores on no test file: no test RMSE to log, none logged
        assert pd.read_csv(run / "metrics.csv").empty
        assert not [k for k in client.get_run(child.run_id).data.metrics if k.startswith("rmse_")]
        artifacts = {a.path for a in client.list_artifacts(child.run_id, "run")}
        assert {"run/summary.json", "run/model.pt", "run/manifest.json"} <= artifacts
    assert parent["metrics.complete"].iloc[0] == 2


@pytest.mark.slow
def test_a_trained_run_is_logged_to_mlflow(tmp_path, dataset_dir, monkeypatch):
    mlflow = pytest.importorskip("mlflow")
    monkeypatch.setenv("MLFLOW_ALLOW_FILE_STORE", "true")  # MLflow 3 reads file stores only when asked
    config = tiny_experiment(tmp_path / "t.toml", dataset_dir, seed=0, epochs=3, warm_start_epochs=1)
    run = tmp_path / "run"
    store = tmp_path / "store"
    zigzag = dataset_dir / "zigzag" / "zigzag_31-Jul-2020_13_57_45.csv"   # not a paper test file
    _sysid(["train", str(config), "-o", str(run), "--test", str(tiny_test_file(dataset_dir)), "--test", str(zigzag),
            "--mlflow", str(store)], dataset_dir, tmp_path)
    mlflow.set_tracking_uri(store.as_uri())
    runs = mlflow.search_runs(experiment_names=["tiny"])
    assert len(runs) == 1 and runs.status.iloc[0] == "FINISHED" and runs["tags.mlflow.runName"].iloc[0] == "run"
    summary = json.loads((run / "summary.json").read_text())
    assert runs["metrics.final_val_loss"].iloc[0] == pytest.approx(summary["val_loss_multistep"], rel=1e-12)
    resolved = tomllib.loads((run / "config.toml").read_text())
    assert runs["params.training.learning_rate"].iloc[0] == str(resolved["training"]["learning_rate"])
    assert runs["params.experiment.seed"].iloc[0] == "0"
    client = mlflow.tracking.MlflowClient()
    logged = sorted(client.get_metric_history(runs.run_id.iloc[0], "train_loss"), key=lambda m: m.step)
    assert [m.value for m in logged] == pytest.approx(list(pd.read_csv(run / "history.csv").train_loss), rel=CSV)
    assert {a.path for a in client.list_artifacts(runs.run_id.iloc[0], "run")} >= {"run/model.pt", "run/config.toml"}
    # every test log its own key: scenario (the paper's name, or the maneuver recognised), log, horizon
    metrics = pd.read_csv(run / "metrics.csv")
    assert dict(zip(metrics.file, metrics.scenario)) == {"berthing_12-Nov-2020_11_49_21": "Berthing",
                                                          "zigzag_31-Jul-2020_13_57_45": "Zigzag 20/20"}
    for row in metrics.itertuples():
        key = f"metrics.rmse_r/{row.scenario}/{row.file}/30s"
        assert runs[key].iloc[0] == pytest.approx(row.rmse_r, rel=1e-12)
