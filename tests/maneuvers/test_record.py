"""Against the record: the dataset's turning and zig-zag test runs are read as the maneuvers
the dataset's README lists, their indices sit beside each model's prediction of them, and
the reproduction's report shows that table."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from synthetic_rundir import write_reproduction  # noqa: E402

from sysid import MMG, load_ship  # noqa: E402
from sysid.maneuvers.recorded import (RECORD_FILE, recorded_maneuver, record_comparison, recorded_test_runs,  # noqa: E402
                                      write_record_comparison,
                                      side_by_side)
from sysid.report import build_report  # noqa: E402
from sysid.store.manifest import write_manifest  # noqa: E402

# the dataset README's table: file -> (n [rps], rudder [deg]); zig-zags +-A
README = {"Turning 20": ("turn_14-Oct-2020_14_56_07", 10.0, -20.0),
          "Turning 35": ("turn_14-Sep-2020_14_50_41", 8.0, 35.0),
          "Zigzag 20/20": ("zigzag_31-Jul-2020_13_04_24", 16.67, 20.0),
          "Zigzag 30/30": ("zigzag_31-Jul-2020_13_14_21", 16.67, 30.0)}


@pytest.fixture(scope="module")
def runs(dataset_dir):
    return recorded_test_runs(dataset_dir.parent)


def test_recorded_runs_are_the_maneuvers_the_dataset_lists(runs):
    for scenario, (stem, rps, rudder) in README.items():
        run = runs[scenario]
        maneuver, execute = recorded_maneuver(run, scenario)
        assert run.name == stem
        assert maneuver.rudder_deg == abs(rudder)
        if scenario.startswith("Turning"):
            assert maneuver.side.sign == math.copysign(1.0, rudder)
        else:
            assert maneuver.check_deg == abs(rudder)
        delta = np.degrees(run.inputs[:, 1])
        side = maneuver.side.sign
        assert side * delta[execute] < 0.5 * abs(rudder) <= side * delta[execute + 1]  # the order follows the execute
        assert run.inputs[execute, 0] == pytest.approx(rps, abs=0.01)


def test_record_and_predictions_side_by_side(runs):
    lab = MMG(load_ship("esso_osaka"))
    frame = record_comparison({"MMG lab": [lab], "two of it": [lab, lab]}, runs)
    assert list(frame.model[:3]) == ["recorded", "MMG lab", "two of it"]
    record = frame[frame.model == "recorded"].set_index("scenario")
    turn = record.loc["Turning 35"]
    assert 1.5 * 3.0 < turn.tactical_diameter_m < 4.0 * 3.0 and turn.transfer_m < turn.tactical_diameter_m
    assert 0.0 < turn.speed_loss_ratio < 1.0
    assert 0.0 < record.loc["Zigzag 20/20"].first_overshoot_deg < 20.0
    single = frame[frame.model == "MMG lab"].reset_index(drop=True)
    double = frame[frame.model == "two of it"].reset_index(drop=True)
    pd.testing.assert_series_equal(single.tactical_diameter_m, double.tactical_diameter_m)  # mean of equals
    assert (double.tactical_diameter_m_std.dropna() == 0.0).all() and double.n_members.eq(2).all()
    wide = side_by_side(frame)
    assert {"recorded", "MMG lab"} <= set(wide.columns)
    assert set(wide[wide.scenario == "Zigzag 30/30"]["index"]) == {"first_overshoot_deg", "second_overshoot_deg"}


def test_reproduction_report_shows_the_record_table(runs, tmp_path):
    repro = write_reproduction(tmp_path / "repro", scale=0.4, names=("mmg_paper", "mmg_lab"))
    frame = record_comparison({"MMG": [MMG(load_ship("esso_osaka", {"Xvr": 0.4535}))]}, runs)
    frame.to_csv(repro / RECORD_FILE, index=False)
    write_manifest(repro, "reproduction")
    paths = build_report(repro, tmp_path / "report")
    html = paths.html.read_text()
    assert "Standard-maneuver indices: recorded runs and predictions" in html
    advance = frame[(frame.model == "MMG") & (frame.scenario == "Turning 35")].advance_m.iloc[0]
    assert f"{advance:.3g}" in html


def test_models_predicted_in_workers_write_the_same_file(dataset_dir, tmp_path):
    """Two worker processes write the bytes the driver alone writes, rows in the order of
    the labels (the bundled ship under two labels, one of them first)."""
    models = {"MMG": "esso_osaka", "MMG again": "esso_osaka"}
    alone = write_record_comparison(tmp_path / "alone", models, dataset_dir.parent)
    workers = write_record_comparison(tmp_path / "workers", models, dataset_dir.parent, workers=2)
    assert workers.read_bytes() == alone.read_bytes()
    frame = pd.read_csv(alone)
    assert list(frame.model[:3]) == ["recorded", "MMG", "MMG again"]
    turning = frame[(frame.model == "MMG") & frame.maneuver.str.startswith("turning")]
    assert len(turning) == 2 and np.isfinite(turning.advance_m).all()
