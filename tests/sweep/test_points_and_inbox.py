"""Point names hold the exact values (two values never share a trial), and the driver's
inbox accepts a run directory only complete, unchanged and with its trial's config."""
from __future__ import annotations

import io
import tarfile

import pandas as pd
import pytest

from sysid.errors import IncompleteOutputError
from sysid.sweep import load_sweep
from sysid.sweep.inbox import COMPLETE, TRAIN, WAIT, RunInbox, pack_run, read_journal
from sysid.sweep.plan import sweep_trials
from sysid.sweep.points import point_name
from tiny_experiment import tiny_experiment


def _spec(tmp_path, dataset_dir, vary: str):
    tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=2, warm_start_epochs=1)
    path = tmp_path / "sweep.toml"
    path.write_text(f"[sweep]\nbase = 'base.toml'\nseeds = [0, 1]\n[vary]\n{vary}\n")
    return load_sweep(path)


def test_values_that_print_alike_are_two_trials(tmp_path, dataset_dir):
    spec = _spec(tmp_path, dataset_dir, "'training.lambda_F' = [0.001, 0.0010001]")
    trials = sweep_trials(spec)
    assert len(trials) == 4 and len({t.path for t in trials}) == 4
    names = sorted({t.point for t in trials})
    assert names == ["lambda_F=0.001", "lambda_F=0.0010001"]
    for trial in trials:  # each name reads back to the exact value its config trains with
        value = float(trial.point.split("=", 1)[1])
        assert value == trial.values["training.lambda_F"]
        assert f"lambda_F = {value!r}" in trial.config


def test_names_that_lose_characters_carry_a_digest():
    a, b = point_name({"mmg.overrides": "a b"}), point_name({"mmg.overrides": "a_b"})
    assert a != b and a.startswith("overrides=a_b-") and b == "overrides=a_b"
    long = point_name({"training.lambda_F": 0.1, "training.learning_rate": 0.2, "network.hidden": (64,) * 30})
    assert len(long) <= 120 and long != point_name({"training.lambda_F": 0.1, "training.learning_rate": 0.2,
                                                    "network.hidden": (64,) * 31})


def _run_dir(tmp_path, dataset_dir):
    """A real (tiny) run directory and its config text."""
    from sysid.config.experiment import load_experiment
    from sysid.data.recordings import read_run
    from sysid.runs.lifecycle import run_experiment
    from tiny_experiment import tiny_test_file

    exp = load_experiment(tiny_experiment(tmp_path / "t.toml", dataset_dir, seed=0, epochs=2, warm_start_epochs=1))
    run = tmp_path / "made" / "seed0"
    run_experiment(exp, run, [read_run(tiny_test_file(dataset_dir))], progress=False, log=lambda m: None)
    return run, exp.to_toml()


def _tamper(blob: bytes, name: str, data: bytes) -> bytes:
    """`blob` with member `name` replaced by `data` (the manifest left as it was)."""
    src = tarfile.open(fileobj=io.BytesIO(blob), mode="r:gz")
    out = io.BytesIO()
    with tarfile.open(fileobj=out, mode="w:gz") as dst:
        for member in src.getmembers():
            payload = src.extractfile(member).read()
            if member.name == name:
                payload, member.size = data, len(data)
            dst.addfile(member, io.BytesIO(payload))
    return out.getvalue()


def test_the_inbox_keeps_only_complete_unchanged_runs_of_their_trial(tmp_path, dataset_dir):
    from sysid.runs.rundir import RunDir
    from sysid.runs.layout import load_model
    from sysid.runs.summary import RunSummary

    run, config = _run_dir(tmp_path, dataset_dir)
    blob = pack_run(run)
    out = tmp_path / "sweep"
    inbox = RunInbox(str(out))
    path = "trials/p/seed0"
    assert inbox.claim(path, "tune-a") == TRAIN and inbox.claim(path, "tune-b") == WAIT
    assert inbox.claim(path, "tune-a") == TRAIN  # the same Tune trial (a retry) takes it over

    changed = _tamper(blob, "metrics.csv", b"scenario\nforged\n")
    with pytest.raises(IncompleteOutputError, match="metrics.csv does not match its checksum"):
        inbox.deliver(path, "tune-a", changed, config)
    with pytest.raises(IncompleteOutputError, match="another config"):
        inbox.deliver(path, "tune-a", blob, config.replace("seed = 0", "seed = 1"))
    escape = io.BytesIO()
    with tarfile.open(fileobj=escape, mode="w:gz") as tar:
        info = tarfile.TarInfo("../../outside.txt")
        info.size = 1
        tar.addfile(info, io.BytesIO(b"x"))
    with pytest.raises(IncompleteOutputError, match="not a plain file"):
        inbox.deliver(path, "tune-a", escape.getvalue(), config)
    assert not (out / "trials" / "p" / "seed0").exists() and not (tmp_path / "outside.txt").exists()
    assert not [p for p in (out / "trials" / "p").iterdir()]  # no half-unpacked leftovers

    assert inbox.save_checkpoint(path, "tune-b", b"not the holder") is False
    assert inbox.save_checkpoint(path, "tune-a", b"epoch 1") is True and inbox.checkpoint(path) == b"epoch 1"
    summary = inbox.deliver(path, "tune-a", blob, config, node="n1")
    placed = out / "trials" / "p" / "seed0"
    RunDir.open(placed)  # the manifest verified
    assert summary == RunSummary.read(run / "summary.json")
    assert inbox.checkpoint(path) is None and inbox.claim(path, "tune-b") == COMPLETE
    assert sorted((p.relative_to(placed).as_posix() for p in placed.rglob("*") if p.is_file())) == \
        sorted(p.relative_to(run).as_posix() for p in run.rglob("*") if p.is_file())
    _, model = load_model(placed)
    assert model is not None
    assert [e["event"] for e in read_journal(out)] == ["trained"]
    assert [r["early_stopping_loss"] for r in inbox.history(path)] == \
        list(pd.read_csv(run / "history.csv").early_stopping_loss)
