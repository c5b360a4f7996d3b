"""The trainer's one logging channel (`sysid.identify.journal`): without a ``log`` callable
its lines go to the ``logging`` logger at INFO and nothing to stdout; and the identify
package keeps its shape: no ``print`` and no function longer than 60 lines."""
from __future__ import annotations

import ast
import logging
from pathlib import Path

from sysid.config.experiment import parse_experiment
from sysid.data.recordings import read_runs
from sysid.device import compute_threads
from sysid.identify.trainer import Trainer
from tiny_experiment import TRAIN_FILES

PACKAGE = Path(__file__).resolve().parents[2] / "sysid" / "identify"
LONGEST = 60


def _functions(tree: ast.AST):
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


def test_identify_has_no_print_and_no_function_over_60_lines():
    long, printed = [], []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        long += [f"{path.name}:{f.name} {f.end_lineno - f.lineno + 1}" for f in _functions(tree)
                 if f.end_lineno - f.lineno + 1 > LONGEST]
        printed += [f"{path.name}:{n.lineno}" for n in ast.walk(tree)
                    if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "print"]
    assert long == [] and printed == []
    assert any(path.name == "trainer.py" for path in PACKAGE.rglob("*.py"))  # the walk sees the package


def test_trainer_logs_through_logging_only(dataset_dir, caplog, capsys, monkeypatch):
    exp = parse_experiment({"experiment": {"name": "logged", "model": "hybrid", "seed": 1},
                            "network": {"hidden": [8]},
                            "training": {"epochs": 2, "warm_start_epochs": 2, "batch_size": 64},
                            "gate": {"k": 3, "space": "inputs"}, "evaluation": {"horizons": [30.0]}})
    # a CLI run earlier in this process leaves the "sysid" logger writing to stdout, not
    # propagating (`sysid.logs.configure`): undone here, anything on stdout was printed
    monkeypatch.setattr(logging.getLogger("sysid"), "handlers", [])
    monkeypatch.setattr(logging.getLogger("sysid"), "propagate", True)
    runs = read_runs([dataset_dir / "berthing" / TRAIN_FILES[0]])
    with compute_threads(1), caplog.at_level(logging.INFO, logger="sysid.identify.journal"):
        trainer = Trainer(exp, progress=True).fit(runs)
    lines = [r.getMessage() for r in caplog.records if r.name == "sysid.identify.journal"]
    assert all(r.levelno == logging.INFO for r in caplog.records if r.name == "sysid.identify.journal")
    windows = f"{trainer.summary_.n_train_windows} training and {trainer.summary_.n_val_windows} validation windows"
    assert lines[0].startswith(windows)
    assert any(line.startswith("MMG-only multi-step loss: training") for line in lines)
    assert any(line.startswith("  epoch 2/2: training") for line in lines)  # progress off a terminal
    assert any(line.startswith("train: 2 epochs, best early-stopping loss") for line in lines)
    assert lines[-1].startswith(f"val_loss_multistep {trainer.summary_.val_loss_multistep:.5f}: the final model")
    assert capsys.readouterr().out == ""

