"""Acceptance: the own-ship path from a folder of logs, as a user takes it, from another working
directory. Five logs of the dataset under new names, their columns renamed and in the user's
units (knots, degrees, rpm, deg/s; one log as Parquet), none of them a paper test file; a
config in its own folder naming them relative to itself, with ``[data.columns]``; then
``sysid train``, ``sysid evaluate``, ``sysid report``. The report's first page states the
verdict, and nothing says D1/D2 or the paper.

The project starts from ``sysid init``, as the docs' "Getting started" does."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from pypdf import PdfReader

from cli_harness import in_process
from own_logs import columns_table, write_own_log
from sysid.package_data import bundled_dir
from sysid.data.splits import PAPER_TEST_STEMS

LOGS = {  # the user's name -> the dataset file it is made from; role
    "harbour_1.csv": ("berthing/berthing_12-Nov-2020_13_37_05.csv", "train"),
    "harbour_2.parquet": ("berthing/berthing_12-Nov-2020_13_09_11.csv", "train"),
    "zigzag_a.csv": ("zigzag/zigzag_31-Jul-2020_13_57_45.csv", "train"),
    "harbour_3.csv": ("berthing/berthing_12-Nov-2020_13_21_03.csv", "validation"),
    "zigzag_b.csv": ("zigzag/zigzag_31-Jul-2020_13_29_19.csv", "test"),
}


def own_project(root: Path, dataset_dir: Path, capsys) -> Path:
    """The documented path: ``sysid init`` writes project/ (ship file, experiment config), the
    user's logs go to project/logs/, the config's [data] lists and [data.columns] are filled in
    and the network made small (a test, not a model to keep). Returns the config."""
    assert in_process(capsys, "init", str(root), "--ship", "own_ship").code == 0
    shutil.copy(bundled_dir("ships") / "esso_osaka.toml", root / "own_ship.toml")  # these logs' ship
    roles: dict[str, list[str]] = {"train": [], "validation": [], "test": []}
    for name, (source, role) in LOGS.items():
        assert Path(source).stem not in PAPER_TEST_STEMS
        write_own_log(dataset_dir / source, root / "logs" / name)
        roles[role].append(f"logs/{name}")
    config = root / "experiment.toml"
    text = config.read_text()
    for old, new in {'train = ["logs/*.csv"]': f"train = {json.dumps(roles['train'])}",
                     "validation = []": f"validation = {json.dumps(roles['validation'])}",
                     'test = ["test/*.csv"]': f"test = {json.dumps(roles['test'])}",
                     "hidden = [64, 64]": "hidden = [16, 16]", "epochs = 400": "epochs = 3",
                     "batch_size = 128": "batch_size = 64", "warm_start_epochs = 150": "warm_start_epochs = 20",
                     'space = "features"': 'space = "inputs"', "horizons = [30.0, 100.0]": "horizons = [30.0]"}.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    config.write_text(text + "\n" + columns_table())
    return config


@pytest.mark.slow
def test_own_logs_train_evaluate_and_report_from_another_directory(dataset_dir, tmp_path, capsys, monkeypatch):
    own_project(tmp_path / "project", dataset_dir, capsys)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    trained = in_process(capsys, "train", "../project/experiment.toml", "-o", "runs/own")
    assert trained.code == 0, trained.err
    run = work / "runs" / "own"
    summary = json.loads((run / "summary.json").read_text())
    used = summary["data"]
    assert used["training"] == "files" and used["test_set"] == "files" and summary["dataset"] == "files"
    names = {role: [Path(f["file"]).name for f in used[role]] for role in ("train", "validation", "test")}
    assert names == {"train": ["harbour_1.csv", "harbour_2.parquet", "zigzag_a.csv"],
                     "validation": ["harbour_3.csv"], "test": ["zigzag_b.csv"]}
    assert all(Path(f["file"]).parent == tmp_path / "project" / "logs" for role in names for f in used[role])
    split = summary["training"]["split"]["files"]   # the validation log is validation whole
    assert [f["train_windows"] for f in split if f["file"] == "harbour_3"] == [0]
    config = (run / "config.toml").read_text()
    assert 'dataset = ""' in config and "zigzag_b.csv" in config and "D1" not in config and "D2" not in config
    verdict = summary["verdict"]
    assert verdict["decided_on"] == "test" and summary["beats_baseline"] == verdict["beats_baseline"]
    assert {c["split"] for c in verdict["cells"]} == {"validation", "test"}
    said = {"beats": "The hybrid beats", "worse": "WARNING: The hybrid is WORSE",
            "not_distinguishable": "WARNING: The hybrid cannot be told apart", "diverged": "WARNING: The hybrid DIVERGED"}
    assert summary["beats_baseline"] == (verdict["outcome"] == "beats")
    if not summary["beats_baseline"]:
        assert trained.err.strip().splitlines()[-1].startswith(said[verdict["outcome"]])

    # evaluate the run on the user's test log (read with the run's column map)
    out = work / "again.csv"
    assert in_process(capsys, "evaluate", "runs/own", "--data", "../project/logs/zigzag_b.csv", "--horizon", "30",
                      "-o", out).code == 0
    again, metrics = pd.read_csv(out).iloc[0], pd.read_csv(run / "metrics.csv").iloc[0]
    assert again.file == "zigzag_b" and again.n_windows == metrics.n_windows > 0
    assert again.rmse_u == pytest.approx(metrics.rmse_u, rel=1e-9)

    reported = in_process(capsys, "report", "runs/own", "-o", "reports/own")
    assert reported.code == 0, reported.err
    first = [line for line in PdfReader(work / "reports" / "own" / "report.pdf").pages[0].extract_text().splitlines()
             if line.strip()]
    assert first[1] == "Verdict"
    assert first[2].startswith(said[verdict["outcome"]]), first[:4]
    html = (work / "reports" / "own" / "report.html").read_text()
    for paper_words in ("D1", "D2", "better than the paper", "cf. Fig"):
        assert paper_words not in html, paper_words
