"""A folder of the user's logs: its turning circles and zig-zags recognised from rudder and
heading alone (every FRT-DS-ESSO log as its folder says), and `sysid maneuver --recorded`
putting the recorded indices beside the model's with their differences."""
from __future__ import annotations

import shutil

import pandas as pd
import pytest

from sysid.data.recordings import read_runs
from sysid.maneuvers.recorded import recognised_kind

FOLDER_KIND = {"turning": "turning", "zigzag": "zigzag", "berthing": None, "random": None}


def test_every_real_log_is_recognised_as_its_folder_says(dataset_dir):
    files = sorted(dataset_dir.rglob("*.csv"))
    runs = read_runs(files, warn=None)
    found = {(r.path.parent.name, recognised_kind(r)) for r in runs}
    assert found == set(FOLDER_KIND.items())
    assert sum(recognised_kind(r) == "zigzag" for r in runs) == 8
    assert sum(recognised_kind(r) == "turning" for r in runs) == 15


def test_maneuver_with_recorded_logs(tmp_path, dataset_dir, capsys):
    from sysid.cli import run
    logs = tmp_path / "logs"
    logs.mkdir()
    shutil.copy(dataset_dir / "zigzag" / "zigzag_31-Jul-2020_13_04_24.csv", logs / "run_a.csv")
    shutil.copy(dataset_dir / "berthing" / "berthing_12-Nov-2020_11_07_23.csv", logs / "run_b.csv")
    run(["maneuver", "esso_osaka", "-o", str(tmp_path / "out"), "--recorded", str(logs), "--zigzag", "20/20",
         "--side", "starboard", "--duration", "20", "--no-report", "--eager"])
    out = capsys.readouterr().out
    assert "1 recorded maneuver(s) in 2 log(s): zigzag 20/20 run_a; 1 other log(s) left out" in out
    frame = pd.read_csv(tmp_path / "out" / "recorded_indices.csv").set_index("model")
    record, model = frame.loc["recorded"], frame.loc["esso_osaka"]
    assert (round(record.first_overshoot_deg, 2), round(record.second_overshoot_deg, 2)) == (5.75, 9.47)
    assert 0.0 < model.first_overshoot_deg < 2 * record.first_overshoot_deg
    line = next(x for x in out.splitlines() if "first_overshoot_deg" in x).split()
    assert float(line[-1]) == pytest.approx(float(line[-2]) - float(line[-3]), abs=2e-3)  # model - record
