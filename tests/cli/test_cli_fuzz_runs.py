"""Fuzzing `sysid train`, `evaluate RUN`, `report` and `reproduce`: bad experiment configs,
bad output paths, diverging training, and run or reproduction directories that are
incomplete, changed after writing or hold a broken model. Every case exits 2 with one
error line naming the file and field, no traceback, and no run left behind."""
from __future__ import annotations

import json
import shutil

import pytest
import torch

from cli_fixtures import run_copy, sysid  # noqa: F401 (fixtures)
from cli_harness import BINARY, assert_refused, leftovers
from tiny_experiment import tiny_config
from sysid.store.manifest import MANIFEST, verify_manifest, write_manifest


# -- train: configs -----------------------------------------------------------------------
CONFIG_CASES = {  # name -> (config text or bytes, what the error line names)
    "empty file": (b"", "[experiment] model is required"),
    "binary": (BINARY, "bad.toml: not"),
    "utf-16": ("[experiment]\nmodel = 'mmg'\n".encode("utf-16"), "not UTF-8 text"),
    "not TOML": ("[experiment\nmodel = 'hybrid'", "not valid TOML"),
    "no model": ("[experiment]\nname = 'x'\n", "[experiment] model is required"),
    "hidden of strings": ({"network": {"hidden": "['a']"}}, "[network] hidden: every element must be an integer, got 'a'"),
    "hidden of floats": ({"network": {"hidden": "[64.5]"}}, "[network] hidden: every element must be an integer, got 64.5"),
    "hidden too wide": ({"network": {"hidden": "[100000]"}}, "[network] hidden widths must be <= 4096"),
    "hidden empty": ({"network": {"hidden": "[]"}}, "[network] hidden must list widths >= 1"),
    "seed -1": ({"experiment": {"seed": "-1"}}, "[experiment] seed = -1: must be >= 0"),
    "seed a string": ({"experiment": {"seed": "'zero'"}}, "[experiment] seed: expected an integer"),
    "k a float": ({"gate": {"k": "1e8"}}, "[gate] k: expected an integer, got 100000000.0"),
    "k zero": ({"gate": {"k": "0"}}, "[gate] k must be >= 1"),
    "bounds of strings": ({"identify": {"parameters": "['X_vr']", "bounds": "{ X_vr = ['a', 'b'] }"}},
                          "[identify] bounds.X_vr must be [low, high]"),
    "bounds reversed": ({"identify": {"parameters": "['X_vr']", "bounds": "{ X_vr = [1.0, -1.0] }"}},
                        "[identify] bounds.X_vr must be [low, high]"),
    "learning rate inf": ({"training": {"learning_rate": "inf"}}, "[training] learning_rate: expected a finite number"),
    "learning rate nan": ({"training": {"learning_rate": "nan"}}, "[training] learning_rate: expected a finite number"),
    "learning rate 0": ({"training": {"learning_rate": "0.0"}}, "[training] learning_rate must be > 0"),
    "epochs -1": ({"training": {"epochs": "-1"}}, "[training] epochs must be >= 0"),
    "horizons empty": ({"evaluation": {"horizons": "[]"}}, "[evaluation] horizons must list at least one horizon"),
    "horizons negative": ({"evaluation": {"horizons": "[-30.0]"}}, "[evaluation] horizons must be > 0"),
    "horizons of strings": ({"evaluation": {"horizons": "['30']"}}, "[evaluation] horizons: every element must be a finite number"),
    "override a string": ({"mmg": {"overrides": "{ X_vr = 'big' }"}}, "[mmg] overrides.X_vr must be a finite number"),
    "rate 0": ({"data": {"rate": "0.0"}}, "[data] rate must be > 0"),
    "unknown key": ({"training": {"learning_rat": "0.1"}}, "[training] unknown key 'learning_rat'"),
    "training file missing": ({"data": {"files": "['no_such_file.csv']"}}, "no_such_file.csv: file not found"),
}


@pytest.mark.parametrize("case", list(CONFIG_CASES))
def test_train_refuses_bad_config(sysid, files, tmp_path, case):
    content, says = CONFIG_CASES[case]
    config, out = tmp_path / "bad.toml", tmp_path / "run"
    if isinstance(content, dict):
        content = tiny_config(files, **content)
    config.write_bytes(content if isinstance(content, bytes) else content.encode())
    assert_refused(sysid("train", config, "-o", out, "--test", files["test"]), 2, says, absent=(out,))


def test_train_refuses_negative_epochs_option(sysid, files, tmp_path):
    config, out = tmp_path / "tiny.toml", tmp_path / "run"
    config.write_text(tiny_config(files))
    assert_refused(sysid("train", config, "-o", out, "--epochs", "-1"), 2, "--epochs -1", absent=(out,))


# -- train: outputs and training failures ---------------------------------------------------
@pytest.mark.parametrize("where", ["existing run", "a file", "under /proc", "below a file"])
def test_train_refuses_an_output_it_cannot_write_before_training(sysid, files, trained, tmp_path, where):
    config = tmp_path / "tiny.toml"
    config.write_text(tiny_config(files))
    (tmp_path / "taken").write_text("a file")
    if where == "existing run":
        shutil.copytree(trained, tmp_path / "old")
    out = {"existing run": tmp_path / "old", "a file": tmp_path / "taken", "under /proc": "/proc/sysid-fuzz-run",
           "below a file": tmp_path / "taken" / "run"}[where]
    outcome = sysid("train", config, "-o", out, "--test", files["test"])
    line = assert_refused(outcome, 2, str(out))
    assert "train:" not in outcome.out  # refused before any training
    if where == "existing run":
        assert "--overwrite" in line
        verify_manifest(out, "run")  # the old run untouched
    assert leftovers(tmp_path) == []


def test_train_overwrite_replaces_the_whole_run(sysid, files, trained, tmp_path):
    config, out = tmp_path / "mmg.toml", tmp_path / "run"
    config.write_text(tiny_config(files, experiment={"model": "'mmg'"}))
    shutil.copytree(trained, out)
    outcome = sysid("train", config, "-o", out, "--test", files["test"], "--overwrite")
    assert outcome.code == 0, outcome.err
    names = set(verify_manifest(out, "run")["files"])
    assert not {"model.pt", "knn.pt", "history.csv"} & names and not (out / "model.pt").exists()  # none stale
    assert json.loads((out / "summary.json").read_text())["model"] == "mmg"
    assert leftovers(tmp_path) == []


def test_training_that_diverges_stops_and_writes_nothing(sysid, files, tmp_path):
    config, out = tmp_path / "wild.toml", tmp_path / "run"
    config.write_text(tiny_config(files, training={"learning_rate": "1e30", "epochs": "3"}))
    line = assert_refused(sysid("train", config, "-o", out, "--test", files["test"]), 2,
                          "wild.toml", "loss became", "no run written", absent=(out,))
    assert "nan" in line or "inf" in line


def test_gate_k_larger_than_the_bank_is_refused(sysid, files, tmp_path):
    config, out = tmp_path / "k.toml", tmp_path / "run"
    config.write_text(tiny_config(files, gate={"k": "100000000"}))
    assert_refused(sysid("train", config, "-o", out, "--test", files["test"]), 2,
                   "k.toml", "[gate] k = 100000000", absent=(out,))


# -- evaluate and report: incomplete, changed or broken runs -------------------------------
def _drop_manifest(run):
    (run / MANIFEST).unlink()


def _drop_model(run):
    (run / "model.pt").unlink()


def _flip_model_byte(run):
    data = bytearray((run / "model.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (run / "model.pt").write_bytes(bytes(data))


def _edit_config(run):
    (run / "config.toml").write_text((run / "config.toml").read_text().replace("hidden = [8]", "hidden = [9]"))


def _nan_weights_resealed(run):
    state = torch.load(run / "model.pt", weights_only=True)
    name = next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)
    state[name][0] = float("nan")
    torch.save(state, run / "model.pt")
    write_manifest(run, "run")  # consistent, but the model itself is broken


def _garbage_model_resealed(run):
    (run / "model.pt").write_bytes(b"\x80\x04not a checkpoint")
    write_manifest(run, "run")


def _drop_summary_resealed(run):
    (run / "summary.json").unlink()
    write_manifest(run, "run")


BROKEN_RUNS = {  # name -> (how the run is broken, what the error line names)
    "no manifest (interrupted)": (_drop_manifest, "incomplete run directory: no manifest.json"),
    "model.pt missing": (_drop_model, "model.pt is missing"),
    "model.pt changed": (_flip_model_byte, "model.pt does not match its checksum"),
    "config changed": (_edit_config, "config.toml does not match its checksum"),
    "NaN weights": (_nan_weights_resealed, "holds NaN or inf"),
    "model.pt not a checkpoint": (_garbage_model_resealed, "model.pt: cannot be loaded safely"),
    "summary.json missing": (_drop_summary_resealed, "summary.json is missing"),
}


@pytest.mark.parametrize("case", list(BROKEN_RUNS))
def test_evaluate_refuses_a_broken_run(sysid, run_copy, files, tmp_path, case):
    breaks, says = BROKEN_RUNS[case]
    breaks(run_copy)
    out = tmp_path / "metrics.csv"
    line = assert_refused(sysid("evaluate", run_copy, "--data", files["test"], "--horizon", "30", "-o", out),
                          2, says, absent=(out,))
    assert str(run_copy) in line and "weights_only" not in line  # no torch advice to the user


@pytest.mark.parametrize("case", ["no manifest (interrupted)", "model.pt missing", "model.pt changed",
                                  "summary.json missing"])
def test_report_refuses_a_broken_run(sysid, run_copy, tmp_path, case):
    breaks, says = BROKEN_RUNS[case]
    breaks(run_copy)
    out = tmp_path / "report"
    assert_refused(sysid("report", run_copy, "-o", out, "--quiet"), 2, str(run_copy), says)
    assert not (out / "report.html").exists() and not (out / "report.pdf").exists()


def test_evaluate_and_report_refuse_a_missing_run(sysid, files, tmp_path):
    out = tmp_path / "metrics.csv"
    assert_refused(sysid("evaluate", tmp_path / "nope", "--data", files["test"], "-o", out), 2,
                   "nope: run directory not found", absent=(out,))
    assert_refused(sysid("report", tmp_path / "nope", "-o", tmp_path / "r"), 2, "nope: no such directory")


def test_evaluate_accepts_the_intact_run(sysid, trained, files, tmp_path):
    out = tmp_path / "metrics.csv"
    outcome = sysid("evaluate", trained, "--data", files["test"], "--horizon", "30", "-o", out)
    assert outcome.code == 0 and out.is_file(), outcome.err


# -- reproduce ----------------------------------------------------------------------------
@pytest.mark.parametrize("where", ["existing output", "a file", "under /proc"])
def test_reproduce_refuses_an_output_it_cannot_write(sysid, dataset_dir, tmp_path, where):
    (tmp_path / "taken").write_text("a file")
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "keep.txt").write_text("old work")
    out = {"existing output": tmp_path / "old", "a file": tmp_path / "taken", "under /proc": "/proc/sysid-fuzz-rep"}[where]
    outcome = sysid("reproduce", "-o", out, "--only", "mmg_paper", "--no-report", "--data", dataset_dir)
    assert_refused(outcome, 2, str(out))
    assert "[1/1]" not in outcome.out and (tmp_path / "old" / "keep.txt").is_file()
    assert leftovers(tmp_path) == []


def test_reproduce_refuses_an_unknown_run_before_any_work(sysid, dataset_dir, tmp_path):
    out = tmp_path / "rep"
    assert_refused(sysid("reproduce", "-o", out, "--only", "mmg_paperr", "--data", dataset_dir), 2,
                   "'mmg_paperr'", absent=(out,))


def test_partial_reproduction_is_complete_on_disk_and_says_partial_on_page_one(sysid, dataset_dir, tmp_path):
    pypdf = pytest.importorskip("pypdf")
    out = tmp_path / "rep"
    outcome = sysid("reproduce", "-o", out, "--only", "mmg_paper", "--no-report", "--data", dataset_dir)
    assert outcome.code == 0, outcome.err
    assert "ReportPaths(" not in outcome.out
    listed = verify_manifest(out, "reproduction")["files"]
    assert "runs/mmg_paper/manifest.json" in listed and "comparison.csv" in listed
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["mmg_paper"]
    again = sysid("reproduce", "-o", out, "--only", "mmg_paper", "--no-report", "--data", dataset_dir)
    assert_refused(again, 2, "already exists")

    report = sysid("report", out, "-o", tmp_path / "report", "--quiet")
    assert report.code == 0, report.err
    first_page = pypdf.PdfReader(tmp_path / "report" / "report.pdf").pages[0].extract_text()
    assert "PARTIAL reproduction" in first_page and "1 of 8 protocol runs" in first_page
    assert "PARTIAL" in (tmp_path / "report" / "report.html").read_text()

    shutil.rmtree(out / "runs" / "mmg_paper" / "traces")  # as a run lost to a crash would be
    assert_refused(sysid("report", out, "-o", tmp_path / "report2", "--quiet"), 2, str(out), "is missing")


@pytest.mark.parametrize("where", ["under /proc", "below a file"])
def test_report_output_that_cannot_be_written(sysid, trained, tmp_path, where):
    (tmp_path / "taken").write_text("a file")
    out = {"under /proc": "/proc/sysid-fuzz-report", "below a file": tmp_path / "taken" / "report"}[where]
    line = assert_refused(sysid("report", trained, "-o", out, "--quiet"), 2)
    assert "sysid-fuzz-report" in line or "taken" in line
    assert leftovers(tmp_path) == [] and (tmp_path / "taken").read_text() == "a file"
