"""A tiny hybrid experiment on two short berthing runs of the real dataset, for the tests
that train end to end (train, resume, sweeps): a few epochs, a 64-window batch, the gate on
the inputs with k = 5, one 30-s horizon; tested on a third berthing run."""
from __future__ import annotations

import json
from pathlib import Path

TRAIN_FILES = ("berthing_12-Nov-2020_11_07_23.csv", "berthing_12-Nov-2020_11_14_47.csv")
TEST_FILE = "berthing_12-Nov-2020_11_49_21.csv"


def tiny_experiment(path: Path, dataset_dir: Path, *, seed: int, epochs: int, warm_start_epochs: int,
                    patience: int | None = 100) -> Path:
    """Write the tiny experiment config to `path`; returns `path`."""
    files = [str(dataset_dir / "berthing" / name) for name in TRAIN_FILES]
    patience_line = f"patience = {patience}\n" if patience is not None else ""
    path.write_text(
        f"[experiment]\nname = 'tiny'\nmodel = 'hybrid'\nseed = {seed}\nship = 'esso_osaka'\n"
        f"[data]\nfiles = {json.dumps(files)}\n"
        f"[training]\nepochs = {epochs}\n{patience_line}warm_start_epochs = {warm_start_epochs}\nbatch_size = 64\n"
        "[gate]\nk = 5\nspace = 'inputs'\n[evaluation]\nhorizons = [30.0]\n")
    return path


def one_epoch_config(path: Path, files) -> Path:
    """A hybrid of one epoch on `files`, for the tests that expect training to stop on bad logs
    before it starts; returns `path`."""
    path.write_text("[experiment]\nname = 'bad'\nmodel = 'hybrid'\nseed = 1\nship = 'esso_osaka'\n"
                    f"[data]\nfiles = {json.dumps([str(f) for f in files])}\n"
                    "[training]\nepochs = 1\nwarm_start_epochs = 1\n[evaluation]\nhorizons = [30.0]\n")
    return path


def tiny_test_file(dataset_dir: Path) -> Path:
    """The berthing run the tiny experiment is evaluated on."""
    return dataset_dir / "berthing" / TEST_FILE


def tiny_config(files, **sections) -> str:
    """A hybrid that trains in seconds on one file; `sections` replace or add keys."""
    doc = {"experiment": {"name": "'fuzz'", "model": "'hybrid'", "seed": "1", "ship": "'esso_osaka'"},
           "data": {"files": json.dumps([str(files["train"])])},
           "network": {"hidden": "[8]"},
           "training": {"epochs": "1", "warm_start_epochs": "2", "batch_size": "64", "max_minutes": "1.0"},
           "gate": {"k": "3", "space": "'inputs'"},
           "evaluation": {"horizons": "[30.0]"}}
    for name, keys in sections.items():
        doc.setdefault(name, {}).update(keys)
    return "".join(f"[{name}]\n" + "".join(f"{k} = {v}\n" for k, v in keys.items()) for name, keys in doc.items())


def tiny_files(dataset_dir: Path) -> dict[str, Path]:
    """The one berthing run `tiny_config` trains on and the one it is tested on."""
    berthing = dataset_dir / "berthing"
    return {"train": berthing / TRAIN_FILES[0], "test": berthing / TEST_FILE}


def train_tiny_run(folder: Path, files: dict[str, Path]) -> Path:
    """``sysid train`` of `tiny_config` into ``folder/run`` (hybrid: model.pt, knn.pt); the
    run directory."""
    from sysid.cli import run
    config = folder / "tiny.toml"
    config.write_text(tiny_config(files))
    run(["train", str(config), "-o", str(folder / "run"), "--test", str(files["test"])])
    return folder / "run"
