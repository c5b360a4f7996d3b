"""``sysid sweep --resume`` of an Optuna sweep unpickles nothing from the output directory:
the search resumes from sysid's own verified run directories, so a crafted pickle where
Tune keeps its state runs no code."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from sysid.sweep import load_sweep
from sysid.sweep.plan import make_trial
from tiny_experiment import tiny_experiment, tiny_test_file

ROOT = Path(__file__).resolve().parents[2]


class Touch:
    """Unpickling this creates `path` (what a crafted file in a shared folder could do)."""

    def __init__(self, path: Path):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (self.path,))


def test_a_crafted_pickle_in_the_output_is_never_loaded(tmp_path, dataset_dir):
    pytest.importorskip("optuna")
    from sysid.config.experiment import parse_experiment
    from sysid.data.recordings import read_run
    from sysid.runs.lifecycle import run_experiment
    import tomllib

    tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=2, warm_start_epochs=1)
    sweep_file = tmp_path / "sweep.toml"
    sweep_file.write_text("[sweep]\nbase = 'base.toml'\nsearch = 'optuna'\nsamples = 1\nseeds = [0]\n"
                          "[vary]\n'training.learning_rate' = { loguniform = [1e-3, 1e-2] }\n")
    spec = load_sweep(sweep_file)
    out = tmp_path / "sweep"
    # the state an interrupted sweep leaves: its sweep file, base and one finished trial
    out.mkdir()
    (out / "sweep.toml").write_text(spec.text)
    (out / "base.toml").write_text(spec.base.to_toml())
    trial = make_trial(spec, {"training.learning_rate": 0.002}, 0)
    exp = parse_experiment(tomllib.loads(trial.config), "test")
    run_experiment(exp, out / trial.path, [read_run(tiny_test_file(dataset_dir))], progress=False,
                   log=lambda m: None)
    # and pickles where Ray Tune keeps (and Tuner.restore loads) its search state
    marker = tmp_path / "code-ran"
    probe = tmp_path / "probe"
    pickle.loads(pickle.dumps(Touch(probe)))
    assert probe.exists()  # the crafted pickle does run code when loaded
    tune_dir = out / "tune"
    tune_dir.mkdir()
    for name in ("tuner.pkl", "searcher-state-2026-01-01_00-00-00.pkl", "search_gen_state-x.pkl",
                 "basic-variant-state-x.pkl", "trainable.pkl"):
        (tune_dir / name).write_bytes(pickle.dumps(Touch(marker)))
    (tune_dir / "experiment_state-2026-01-01_00-00-00.json").write_text('{"trial_data": []}')

    env = {**os.environ, "PYTHONPATH": str(ROOT), "SYSID_DATA": str(dataset_dir.parent)}
    proc = subprocess.run([sys.executable, "-m", "sysid", "sweep", str(sweep_file), "-o", str(out), "--resume"],
                          capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert not marker.exists()
    said = [line for line in proc.stdout.splitlines() if "search state is not read" in line]
    assert len(said) == 1 and "1 finished configurations" in said[0]
    table = pd.read_csv(out / "results.csv")
    assert list(table.status) == ["complete"] and table["training.learning_rate"].iloc[0] == 0.002


@pytest.mark.slow
def test_an_optuna_sweep_resumed_on_ray_loads_no_pickle(tmp_path, dataset_dir):
    """A finished Optuna sweep loses one configuration's run (as an interruption would leave
    it) and Tune's state is replaced by crafted pickles: --resume trains the missing
    configuration on Ray, tells Optuna the finished one, and runs no code from the folder."""
    pytest.importorskip("optuna")
    pytest.importorskip("ray.tune")
    import shutil

    tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=2, warm_start_epochs=1)
    sweep_file = tmp_path / "sweep.toml"
    sweep_file.write_text("[sweep]\nbase = 'base.toml'\nsearch = 'optuna'\nsamples = 2\nseeds = [0]\n"
                          "[vary]\n'training.learning_rate' = { loguniform = [1e-3, 1e-2] }\n")
    out = tmp_path / "sweep"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SYSID_DATA": str(dataset_dir.parent)}
    env.pop("RAY_ADDRESS", None)
    # the first sweep's two trials side by side
    first = subprocess.run([sys.executable, "-m", "sysid", "sweep", str(sweep_file), "-o", str(out), "--workers", "2"],
                           capture_output=True, text=True, timeout=1200, env=env)
    assert first.returncode == 0, first.stdout[-3000:] + first.stderr[-3000:]
    runs = sorted((out / "trials").glob("*/seed0"))
    assert len(runs) == 2
    shutil.rmtree(runs[1].parent)
    marker = tmp_path / "code-ran"
    for path in (out / "tune").rglob("*.pkl"):
        path.write_bytes(pickle.dumps(Touch(marker)))
    assert list((out / "tune").glob("*.pkl"))  # Tune did keep pickles there
    second = subprocess.run([sys.executable, "-m", "sysid", "sweep", str(sweep_file), "-o", str(out), "--resume",
                             "--workers", "1"], capture_output=True, text=True, timeout=1200, env=env)
    assert second.returncode == 0, second.stdout[-3000:] + second.stderr[-3000:]
    assert not marker.exists()
    assert "optuna resumes from 1 finished configurations" in second.stdout
    table = pd.read_csv(out / "results.csv")
    assert len(table) == 2 and set(table.status) == {"complete"}
    assert runs[0].parent.name in set(table.point)  # the finished one is kept, one new one trained
