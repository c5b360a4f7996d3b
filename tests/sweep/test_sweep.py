"""Sweeps: sweep files are checked before anything runs; a tiny sweep on local Ray is
killed part-way, resumed, and no trial is trained twice."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

from sysid.errors import ConfigError

from sysid.sweep import load_sweep
from sysid.sweep.plan import sweep_trials
from sysid.sweep.points import point_name, sweep_points
from sysid.sweep.inbox import read_journal
from tiny_experiment import tiny_experiment


def _base(tmp_path, dataset_dir) -> str:
    return tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=4, warm_start_epochs=3).name


def _sweep(tmp_path, dataset_dir, body: str) -> object:
    path = tmp_path / "sweep.toml"
    path.write_text(f"[sweep]\nbase = '{_base(tmp_path, dataset_dir)}'\n" + body)
    return path


@pytest.mark.parametrize("body, message", [
    ("[vary]\n'training.learning_rat' = [1e-3]\n", "'training.learning_rat': not an experiment option"),
    ("[vary]\n'training.learning_rate' = [1e-3, -1.0]\n", "learning_rate must be > 0"),
    ("[vary]\n'training.learning_rate' = { loguniform = [1e-4, 1e-2] }\n", "needs search = \"random\""),
    ("search = 'random'\n[vary]\n'training.lambda_F' = { loguniform = [0.0, 1.0] }\n", "low > 0"),
    ("seeds = [0, 0]\n", "seeds must be a list of distinct integers"),
    ("objective = 'test_rmse'\n", "never used to choose"),
    ("[vary]\n'experiment.seed' = [1, 2]\n", "set seeds with [sweep] seeds"),
])
def test_bad_sweep_files_name_the_file_and_key(tmp_path, dataset_dir, body, message):
    path = _sweep(tmp_path, dataset_dir, body)
    with pytest.raises(ConfigError) as err:
        load_sweep(path)
    assert str(path) in str(err.value) and message in str(err.value)


def test_grid_and_random_points(tmp_path, dataset_dir):
    grid = load_sweep(_sweep(tmp_path, dataset_dir, "seeds = [0, 3]\n[vary]\n'training.learning_rate' = [1e-3, 3e-3]\n"
                                                   "'network.hidden' = [[64, 64], [128, 128]]\n"))
    trials = sweep_trials(grid)
    assert len(trials) == 8 and {t.seed for t in trials} == {0, 3}
    assert trials[0].path == "trials/learning_rate=0.001,hidden=64x64/seed0"
    assert "hidden = [128, 128]" in trials[-1].config and "seed = 3" in trials[-1].config
    assert "threads = 1" in trials[0].config  # one torch thread per trial
    rand = load_sweep(_sweep(tmp_path, dataset_dir, "search = 'random'\nsamples = 5\nsearch_seed = 7\n[vary]\n"
                                                   "'training.lambda_F' = { loguniform = [1e-3, 1e-1] }\n"))
    a, b = sweep_points(rand), sweep_points(rand)
    assert a == b and len(a) == 5  # the same draws on every run: resumable
    values = [p["training.lambda_F"] for p in a]
    assert all(1e-3 <= v <= 1e-1 for v in values) and len(set(values)) == 5
    assert point_name({"training.lambda_F": 0.0123456}) == "lambda_F=0.0123456"


def _sysid(*args, **kwargs):
    return subprocess.Popen([sys.executable, "-m", "sysid", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, **kwargs)


def _wait_for_a_trained_trial(proc, out, timeout: float = 300.0) -> None:
    """Until the sweep `proc` writing `out` has trained one trial; it must still be running."""
    deadline = time.time() + timeout
    while time.time() < deadline and proc.poll() is None:
        if any(e["event"] == "trained" for e in read_journal(out)):
            break
        time.sleep(0.5)
    assert proc.poll() is None, proc.communicate()[0][-2000:]


@pytest.mark.slow
def test_sweep_killed_part_way_resumes_without_training_a_trial_twice(tmp_path, dataset_dir):
    pytest.importorskip("ray.tune")
    path = _sweep(tmp_path, dataset_dir, "seeds = [0, 1]\nmax_retries = 1\n[vary]\n"
                                         "'training.learning_rate' = [1e-3, 3e-3]\n")
    out = tmp_path / "sweep"
    env = {**os.environ, "SYSID_DATA": str(dataset_dir.parent)}
    # one trial at a time, so that the kill after the first trained trial lands with trials left
    # (two workers can finish both points' trials, two seeds each side by side, within one poll)
    first = _sysid("sweep", str(path), "-o", str(out), "--workers", "1", env=env, start_new_session=True)
    _wait_for_a_trained_trial(first, out)
    os.killpg(first.pid, signal.SIGKILL)  # the whole sweep, Ray's workers too
    first.wait()
    trained_before = [e["trial"] for e in read_journal(out) if e["event"] == "trained"]
    assert 1 <= len(trained_before) < 4
    assert not (out / "results.csv").exists()

    second = _sysid("sweep", str(path), "-o", str(out), "--resume", "--workers", "2", env=env)
    log = second.communicate(timeout=600)[0]
    assert second.returncode == 0, log[-3000:]
    assert "4/4 trials complete" in log
    assert not (out / ".locks").exists()  # the runner removes the trial locks when all are over

    events = read_journal(out)
    trained = [e["trial"] for e in events if e["event"] == "trained"]
    assert sorted(trained) == sorted(set(trained)) and len(trained) == 4  # none twice
    reused = {e["trial"] for e in events if e["event"] == "reused"}
    assert set(trained_before) <= reused
    table = pd.read_csv(out / "results.csv")
    assert len(table) == 4 and set(table.status) == {"complete"}
    assert table.val_loss_multistep.map(math.isfinite).all()
    assert sorted(table.seed) == [0, 0, 1, 1]
    summary = json.loads((out / "sweep.json").read_text())
    points = pd.read_csv(out / "points.csv")
    assert summary["best"]["point"] == points.point.iloc[0]
    assert summary["best"]["val_loss_multistep_mean"] == pytest.approx(points.val_loss_multistep_mean.min(), rel=1e-5)
    best = table[table.point == summary["best"]["point"]].val_loss_multistep.mean()
    assert summary["best"]["val_loss_multistep_mean"] == pytest.approx(best, rel=1e-5)

    # every trial is an ordinary run directory
    from sysid.runs.layout import load_model
    exp, model = load_model(out / table.run.iloc[0])
    assert exp.experiment.seed == table.seed.iloc[0] and exp.training.threads == 1
    # the sweep's report: objective against the keys, seed spread, the chosen configuration
    from sysid.report import build_report
    html = build_report(out, tmp_path / "report").html.read_text()
    assert "val_loss_multistep against the varied keys" in html and "Spread over 2 seeds" in html
    # page 1: the chosen configuration's verdict over its 2 seeds (their validation blocks differ: each
    # log's windows of both seeds pooled as one model's), with the seeds' spread of the RMSE
    assert html.index('id="verdict"') < html.index('id="summary"')
    verdict = html[html.index('id="verdict"'):html.index('id="summary"')]
    assert "2 seeds&#39; windows pooled" in verdict or "2 seeds' windows pooled" in verdict, verdict
    # per log and channel, the RMSE over both seeds' windows, named as the 2 seeds' (not the first seed's)
    assert "Hybrid (2 seeds) RMSE" in verdict and verdict.count("validation (decides)") >= 3
    assert "Chosen" in html and summary["best"]["point"] in html
    # the resumed sweep refuses another sweep file
    path.write_text(path.read_text().replace("3e-3", "5e-3"))
    again = _sysid("sweep", str(path), "-o", str(out), "--resume", env=env)
    text = again.communicate(timeout=120)[0]
    assert again.returncode == 2 and "differs from" in text


@pytest.mark.slow
def test_ctrl_c_during_the_trials_ends_the_sweep_as_interrupted(tmp_path, dataset_dir):
    """Tune catches SIGINT and returns with trials pending: sysid must not take that for a
    finished sweep (no results, no summary; exit 130 and the --resume note)."""
    pytest.importorskip("ray.tune")
    path = _sweep(tmp_path, dataset_dir, "seeds = [0, 1]\n[vary]\n'training.learning_rate' = [1e-3, 3e-3]\n")
    out = tmp_path / "sweep"
    env = {**os.environ, "SYSID_DATA": str(dataset_dir.parent)}
    sweep = _sysid("sweep", str(path), "-o", str(out), "--workers", "1", env=env, start_new_session=True)
    _wait_for_a_trained_trial(sweep, out)
    os.kill(sweep.pid, signal.SIGINT)  # Ctrl-C reaches the driver
    log = sweep.communicate(timeout=300)[0]
    assert sweep.returncode == 130, log[-3000:]
    assert "interrupted" in log
    assert not (out / "results.csv").exists() and not (out / "sweep.json").exists()


def test_shipped_sweep_files_are_valid():
    from pathlib import Path
    root = Path(__file__).resolve().parents[2] / "configs" / "sweeps"
    files = sorted(root.glob("*.toml"))
    assert files
    for path in files:
        spec = load_sweep(path)
        assert spec.objective == "val_loss_multistep" and len(spec.seeds) >= 2 and sweep_trials(spec)


def test_two_trainings_of_one_trial_train_it_once(tmp_path, dataset_dir):
    """Optuna can propose a configuration twice while it trains: the second training waits
    at the inbox's claim and reuses the first one's run instead of training it again."""
    import threading
    from sysid.data.datasets import data_root
    from sysid.config.experiment import load_experiment
    from sysid.sweep.inbox import RunInbox
    from sysid.sweep.trial import TrialSpec, read_trial_data, run_trial
    import sysid.sweep.trial as trial_module

    path = tiny_experiment(tmp_path / "t.toml", dataset_dir, seed=0, epochs=3, warm_start_epochs=2)
    exp = load_experiment(path)
    data = read_trial_data([exp], data_root())
    out = tmp_path / "out"
    inbox = RunInbox(str(out))
    trial = TrialSpec("trials/p/seed0", "p", 0, exp.to_toml())
    trial_module.CLAIM_POLL_S = 0.2
    rows = {}

    def train(holder):
        rows[holder] = run_trial(trial, inbox, data, holder)
    threads = [threading.Thread(target=train, args=(h,)) for h in ("tune-a", "tune-b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=600)
    events = sorted(e["event"] for e in read_journal(out))
    assert events == ["reused", "started", "trained"]
    assert rows["tune-a"]["val_loss_multistep"] == rows["tune-b"]["val_loss_multistep"] and rows["tune-a"]["status"] == "complete"
    assert (out / "trials" / "p" / "seed0" / "summary.json").is_file() and not inbox.claims


def test_a_sweep_failing_before_its_first_trial_leaves_no_output(tmp_path, dataset_dir, monkeypatch):
    from contextlib import contextmanager
    import sysid.sweep.study as study
    from sysid.sweep.runner import Session

    @contextmanager
    def session(out, workers, address, log, *lost):  # Ray up, as far as the sweep can tell
        yield Session(None, "inbox", 1)

    def tune_fails(*args, **kwargs):
        raise RuntimeError("Tune could not start")
    monkeypatch.setattr(study, "ray_session", session)
    monkeypatch.setattr(study, "run_trials", tune_fails)
    spec = load_sweep(_sweep(tmp_path, dataset_dir, "[vary]\n'training.learning_rate' = [1e-3]\n"))
    for out in (tmp_path / "new", tmp_path / "empty"):
        if out.name == "empty":
            out.mkdir()
        with pytest.raises(RuntimeError, match="Tune could not start"):
            study.run_sweep(spec, out, workers=1, data=dataset_dir.parent, log=lambda m: None)
        assert (not out.exists()) if out.name == "new" else (out.is_dir() and not any(out.iterdir()))


class _KilledAfter:
    """A `RunInbox` whose driver dies (KeyboardInterrupt) once it holds the checkpoint of
    epoch `epochs` of a trial."""

    def __init__(self, out, epochs: int):
        from sysid.sweep.inbox import RunInbox
        self.inbox, self.left = RunInbox(str(out)), epochs

    def __getattr__(self, name):
        return getattr(self.inbox, name)

    def save_checkpoint(self, path, holder, blob):
        kept = self.inbox.save_checkpoint(path, holder, blob)
        self.left -= 1
        if self.left == 0:
            raise KeyboardInterrupt
        return kept


def test_a_sweep_moved_with_its_project_resumes_its_interrupted_trial(tmp_path, dataset_dir):
    """A sweep inside its project (``-o out``), its driver killed after a trial's second
    epoch, the whole project folder moved (the original gone): resuming the moved sweep
    continues that trial from its checkpoint (journal: resumed after 2 epochs; the trial's
    config now names the logs by their new paths) to the history of an uninterrupted trial,
    and the finished run finds its logs in the moved project."""
    import shutil
    from sysid.data.datasets import data_root
    from sysid.runs.rundir import RunDir
    from sysid.sweep.inbox import RunInbox
    from sysid.sweep.study import write_output
    from sysid.sweep.trial import read_trial_data, run_trial
    from own_sweep import own_sweep_project

    def trial_of(project):
        spec = load_sweep(project / "own.toml")
        trial = sweep_trials(spec)[0]
        return spec, trial, read_trial_data([spec.base], data_root())

    origin = tmp_path / "a" / "project"
    own_sweep_project(origin, dataset_dir, epochs=4)
    spec, trial, data = trial_of(origin)
    write_output(spec, origin / "out", resume=False)
    with pytest.raises(KeyboardInterrupt):
        run_trial(trial, _KilledAfter(origin / "out", 2), data, "tune-a")
    moved = shutil.copytree(origin, tmp_path / "b" / "moved")
    shutil.rmtree(origin)

    spec, trial, data = trial_of(moved)
    assert str(moved / "my logs" / "harbour_0.csv") in trial.config
    row = run_trial(trial, RunInbox(str(moved / "out")), data, "tune-b")
    events = read_journal(moved / "out")
    assert [(e["event"], e.get("after_epochs")) for e in events] == [("started", None), ("resumed", 2),
                                                                        ("trained", None)]
    whole = run_trial(trial, RunInbox(str(tmp_path / "whole")), data, "tune-c")   # never interrupted
    run = moved / "out" / trial.path
    assert row["status"] == "complete" and row["val_loss_multistep"] == whole["val_loss_multistep"]
    history = [pd.read_csv(r / "history.csv").drop(columns="seconds") for r in (run, tmp_path / "whole" / trial.path)]
    assert len(history[0]) == 4 and history[0].equals(history[1])   # the 4 epochs alike
    assert RunDir.open(run).read_experiment().data.train == tuple(
        str(moved / "my logs" / f"harbour_{i}.csv") for i in (0, 1))
