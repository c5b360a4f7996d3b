"""The docs' "Getting started" path, as a user walks it: ``sysid init``, logs and ship filled
in, a hybrid trained, evaluated and reported, every command run from another working
directory. Real FRT-DS-ESSO logs under new names; none of the paper's test files."""
from __future__ import annotations

import json
import shutil

import pandas as pd
import pytest

from cli_harness import in_process
from sysid.package_data import bundled_dir
from sysid.data.datasets import TEST_FILES
from sysid.runs.rundir import RunDir

LOGS = {"logs/monday_turn.csv": "turning/turn_14-Oct-2020_14_17_39.csv",
        "logs/monday_zigzag.csv": "zigzag/zigzag_31-Jul-2020_13_42_53.csv",
        "logs/tuesday_zigzag.csv": "zigzag/zigzag_31-Jul-2020_13_57_45.csv",
        "test/wednesday_zigzag.csv": "zigzag/zigzag_31-Jul-2020_14_03_39.csv"}


@pytest.mark.slow
def test_getting_started_from_another_directory(tmp_path, dataset_dir, monkeypatch, capsys):
    assert not set(LOGS.values()) & set(TEST_FILES.values())
    home, elsewhere = tmp_path / "home", tmp_path / "elsewhere"
    home.mkdir(), elsewhere.mkdir()
    monkeypatch.chdir(home)
    assert in_process(capsys, "init", "tanker", "--ship", "my_tanker").code == 0
    project = home / "tanker"
    for new, old in LOGS.items():  # step 2: the logs
        shutil.copy(dataset_dir / old, project / new)
    # step 3: the ship's values (these logs are the Esso Osaka's)
    shutil.copy(bundled_dir("ships") / "esso_osaka.toml", project / "my_tanker.toml")
    # step 4: a small network, few epochs (a test, not a model to keep)
    config = project / "experiment.toml"
    text = config.read_text()
    for old, new in {"hidden = [64, 64]": "hidden = [16, 16]", "epochs = 400": "epochs = 3",
                     "warm_start_epochs = 150": "warm_start_epochs = 5", "horizons = [30.0, 100.0]": "horizons = [30.0]"
                     }.items():
        assert old in text, old
        text = text.replace(old, new)
    config.write_text(text)

    monkeypatch.chdir(elsewhere)  # step 5, from another working directory
    check = in_process(capsys, "ship", "check", "../home/tanker/my_tanker.toml")
    assert check.code == 0 and "course-unstable" in check.out
    run = elsewhere / "runs" / "first"
    out = in_process(capsys, "train", "../home/tanker/experiment.toml", "-o", run, "--test", "../home/tanker/test")
    assert out.code == 0, out.err
    resolved = (run / "config.toml").read_text()
    # the run's config names what it was made from: the pattern's files, the test folder's log,
    # relative to the run directory (sysid.runs.log_paths)
    assert '"../../../home/tanker/my_tanker.toml"' in resolved and '"../../../home/tanker/logs/monday_turn.csv"' in resolved
    assert '"../../../home/tanker/test/wednesday_zigzag.csv"' in resolved and 'dataset = ""' in resolved
    exp = RunDir.open(run).read_experiment()
    assert str(project / "logs" / "monday_turn.csv") in exp.data.train
    assert exp.data.test == (str(project / "test" / "wednesday_zigzag.csv"),)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "complete" and summary["model"] == "hybrid"
    assert summary["verdict"]["decided_on"] == "test" and summary["data"]["test_set"] == "files"
    trained = pd.read_csv(run / "metrics.csv")
    assert list(trained.file) == ["wednesday_zigzag"]

    again = in_process(capsys, "evaluate", run, "--data", "../home/tanker/test", "--horizon", "30", "-o", "m.csv")
    assert again.code == 0, again.err
    evaluated = pd.read_csv(elsewhere / "m.csv")
    for channel in ("rmse_u", "rmse_v", "rmse_r"):  # the same predictions, read back from the run
        assert evaluated[channel].iloc[0] == pytest.approx(trained[channel].iloc[0], rel=1e-9)

    report = in_process(capsys, "report", run, "-o", "reports/first", "-q")
    assert report.code == 0, report.err
    assert (elsewhere / "reports" / "first" / "report.pdf").stat().st_size > 10_000
