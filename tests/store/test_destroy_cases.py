"""The bad-input probe's cases that destroyed a user's files (issue 20), one test each, run
as a user runs `sysid`: exit 2, one error line naming the output and the path at fault, no
traceback, and the user's file byte-identical afterwards. And two trainings into one
output at once: the second is refused at once, the first finishes clean."""
from __future__ import annotations

import importlib
import json
import shutil
import subprocess

import pandas as pd
import pytest

from cli_harness import assert_refused, console_script, environment, in_process, leftovers
from preprocessing import synth
from sysid.store.manifest import MANIFEST, verify_manifest
from analytic_runs import analytic_run
from tiny_experiment import tiny_config

FOREIGN_MANIFEST = json.dumps({"name": "My App", "start_url": "/", "icons": []})


@pytest.fixture
def sysid(capsys):
    return lambda *args: in_process(capsys, *args)


class Untouched:
    """Every file below a folder, byte for byte, to compare after a refused command."""

    def __init__(self, *roots):
        self.roots = roots
        self.before = self.snapshot()
        assert self.before, "nothing to protect"

    def snapshot(self) -> dict:
        return {p: p.read_bytes() for root in self.roots
                for p in ([root] if root.is_file() else sorted(root.rglob("*"))) if p.is_file()}

    def check(self) -> None:
        assert self.snapshot() == self.before, "a user's file was changed or deleted"


@pytest.fixture
def run_copy(trained, tmp_path):
    return shutil.copytree(trained, tmp_path / "run")


@pytest.fixture
def site(tmp_path):
    """A user's folder with its own manifest.json (a web app's) and a thesis."""
    folder = tmp_path / "site"
    folder.mkdir()
    (folder / MANIFEST).write_text(FOREIGN_MANIFEST)
    (folder / "thesis.tex").write_text("\\chapter{Years of work}\n")
    return folder


def processed_run(path):
    """A processed 10 Hz run (public schema, 20 s) synth-raw reads."""
    frame = analytic_run(20.0)
    frame.columns = [f"{c} [{u}]" for c, u in synth.schema.PROCESSED.items()]
    frame.to_csv(path, index=False)
    return path


# -- single files onto the data they read ------------------------------------------------------
def test_forces_output_onto_its_input(sysid, tmp_path):
    data = tmp_path / "states.csv"  # plausible states of the 3 m model
    pd.DataFrame({"x": [0.0, 1.0], "u": 0.5, "y": 0.0, "v": 0.01, "psi": 0.2, "r": 0.003, "n_prop": 10.0,
                  "delta_rudder": 0.1, "wind_velo_true": 1.5, "wind_dir_true": 2.0}).to_csv(data, index=False)
    kept = Untouched(tmp_path)
    assert_refused(sysid("forces", data, "-o", data), 2, f"{data}: is {data}, an input of this command")
    kept.check()


def test_simulate_output_onto_its_log(sysid, files, tmp_path):
    log = shutil.copy(files["train"], tmp_path / "log.csv")
    kept = Untouched(tmp_path)
    assert_refused(sysid("simulate", "--log", log, "--start", "10", "--horizon", "30", "-o", tmp_path / "log.csv"),
                   2, f"{log}: is {log}, an input of this command")
    kept.check()


def test_evaluate_output_onto_its_data_file_or_into_its_data_folder(sysid, files, tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    test = shutil.copy(files["test"], data / "test.csv")
    kept = Untouched(tmp_path)
    assert_refused(sysid("evaluate", "--data", test, "--horizon", "30", "-o", test), 2,
                   f"{test}: is {test}, an input of this command")
    assert_refused(sysid("evaluate", "--data", data, "--horizon", "30", "-o", data / "metrics.csv"), 2,
                   f"{data / 'metrics.csv'}: lies inside {data}, an input of this command")
    kept.check()
    assert leftovers(data) == [] and leftovers(tmp_path) == []


def test_evaluate_output_onto_the_run_directorys_metrics(sysid, run_copy, files, tmp_path):
    kept = Untouched(run_copy)
    out = run_copy / "metrics.csv"
    assert_refused(sysid("evaluate", run_copy, "--data", files["test"], "--horizon", "30", "-o", out), 2,
                   f"{out}: lies inside {run_copy}, a run directory sysid sealed")
    kept.check()
    verify_manifest(run_copy, "run")


# -- synth-raw ---------------------------------------------------------------------------------
def test_synth_raw_output_equal_to_its_input(sysid, tmp_path):
    src = processed_run(tmp_path / "run.csv")
    kept = Untouched(src)
    assert_refused(sysid("synth-raw", src, "-o", src), 2, f"{src}: is {src}, an input of this command")
    kept.check()
    # the truth file's name may be the input's too: raw.csv brings raw.truth.csv along
    truth_named = processed_run(tmp_path / "raw.truth.csv")
    kept = Untouched(truth_named)
    assert_refused(sysid("synth-raw", truth_named, "-o", tmp_path / "raw.csv"), 2,
                   f"{truth_named}: is {truth_named}, an input of this command")
    kept.check()
    assert not (tmp_path / "raw.csv").exists()


def test_synth_raw_truth_file_that_already_exists(sysid, tmp_path):
    src = processed_run(tmp_path / "run.csv")
    truth = tmp_path / "raw.truth.csv"
    truth.write_text("my hand-made truth, not sysid's\n")
    kept = Untouched(truth)
    raw = tmp_path / "raw.csv"
    assert_refused(sysid("synth-raw", src, "-o", raw), 2, f"{truth}: already exists", str(raw), "--overwrite")
    kept.check()
    assert not raw.exists() and leftovers(tmp_path) == []
    done = sysid("synth-raw", src, "-o", raw, "--overwrite")  # said so: replaced
    assert done.code == 0, done.err
    assert list(pd.read_csv(truth).columns)[:2] == ["t [s]", "x_position_mid [m]"]


# -- --overwrite onto a folder with someone else's manifest.json ---------------------------------
def test_preprocess_overwrite_onto_a_foreign_manifest(sysid, site, tmp_path):
    from preprocessing.sensors import SensorLayout
    raw = tmp_path / "raw.csv"
    synth.synthesise(analytic_run(30.0), SensorLayout(), synth.SynthSettings(seed=1)).raw.to_csv(raw, index=False)
    kept = Untouched(site)
    assert_refused(sysid("preprocess", raw, "-o", site, "--overwrite"), 2,
                   f"{site}: exists and was not written by sysid ({site / MANIFEST} is not a sysid manifest")
    kept.check()


def test_train_overwrite_onto_a_foreign_manifest(sysid, site, files, tmp_path):
    config = tmp_path / "tiny.toml"
    config.write_text(tiny_config(files))
    kept = Untouched(site)
    outcome = sysid("train", config, "-o", site, "--test", files["test"], "--overwrite")
    assert_refused(outcome, 2, f"{site}: exists and was not written by sysid ({site / MANIFEST}")
    assert "train:" not in outcome.out  # refused before training
    kept.check()


def test_reproduce_overwrite_onto_a_foreign_manifest(sysid, site, dataset_dir):
    kept = Untouched(site)
    outcome = sysid("reproduce", "-o", site, "--only", "mmg_paper", "--no-report", "--data", dataset_dir,
                    "--overwrite")
    assert_refused(outcome, 2, f"{site}: exists and was not written by sysid ({site / MANIFEST}")
    kept.check()


# -- sweeps ------------------------------------------------------------------------------------
def sweep_folder(folder, dataset_dir, name="sweep.toml"):
    """A user's folder holding a sweep file, its base config and a thesis."""
    from tiny_experiment import tiny_experiment
    folder.mkdir(exist_ok=True)
    tiny_experiment(folder / "base.toml", dataset_dir, seed=0, epochs=1, warm_start_epochs=1)
    (folder / name).write_text("[sweep]\nbase = 'base.toml'\nseeds = [0]\n[vary]\n'training.learning_rate' = [1e-3]\n")
    (folder / "thesis.tex").write_text("\\chapter{Years of work}\n")
    return folder / name


def test_sweep_output_dot_with_overwrite(sysid, dataset_dir, tmp_path, monkeypatch):
    sweep_file = sweep_folder(tmp_path / "work", dataset_dir)
    monkeypatch.chdir(tmp_path / "work")
    kept = Untouched(tmp_path / "work")
    assert_refused(sysid("sweep", "sweep.toml", "-o", ".", "--overwrite"), 2,
                   ".: holds sweep.toml, an input of this command")
    kept.check()
    assert sweep_file.is_file()


@pytest.mark.parametrize("flag", ["--overwrite", "--resume", None])
def test_sweep_output_the_folder_holding_the_sweep_file(sysid, dataset_dir, tmp_path, flag):
    folder = tmp_path / "mine"
    sweep_file = sweep_folder(folder, dataset_dir, name="my_sweep.toml")
    (folder / "sweep.toml").write_bytes(sweep_file.read_bytes())  # a copy named as the sweep's own marker
    kept = Untouched(folder)
    outcome = sysid("sweep", sweep_file, "-o", folder, *([flag] if flag else []))
    assert_refused(outcome, 2, f"{folder}: holds {sweep_file}, an input of this command")
    kept.check()
    assert leftovers(tmp_path) == []


# -- train --overwrite onto the folder holding its own inputs -----------------------------------
def test_train_overwrite_onto_a_run_folder_holding_its_inputs(sysid, run_copy, files, tmp_path):
    data = shutil.copy(files["train"], run_copy / "train.csv")  # the user keeps config and data in the old run
    config = run_copy / "tiny.toml"
    config.write_text(tiny_config(files, data={"files": json.dumps([str(data)])}))
    kept = Untouched(config, data)
    outcome = sysid("train", config, "-o", run_copy, "--test", files["test"], "--overwrite")
    line = assert_refused(outcome, 2, f"{run_copy}: holds", "an input of this command")
    assert str(config) in line or str(data) in line
    kept.check()
    verify_manifest(run_copy, "run")  # the old run untouched too


# -- export ------------------------------------------------------------------------------------
def test_export_through_a_symlink_to_a_user_file(sysid, trained, tmp_path):
    thesis = tmp_path / "home" / "thesis.tex"
    thesis.parent.mkdir()
    thesis.write_text("\\chapter{Years of work}\n")
    link = tmp_path / "model.pt2"
    link.symlink_to(thesis)
    kept = Untouched(thesis)
    assert_refused(sysid("export", trained, "-o", link, "--portable"), 2,
                   f"{link}: is a symbolic link to {thesis}")
    kept.check()
    assert link.is_symlink()


def test_export_onto_the_run_directorys_model(sysid, run_copy, tmp_path):
    kept = Untouched(run_copy)
    out = run_copy / "model.pt"
    assert_refused(sysid("export", run_copy, "-o", out, "--portable"), 2, f"{out}: lies inside {run_copy}")
    kept.check()
    verify_manifest(run_copy, "run")


# -- two writers -------------------------------------------------------------------------------
def test_two_trainings_into_one_output(sysid, files, tmp_path):
    """The first takes the output's lock before it trains; the second, started meanwhile,
    is refused at once with one line; the first finishes with a complete run and nothing
    beside it (no checkpoint, no lock file)."""
    for module in ("sysid.config.experiment", "sysid.data.recordings", "sysid.runs.lifecycle"):
        importlib.import_module(module)  # now: the second answers in milliseconds, while the first trains
    config, out = tmp_path / "tiny.toml", tmp_path / "run"
    config.write_text(tiny_config(files, training={"epochs": "4", "patience": "1000", "warm_start_epochs": "2",
                                                   "batch_size": "64", "max_minutes": "5.0"}))
    first = subprocess.Popen([console_script(), "train", str(config), "-o", str(out), "--test", str(files["test"])],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env={**environment(), "PYTHONUNBUFFERED": "1"})  # each line as it is printed
    try:
        for line in first.stdout:  # its first line comes once it holds the output, before it trains
            if "train: " in line:  # time-stamped: stdout is a pipe
                break
        second = sysid("train", config, "-o", out, "--test", files["test"])
        assert_refused(second, 2, f"{out}: another sysid process (pid {first.pid}) is writing it",
                       str(tmp_path / ".run.lock"))
        rest, err = first.communicate(timeout=600)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, err
    verify_manifest(out, "run")
    assert leftovers(tmp_path) == []  # no checkpoint, no lock, no staging directory
    assert "train: wrote" in rest
