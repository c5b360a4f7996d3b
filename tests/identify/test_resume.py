"""Interrupted training continues to the same model: `sysid train --resume`."""
import json

import pytest
import torch

from sysid.identify.checkpoint import CheckpointState, TrainingCheckpoint, plain
from sysid.cli import main, run as sysid
from sysid.runs.lifecycle import checkpoint_path
from tiny_experiment import tiny_experiment, tiny_test_file


def _config(tmp_path, dataset_dir):
    config = tiny_experiment(tmp_path / "tiny.toml", dataset_dir, seed=5, epochs=6, warm_start_epochs=5)
    return config, tiny_test_file(dataset_dir)


def _interrupt_after_saves(monkeypatch, n: int) -> list[int]:
    """Ctrl-C right after the `n`-th checkpoint is saved; the epochs saved (filled as they are)."""
    original, saves = TrainingCheckpoint.save, []

    def save_then_interrupt(self, state):
        original(self, state)
        saves.append(state.epoch)
        if len(saves) == n:
            raise KeyboardInterrupt

    monkeypatch.setattr(TrainingCheckpoint, "save", save_then_interrupt)
    return saves


def test_interrupted_training_resumes_to_the_same_metrics(dataset_dir, tmp_path, monkeypatch, capsys):
    config, test_file = _config(tmp_path, dataset_dir)
    capsys.readouterr()
    # --resume without a checkpoint: said, and the run trains from its first epoch
    sysid(["train", str(config), "-o", str(tmp_path / "whole"), "--test", str(test_file), "--resume"])
    assert (f"WARNING: --resume: no checkpoint {checkpoint_path(tmp_path / 'whole')} to resume from: "
            f"{tmp_path / 'whole'} trains from the first epoch") in capsys.readouterr().err
    whole = (tmp_path / "whole" / "metrics.csv").read_text()

    saves = {"n": 0}
    original = TrainingCheckpoint.save

    def save_then_interrupt(self, state):
        original(self, state)
        saves["n"] += 1
        if saves["n"] == 3:  # Ctrl-C right after epoch 3 was checkpointed
            raise KeyboardInterrupt

    monkeypatch.setattr(TrainingCheckpoint, "save", save_then_interrupt)
    out = tmp_path / "parted"
    with pytest.raises(SystemExit) as stop:
        main(["train", str(config), "-o", str(out), "--test", str(test_file)])
    assert stop.value.code == 130
    err = capsys.readouterr().err
    assert "interrupted:" in err and "--resume" in err and str(checkpoint_path(out)) in err
    assert not out.exists() and checkpoint_path(out).is_file()
    monkeypatch.setattr(TrainingCheckpoint, "save", original)

    sysid(["train", str(config), "-o", str(out), "--test", str(test_file), "--resume"])
    assert "resumed after epoch 3" in capsys.readouterr().out
    assert (out / "metrics.csv").read_text() == whole
    assert not checkpoint_path(out).exists()  # removed once the run is complete
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "complete" and summary["epochs"] == 6
    assert summary["stopped"] == {"train": "epoch limit"}


def test_resume_refuses_another_configs_checkpoint(dataset_dir, tmp_path, monkeypatch):
    from sysid.errors import CheckpointError
    config, test_file = _config(tmp_path, dataset_dir)
    out = tmp_path / "run"
    state = CheckpointState("train", 1, {}, {}, {}, torch.zeros(0, dtype=torch.uint8), 1.0, 1, None, [], [], {})
    TrainingCheckpoint(checkpoint_path(out), "[experiment]\nname = 'other'\n").save(state)
    with pytest.raises(CheckpointError, match="made with another config"):
        sysid(["train", str(config), "-o", str(out), "--test", str(test_file), "--resume"])


def test_a_checkpoint_of_torch_adam_resumes_to_the_same_metrics(dataset_dir, tmp_path, monkeypatch, capsys):
    """A checkpoint whose optimizer state is torch.optim.Adam's (what sysid wrote before its
    own `Adam`) resumes to the metrics of an uninterrupted run."""
    from sysid.identify import loop

    config, test_file = _config(tmp_path, dataset_dir)
    capsys.readouterr()
    # --resume without a checkpoint: said, and the run trains from its first epoch
    sysid(["train", str(config), "-o", str(tmp_path / "whole"), "--test", str(test_file), "--resume"])
    assert (f"WARNING: --resume: no checkpoint {checkpoint_path(tmp_path / 'whole')} to resume from: "
            f"{tmp_path / 'whole'} trains from the first epoch") in capsys.readouterr().err
    whole = (tmp_path / "whole" / "metrics.csv").read_text()

    made: list[float] = []
    saves = _interrupt_after_saves(monkeypatch, 2)
    monkeypatch.setattr(loop, "adam", lambda params, lr: made.append(lr) or torch.optim.Adam(params, lr=lr, foreach=True))
    out = tmp_path / "parted"
    with pytest.raises(SystemExit):
        main(["train", str(config), "-o", str(out), "--test", str(test_file)])
    monkeypatch.undo()
    assert made and saves == [1, 2]
    saved = CheckpointState.from_state_dict(torch.load(checkpoint_path(out), weights_only=True), "checkpoint")
    assert saved.optimizer["state"][0]["step"] > 0
    sysid(["train", str(config), "-o", str(out), "--test", str(test_file), "--resume"])
    assert "resumed after epoch 2" in capsys.readouterr().out
    assert (out / "metrics.csv").read_text() == whole


def test_a_version_1_checkpoint_resumes_to_the_same_metrics(dataset_dir, tmp_path, monkeypatch, capsys):
    """A checkpoint in version 1's layout (every tensor on its own, what sysid wrote before the
    packed tables) resumes to the metrics of an uninterrupted run."""
    config, test_file = _config(tmp_path, dataset_dir)
    capsys.readouterr()
    # --resume without a checkpoint: said, and the run trains from its first epoch
    sysid(["train", str(config), "-o", str(tmp_path / "whole"), "--test", str(test_file), "--resume"])
    assert (f"WARNING: --resume: no checkpoint {checkpoint_path(tmp_path / 'whole')} to resume from: "
            f"{tmp_path / 'whole'} trains from the first epoch") in capsys.readouterr().err
    whole = (tmp_path / "whole" / "metrics.csv").read_text()

    saves = []

    def save_version_1_then_interrupt(self, state):
        torch.save(plain({"version": 1, "config": self.config, **state.to_state_dict()}), self.path)
        saves.append(state.epoch)
        if len(saves) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(TrainingCheckpoint, "save", save_version_1_then_interrupt)
    out = tmp_path / "parted"
    with pytest.raises(SystemExit):
        main(["train", str(config), "-o", str(out), "--test", str(test_file)])
    monkeypatch.undo()
    raw = torch.load(checkpoint_path(out), weights_only=True)
    assert raw["version"] == 1 and isinstance(raw["model"], dict) and len(raw["model"]) > 10
    sysid(["train", str(config), "-o", str(out), "--test", str(test_file), "--resume"])
    assert "resumed after epoch 3" in capsys.readouterr().out
    assert (out / "metrics.csv").read_text() == whole


def _project(folder, dataset_dir):
    """A project with its own copies of the tiny experiment's logs and a config naming them
    relative to itself (``logs/``, ``test/``); returns its config."""
    from tiny_experiment import TRAIN_FILES, TEST_FILE
    import shutil
    (folder / "logs").mkdir(parents=True)
    (folder / "test").mkdir()
    for name in TRAIN_FILES:
        shutil.copy(dataset_dir / "berthing" / name, folder / "logs" / name)
    shutil.copy(dataset_dir / "berthing" / TEST_FILE, folder / "test" / TEST_FILE)
    config = folder / "tiny.toml"
    text = tiny_experiment(folder / "scratch.toml", dataset_dir, seed=5, epochs=5, warm_start_epochs=4).read_text()
    config.write_text(text.replace(str(dataset_dir / "berthing"), "logs").replace("[data]\n", "[data]\ntest = ['test']\n", 1))
    (folder / "scratch.toml").unlink()
    return config


def test_a_checkpoint_resumes_after_its_project_folder_moved(dataset_dir, tmp_path, monkeypatch, capsys):
    """The checkpoint's config names the logs by absolute path; the project moved (the
    original gone), its logs hold the same bytes at their new paths: the training resumes to
    the metrics of the uninterrupted run. A training log edited since: refused in one line."""
    import shutil
    config = _project(tmp_path / "a" / "tanker", dataset_dir)
    assert "logs/" in config.read_text() and str(dataset_dir) not in config.read_text()
    sysid(["train", str(config), "-o", str(config.parent / "runs" / "whole")])
    _interrupt_after_saves(monkeypatch, 2)
    with pytest.raises(SystemExit):
        main(["train", str(config), "-o", str(config.parent / "runs" / "parted")])
    monkeypatch.undo()
    moved = shutil.copytree(config.parent, tmp_path / "b" / "t2")
    edited = shutil.copytree(config.parent, tmp_path / "c" / "t3")
    shutil.rmtree(config.parent)
    saved = torch.load(checkpoint_path(moved / "runs" / "parted"), weights_only=True)
    assert str(tmp_path / "a" / "tanker" / "logs") in saved["config"]   # the old absolute paths
    capsys.readouterr()
    sysid(["train", str(moved / "tiny.toml"), "-o", str(moved / "runs" / "parted"), "--resume"])
    assert "resumed after epoch 2" in capsys.readouterr().out
    assert (moved / "runs" / "parted" / "metrics.csv").read_text() == (moved / "runs" / "whole" / "metrics.csv").read_text()
    assert not checkpoint_path(moved / "runs" / "parted").exists()

    log = next((edited / "logs").iterdir())
    lines = log.read_text().splitlines(keepends=True)
    log.write_text("".join(lines[:-1]))   # the last sample gone: another training set
    from sysid.errors import CheckpointError
    with pytest.raises(CheckpointError, match="made with another config"):
        sysid(["train", str(edited / "tiny.toml"), "-o", str(edited / "runs" / "parted"), "--resume"])
