"""Every path in a config resolves against the file that names it, from any working
directory; globs are allowed (real FRT-DS-ESSO logs under new names)."""
from __future__ import annotations

import shutil

import numpy as np

from sysid.config.experiment import DataOptions, load_experiment
from sysid.data.recordings import read_run
from sysid.runs.lifecycle import training_runs
from sysid.sweep import load_sweep

# the training-logs key of [data] (files, or train once the own-logs keys are in)
TRAIN = "train" if "train" in DataOptions.__dataclass_fields__ else "files"
LOGS = {"day1_turn.csv": "turning/turn_14-Oct-2020_14_08_51.csv",
        "day1_zigzag.csv": "zigzag/zigzag_31-Jul-2020_13_22_52.csv",
        "day2_berthing.csv": "berthing/berthing_12-Nov-2020_11_07_23.csv"}


def _project(tmp_path, dataset_dir):
    project = tmp_path / "project"
    (project / "logs").mkdir(parents=True)
    for new, old in LOGS.items():
        shutil.copy(dataset_dir / old, project / "logs" / new)
    shutil.copy(_bundled_ship(), project / "tanker.toml")
    (project / "experiment.toml").write_text(
        f'[experiment]\nmodel = "hybrid"\nship = "tanker.toml"\n[data]\n{TRAIN} = ["logs/day1_*.csv", "logs/day2_berthing.csv"]\n')
    return project


def _bundled_ship():
    from sysid.package_data import bundled_dir
    return bundled_dir("ships") / "esso_osaka.toml"


def test_relative_files_and_globs_resolve_against_the_config_from_another_directory(tmp_path, dataset_dir,
                                                                                    monkeypatch):
    project = _project(tmp_path, dataset_dir)
    elsewhere = tmp_path / "a" / "b"
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    exp = load_experiment(project / "experiment.toml")
    assert exp.experiment.ship == str(project / "tanker.toml")
    runs = training_runs(exp)
    assert [r.name for r in runs] == ["day1_turn", "day1_zigzag", "day2_berthing"]
    for run, new in zip(runs, sorted(LOGS)):  # the same samples as the dataset's own files
        original = read_run(dataset_dir / LOGS[new])
        assert np.array_equal(run.states, original.states) and np.array_equal(run.inputs, original.inputs)
    monkeypatch.chdir(project.parent)  # the same config from its parent folder: the same files
    assert load_experiment("project/experiment.toml").data.train == exp.data.train


def test_sweep_values_resolve_against_the_sweep_file(tmp_path, dataset_dir, monkeypatch):
    project = _project(tmp_path, dataset_dir)
    (tmp_path / "ships").mkdir()
    shutil.copy(_bundled_ship(), tmp_path / "ships" / "other.toml")
    sweeps = tmp_path / "sweeps"
    sweeps.mkdir()
    (sweeps / "s.toml").write_text('[sweep]\nbase = "../project/experiment.toml"\nseeds = [0]\n'
                                   '[set]\n"experiment.ship" = "../ships/other.toml"\n'
                                   f'[vary]\n"data.{TRAIN}" = [["../project/logs/day2_berthing.csv"]]\n')
    monkeypatch.chdir(tmp_path / "ships")
    spec = load_sweep(sweeps / "s.toml")
    assert spec.base.experiment.ship == str(tmp_path / "ships" / "other.toml")
    trial = spec.experiment({f"data.{TRAIN}": ("../project/logs/day2_berthing.csv",)}, 0, "t")
    assert trial.data.train == (str(project / "logs" / "day2_berthing.csv"),)
    assert trial.experiment.ship == str(tmp_path / "ships" / "other.toml")
