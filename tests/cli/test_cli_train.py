"""`sysid train` and `sysid evaluate RUN` end to end on two short real files."""
import json

import numpy as np
import pandas as pd
import pytest

from sysid.cli import run as sysid
from sysid.errors import CheckpointError, ConfigError, DataError, OutputError
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
    logs decide, each its own cell named by its file, resampled by log, on its non-overlapping
    30-s windows: the test path's windows of the same logs."""
    from pathlib import Path

    from cli_harness import in_process
    from sysid.data.recordings import protocol_windows, read_run
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
    # val_loss_multistep and the pooled rows keep all 827 windows slid by 2 s; the verdict judges
    # the 58 of them that do not overlap
    assert verdict.decided_on == VALIDATION and (j.n_logs, j.n_windows) == (5, 58)
    assert "val_loss_multistep" in trained.out and "validation windows: 827 of 30 s" in trained.out
    assert sorted({c.log for c in j.cells}) == held_out and all(c.scenario == "" for c in j.cells)
    assert ", on 5 logs, 58 windows, 1 seed" in verdict.statement()
    assert "Decided on the non-overlapping validation windows at 30 s" in verdict.statement()
    assert verdict.statement() in trained.out + trained.err
    assert all(c.log in held_out for c in j.worst)
    # each log's judged windows are the test path's 30-s windows of that log (consecutive, from
    # its first sample), except after a window left out for frozen GNSS (random, t = 645.7 s)
    files = {p.stem: p for p in dataset_dir.rglob("*.csv")}
    for cell in verdict.evidence[VALIDATION][SHIP_FILE_MMG]:
        run = read_run(files[cell.log])
        test_starts = run.t[protocol_windows(len(run), 30)]
        assert cell.n_windows == test_starts.size, cell.log
        same = test_starts[:-1] if cell.log.startswith("random") else test_starts
        np.testing.assert_allclose(cell.window_start_s[:same.size], same, atol=1e-6)
        assert np.all(np.diff(cell.window_start_s) >= 30.0 - 1e-6)
    assert [c.n_windows for c in j.cells if c.channel == "u"] == [4, 22, 12, 14, 6]


def test_train_refuses_data_it_would_ignore(files, tmp_path):
    """``sysid train CONFIG --data DIR`` where CONFIG names its own logs: --data is the paper's
    data set root, read only with [experiment] dataset = D1/D2, so it would be ignored and the
    run trained on other logs than the user meant: one error naming --data, nothing written."""
    from tiny_experiment import tiny_config

    config = tmp_path / "own.toml"
    config.write_text(tiny_config(files))
    with pytest.raises(DataError, match=r"--data .*read only with \[experiment\] dataset = \"D1\" or \"D2\".*"
                                        r"own.toml names its own logs \(\[data\] train\): drop --data"):
        sysid(["train", str(config), "-o", str(tmp_path / "run"), "--data", str(files["test"].parent)])
    assert not (tmp_path / "run").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["own.toml"]


def test_evaluate_never_writes_over_a_log_the_run_was_trained_on(files, tmp_path):
    """``sysid evaluate RUN --data OTHER -o LOG`` where LOG is one of the run's training logs
    (a slip of the shell's completion): refused in one line naming it, the log unchanged;
    a new file beside it is written."""
    import shutil

    from tiny_experiment import tiny_config

    log = shutil.copy(files["train"], tmp_path / "monday.csv")
    config = tmp_path / "own.toml"
    config.write_text(tiny_config({"train": log}))
    sysid(["train", str(config), "-o", str(tmp_path / "run")])
    before = (tmp_path / "monday.csv").read_bytes()
    with pytest.raises(OutputError, match=r"monday.csv: is .*monday.csv, an input of this command"):
        sysid(["evaluate", str(tmp_path / "run"), "--data", str(files["test"]), "--horizon", "30", "-o", str(log)])
    assert (tmp_path / "monday.csv").read_bytes() == before
    sysid(["evaluate", str(tmp_path / "run"), "--data", str(files["test"]), "--horizon", "30",
           "-o", str(tmp_path / "metrics.csv")])
    assert list(pd.read_csv(tmp_path / "metrics.csv").horizon_s) == [30.0]
