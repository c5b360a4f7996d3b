"""`sysid train` and `sysid evaluate RUN` end to end on two short real files."""
import json

import pandas as pd
import pytest

from sysid.cli import run as sysid
from sysid.errors import CheckpointError, ConfigError, DataError


def test_train_then_evaluate_run(dataset_dir, tmp_path):
    files = [dataset_dir / "berthing" / f"berthing_12-Nov-2020_{t}.csv" for t in ("11_07_23", "11_14_47")]
    config = tmp_path / "tiny.toml"
    config.write_text(
        "[experiment]\nname = 'tiny'\nmodel = 'hybrid'\nseed = 3\n"
        f"[data]\nfiles = {json.dumps([str(f) for f in files])}\n"
        "[training]\nepochs = 2\nwarm_start_epochs = 5\nbatch_size = 64\n"
        "[gate]\nk = 5\nspace = 'inputs'\n[evaluation]\nhorizons = [30.0]\n")
    test_file = dataset_dir / "berthing" / "berthing_12-Nov-2020_11_49_21.csv"
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
    bad.write_text(config.read_text().replace(files[1].name, "no_such_file.csv"))
    with pytest.raises(DataError, match="no_such_file.csv: file not found"):
        sysid(["train", str(bad), "-o", str(tmp_path / "y")])
