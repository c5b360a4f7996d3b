"""`sysid train` and `sysid evaluate RUN` end to end on two short real files."""
import json

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
