"""A folder of the user's logs: its turning circles and zig-zags recognised from the
signals (`sysid.data.scenario`), and `sysid maneuver --recorded` putting the recorded
indices beside the model's with their differences."""
from __future__ import annotations

import shutil

import pandas as pd
import pytest

from sysid.data.recordings import read_runs
from sysid.maneuvers.recorded import recorded_maneuver_runs

def test_the_turning_circles_and_zig_zags_of_a_folder(dataset_dir, tmp_path):
    """Copies of one log of each folder under neutral names: the turning circle and the
    zig-zag are found, with the maneuver the dataset's README gives; the others left out."""
    names = {"turning": "turn_14-Sep-2020_14_50_41", "zigzag": "zigzag_31-Jul-2020_13_04_24",
             "berthing": "berthing_12-Nov-2020_11_07_23", "random": "random_31-Jul-2020_12_29_58"}
    paths = []
    for i, (folder, stem) in enumerate(names.items()):
        paths.append(tmp_path / f"log{i}.csv")
        shutil.copy(dataset_dir / folder / f"{stem}.csv", paths[-1])
    found, other = recorded_maneuver_runs(read_runs(paths, warn=None))
    assert list(found) == ["turning 35 log0", "zigzag 20/20 log1"]
    assert [r.name for r in other] == ["log2", "log3"]


def test_a_check_angle_beyond_180_deg_is_one_error_naming_the_log(dataset_dir, tmp_path):
    """A zig-zag whose heading deviation at the reversals reads 185 deg (a meandering run taken
    for one) is no IMO zig-zag: a DataError naming the log and the angle, so the folder's
    other runs are still compared (`recorded_maneuver_runs` leaves it out)."""
    from sysid.errors import DataError
    from sysid.maneuvers.recorded import recorded_maneuver
    path = tmp_path / "log0.csv"
    shutil.copy(dataset_dir / "zigzag" / "zigzag_31-Jul-2020_13_04_24.csv", path)
    run = read_runs([path], warn=None)[0]
    with pytest.raises(DataError, match=r"log0\.csv: a zig-zag's heading deviation of 185 deg"):
        recorded_maneuver(run, "Zigzag 20/185")
    maneuver, _ = recorded_maneuver(run, "Zigzag 20/20")
    assert (maneuver.rudder_deg, maneuver.check_deg) == (20.0, 20.0)


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
