"""`sysid train` and `sysid evaluate RUN` end to end on two short real files."""
import json

import numpy as np
import pandas as pd
import pytest

from sysid.cli import run as sysid
from sysid.errors import CheckpointError, ConfigError, DataError
from tiny_experiment import TRAIN_FILES, tiny_experiment, tiny_test_file


def test_train_then_evaluate_run(dataset_dir, tmp_path):
    config = tiny_experiment(tmp_path / "tiny.toml", dataset_dir, seed=3, epochs=2, warm_start_epochs=5, patience=None)
    test_file = tiny_test_file(dataset_dir)
    sysid(["train", str(config), "-o", str(tmp_path / "run"), "--test", str(test_file)])
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["model"] == "hybrid" and summary["epochs"] == 2
    assert summary["gate"]["space"] == "inputs" and summary["gate"]["bank"] > 100
    trained = pd.read_csv(tmp_path / "run" / "metrics.csv")
    out = tmp_path / "m.csv"
    sysid(["evaluate", str(tmp_path / "run"), "--data", str(test_file), "--horizon", "30", "-o", str(out)])
    again = pd.read_csv(out)
    assert again.rmse_u.iloc[0] == pytest.approx(trained.rmse_u.iloc[0], rel=1e-9)
    assert again.rmse_r.iloc[0] == pytest.approx(trained.rmse_r.iloc[0], rel=1e-9)

    with pytest.raises(CheckpointError, match="run directory not found"):
        sysid(["evaluate", str(tmp_path / "nope"), "--data", str(test_file), "-o", str(out)])
    with pytest.raises(ConfigError, match="config file not found"):
        sysid(["train", str(tmp_path / "missing.toml"), "-o", str(tmp_path / "x")])
    bad = tmp_path / "bad.toml"
    bad.write_text(config.read_text().replace(TRAIN_FILES[1], "no_such_file.csv"))
    with pytest.raises(DataError, match="no_such_file.csv: file not found"):
        sysid(["train", str(bad), "-o", str(tmp_path / "y")])


def test_d2_without_test_logs_judges_each_held_out_validation_log(dataset_dir, tmp_path, capsys):
    """The shipped hybrid D2 config (3 epochs): no test logs, so its 5 held-out validation
    logs decide, each its own cell named by its file, resampled by log."""
    from pathlib import Path

    from cli_harness import in_process
    from sysid.evaluation.verdict import SHIP_FILE_MMG, VALIDATION, BaselineVerdict

    config = Path(__file__).resolve().parents[2] / "configs" / "experiments" / "hybrid_D2.toml"
    trained = in_process(capsys, "train", config, "--epochs", "3", "--threads", "1", "-o", tmp_path / "run")
    assert trained.code == 0, trained.err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    held_out = sorted(n for names in summary["data"]["held_out"]["groups"].values() for n in names)
    assert held_out == ["berthing_12-Nov-2020_11_38_50", "random_31-Jul-2020_12_29_58", "turn_14-Oct-2020_14_17_39",
                        "turn_14-Oct-2020_14_29_49", "zigzag_31-Jul-2020_13_42_53"]
    verdict = BaselineVerdict.from_dict(summary["verdict"])
    j = verdict.judgements[SHIP_FILE_MMG]
    assert verdict.decided_on == VALIDATION and (j.n_logs, j.n_windows) == (5, 827)
    assert "val_loss_multistep" in trained.out and "validation windows: 827 of 30 s" in trained.out
    assert sorted({c.log for c in j.cells}) == held_out and all(c.scenario == "" for c in j.cells)
    assert ", on 5 logs, 827 windows, 1 seed" in verdict.statement()
    assert verdict.statement() in trained.out + trained.err
    assert all(c.log in held_out for c in j.worst)
    # each log's cells hold its own windows: pooled again, they give the run's pooled validation RMSE
    pooled = {c.channel: c.model for c in verdict.cells if c.split == VALIDATION}
    for channel, rmse in pooled.items():
        cells = [c for c in j.cells if c.channel == channel]
        n = np.array([c.n_windows for c in cells])
        assert sum(n) == 827
        again = np.sqrt((n * np.array([c.model_rmse for c in cells]) ** 2).sum() / n.sum())
        assert again == pytest.approx(rmse, rel=1e-6)   # float32 rollouts
