"""summary.json as `RunSummary`: the record mirrors what the trainer's writer writes, key for
key and byte for byte, and refuses a malformed file with one line naming the file and key."""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import pytest
import torch

from sysid.config.choices import Solver
from sysid.identify.trainer import TrainingSummary
from sysid.errors import CheckpointError, RecordError
from sysid.evaluation.verdict import BaselineVerdict
from sysid.records.summary import GateSummary, IdentificationSummary, UncertaintySummary
from sysid.runs.layout import run_summary
from sysid.runs.rundir import RunDir
from sysid.runs.records import JsonRecord
from sysid.runs.summary import RunSummary
from synthetic_rundir import measured_runs, write_run


def _extras(record: JsonRecord, at: str = "summary") -> dict:
    """Every key the record did not know, anywhere in it (path -> keys)."""
    found = {at: list(record.extra)} if record.extra else {}
    for f in dataclasses.fields(record):
        values = getattr(record, f.name)
        for i, value in enumerate(values if isinstance(values, tuple) else (values,)):
            if isinstance(value, JsonRecord):
                found.update(_extras(value, f"{at}.{f.name}[{i}]"))
    return found


KEYS = ["name", "model", "status", "dataset", "ship", "seed", "created", "seconds", "train_seconds", "epochs",
        "best_epoch", "val_loss_multistep", "val_loss_definition", "verdict", "beats_baseline", "data", "training_range", "stopped", "n_train_windows", "n_val_windows", "versions", "mmg_overrides",
        "identified", "identified_initial", "identified_uncertainty", "identification", "gate", "training"]


@pytest.mark.parametrize("which", ["hybrid_run", "levenberg_marquardt_run"])
def test_written_summary_reads_back_and_writes_byte_identical(which, request):
    run = RunDir.open(request.getfixturevalue(which).path)
    text = run.summary.read_text()
    summary = run.read_summary()
    assert summary.to_text() == text                      # read, write again: the same bytes
    assert RunSummary.from_json(json.loads(summary.to_text()), "again") == summary
    assert _extras(summary) == {}                         # every key the writer writes is a typed field


@pytest.mark.parametrize("which", ["hybrid_run", "levenberg_marquardt_run"])
def test_summary_keeps_the_trainers_blocks_key_for_key_in_their_order(which, request):
    """The documented top-level keys; the blocks as the trainer made them (`TrainingSummary`,
    its identification, sigma and gate dicts), in the order it made them."""
    result = request.getfixturevalue(which)
    written = json.loads(RunDir(result.path).summary.read_text())
    assert list(written) == KEYS
    made = result.training.to_dict()
    for key in ("identification", "identified_uncertainty", "identified", "identified_initial", "stopped"):
        assert json.dumps(written[key]) == json.dumps(made.get(key)), key
    gate = {**(made.get("gate") or {}), "off_share": result.evaluation.gate_off_share}
    assert json.dumps(written["gate"]) == json.dumps(gate)
    rest = {k: v for k, v in made.items() if k not in KEYS and k != "failure"}
    assert json.dumps(written["training"]) == json.dumps(rest)


@pytest.mark.parametrize("which", ["hybrid_run", "levenberg_marquardt_run"])
def test_a_checkpoint_summary_of_the_dict_trainer_loads_as_records(which, request, tmp_path):
    """A training checkpoint's summary as the trainer wrote it when its identification, sigma
    and gate were dicts (the blocks of summary.json, the gate without its off shares) loads
    with ``weights_only=True`` into the records the trainer gives now, and writes the same
    summary.json blocks."""
    result = request.getfixturevalue(which)
    written = json.loads(RunDir(result.path).summary.read_text())
    made = result.training
    legacy = {**made.to_dict(), "identification": written["identification"],
              "identified_uncertainty": written["identified_uncertainty"]}
    legacy.pop("gate", None)
    gate = {k: v for k, v in written["gate"].items() if k != "off_share"}
    if gate:
        legacy["gate"] = gate
    torch.save({"summary": legacy}, tmp_path / "checkpoint.pt")
    loaded = TrainingSummary.from_dict(torch.load(tmp_path / "checkpoint.pt", weights_only=True)["summary"])
    assert isinstance(made.identification, IdentificationSummary)
    assert isinstance(loaded.identification, IdentificationSummary)
    assert isinstance(loaded.identified_uncertainty, UncertaintySummary)
    assert (loaded.gate is None) == (made.gate is None) and (made.gate is None or isinstance(made.gate, GateSummary))
    assert loaded.to_dict() == made.to_dict()
    again = run_summary(result.experiment, result.evaluation, loaded).to_json()
    for key in ("identification", "identified_uncertainty", "gate", "training"):
        assert json.dumps(again[key]) == json.dumps(written[key]), key


def test_hybrid_summary_agrees_with_the_runs_other_files(hybrid_run):
    run = RunDir.open(hybrid_run.path)
    summary, bank = run.read_summary(), run.read_knn_bank()
    assert (summary.name, summary.model, summary.status, summary.dataset) == ("tiny", "hybrid", "complete", "files")
    assert (summary.gate.k, summary.gate.space) == (5, "inputs")  # the tiny experiment's [gate]
    assert summary.gate.bank == bank.bank.shape[0] and summary.gate.threshold == float(bank.threshold)
    assert set(summary.gate.off_share) == {p.name for p in run.traces.iterdir()}
    assert summary.n_train_windows == sum(f.train_windows for f in summary.training.split.files)
    assert summary.n_val_windows == sum(f.val_windows for f in summary.training.split.files)
    history = run.read_history()
    assert summary.epochs == history.epoch.max() and set(summary.stopped) == {"identify", "train"}
    assert summary.identification.solver is Solver.GRADIENT and summary.identification.epochs == 2
    assert summary.identified_uncertainty.names == ("N_r",)
    assert summary.identified_uncertainty.estimate[0] == pytest.approx(summary.identified["N_r"])
    assert summary.val_loss_multistep > 0 and summary.objective == summary.val_loss_multistep
    verdict = BaselineVerdict.from_dict(summary.verdict.to_json())  # the typed block gives back the trainer's verdict
    assert summary.beats_baseline == summary.verdict.beats_baseline == verdict.beats_baseline
    assert summary.verdict.statement == verdict.statement()
    assert summary.data.training == "files" and summary.data.test_set == "files"
    for log in summary.data.train + summary.data.test:  # every log named with its SHA-256
        assert log.sha256 == hashlib.sha256(Path(log.file).read_bytes()).hexdigest()


def test_levenberg_marquardt_check_reads_as_the_trainer_logged_it(levenberg_marquardt_run):
    summary = RunDir.open(levenberg_marquardt_run.path).read_summary()
    est = summary.identification
    assert (est.solver, est.start_states, est.iterations) == ("levenberg_marquardt", "estimated", 2)
    check = est.start_state_check
    assert check.start_states == "recorded" and set(check.coefficients) == {"N_r"}
    assert check.largest == "N_r" and check.largest_sigma == check.difference_sigma["N_r"]
    assert check.verdict().startswith(f"with start states recorded the estimates move by at most "
                                      f"{abs(check.largest_sigma):.1f}σ (N_r)")


def test_unknown_keys_are_kept_and_written_after_the_known_ones(hybrid_run):
    data = json.loads(RunDir(hybrid_run.path).summary.read_text())
    data["calibration"] = {"fit": "good"}              # a block a newer sysid writes
    data["gate"]["bank_bytes"] = 123
    summary = RunSummary.from_json(data, "summary.json")
    assert summary.extra == {"calibration": {"fit": "good"}} and summary.gate.extra == {"bank_bytes": 123}
    assert summary.to_text() == json.dumps(data, indent=2)


def test_a_run_written_before_keys_existed_reads_with_their_defaults(tmp_path):
    """The report tests' synthetic run: no status, seconds, val_loss_multistep, verdict, data, stopped, training."""
    runs = measured_runs(0.2)
    path = write_run(tmp_path / "hybrid_D1", "hybrid_D1", {"Berthing": runs["Berthing"]}, horizons=(30,))
    summary = RunDir.open(path).read_summary()
    assert (summary.status, summary.val_loss_multistep, summary.stopped, summary.training.split) == ("complete", None, {}, None)
    assert (summary.verdict, summary.beats_baseline, summary.data) == (None, None, None)
    assert (summary.gate.k, summary.gate.threshold, summary.gate.off_share) == (10, 1.0, None)
    assert not summary.failed and summary.epochs == 40


@pytest.mark.parametrize("change, message", [
    (lambda d: d["gate"].update(k="ten"), r"gate\.k: expected an integer, got a string 'ten'"),
    (lambda d: d.update(stopped=["train"]), r"stopped: expected an object, got an array"),
    (lambda d: d.update(val_loss_multistep=True), r"val_loss_multistep: expected a number, got true/false"),
    (lambda d: d["training"]["split"]["files"][0].pop("val_windows"),
     r"key 'training\.split\.files\[0\]\.val_windows' is missing"),
    (lambda d: d.pop("name"), r"key 'name' is missing"),
    (lambda d: d["identification"].update(solver="adam"),
     r"identification\.solver: expected one of gradient, levenberg_marquardt, got a string 'adam'"),
])
def test_a_malformed_summary_is_one_line_naming_the_file_and_key(hybrid_run, tmp_path, change, message):
    data = json.loads(RunDir(hybrid_run.path).summary.read_text())
    change(data)
    path = tmp_path / "summary.json"
    path.write_text(json.dumps(data))
    with pytest.raises(RecordError, match=message) as err:
        RunSummary.read(path)
    said = str(err.value)
    assert said.startswith(f"{path}: ") and "\n" not in said and "write it again" in said
    assert isinstance(err.value, CheckpointError)  # a corrupt run directory, as every caller catches it


@pytest.mark.parametrize("text, message", [
    ('{"name": "hybrid_D2", ', r"not valid JSON \(Expecting property name"),
    ("[1, 2]", r"expected a JSON object"),
])
def test_a_summary_that_is_not_a_json_object_is_a_record_error_naming_the_file(tmp_path, text, message):
    path = tmp_path / "summary.json"
    path.write_text(text)
    with pytest.raises(RecordError, match=message) as err:
        RunSummary.read(path)
    assert str(err.value).startswith(f"{path}: ") and "\n" not in str(err.value)


def test_reproduce_warns_for_every_run_below_its_baseline(hybrid_run, tmp_path, capsys):
    """``sysid reproduce``'s last lines: one line per model with its verdict statement (a
    WARNING on stderr when it does not beat its physics baseline); a model's seeds are members
    of one model, judged once."""
    import shutil

    from sysid.cli.train_commands import _warn_below_baseline

    data = json.loads(RunDir(hybrid_run.path).summary.read_text())
    assert data["beats_baseline"] is False
    shutil.copytree(hybrid_run.path, tmp_path / "runs" / "a")
    for seed in ("seed0", "seed1"):
        shutil.copytree(hybrid_run.path, tmp_path / "runs" / "b" / seed)
    _warn_below_baseline(tmp_path)
    said = capsys.readouterr().err.splitlines()
    assert said[0] == f"WARNING: run a: {data['verdict']['statement']}"
    assert said[1].startswith("WARNING: run b (2 seeds): The hybrid (mean over 2 seeds) ") and len(said) == 2
