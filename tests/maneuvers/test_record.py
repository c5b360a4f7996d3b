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
from sysid.maneuvers.recorded import (OPEN_LOOP_COLUMNS, RECORD_FILE, approach_conditions,  # noqa: E402
                                      recorded_maneuver, record_comparison, recorded_test_runs,
                                      write_record_comparison, side_by_side)
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


@pytest.fixture(scope="module")
def lab_frame(runs):
    """The record beside the lab MMG (esso_osaka) once and as two equal members."""
    lab = MMG(load_ship("esso_osaka"))
    return record_comparison({"MMG lab": [lab], "two of it": [lab, lab]}, runs)


def test_record_and_predictions_side_by_side(lab_frame):
    frame = lab_frame
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
    assert set(wide[wide.scenario == "Zigzag 30/30"]["index"]) == {"first_overshoot_deg", "second_overshoot_deg",
                                                                   *OPEN_LOOP_COLUMNS}


def test_the_record_s_approach_is_read_from_the_record(runs, dataset_dir):
    """u and n at the execute, the fastest rudder move and the mean wind, counted
    independently from the 10-Hz file's 1-Hz samples (the dataset README: 16.67 rps)."""
    run = runs["Zigzag 20/20"]
    maneuver, execute = recorded_maneuver(run, "Zigzag 20/20")
    c = approach_conditions(run, execute)
    raw = pd.read_csv(dataset_dir / "zigzag" / f"{run.name}.csv").dropna().iloc[::10].reset_index(drop=True)
    assert c.speed == pytest.approx(raw["u_velo [m/s]"][execute], rel=1e-12) and round(c.speed, 3) == 0.316
    assert c.rps == pytest.approx(16.67, abs=0.01)
    assert c.rudder_rate == pytest.approx(np.abs(np.diff(np.degrees(raw["delta_rudder [rad]"]))).max(), rel=1e-12)
    assert c.wind_speed == pytest.approx(raw["wind_velo_true [m/s]"][execute:].mean(), rel=1e-12)
    assert c.duration == pytest.approx(raw["t [s]"].iloc[-1] - raw["t [s]"][execute])
    assert c.dt == 0.1 and c.method.value == "rk4"


def test_zigzag_overshoots_are_like_for_like(lab_frame):
    """The IMO overshoots of the record (heading-triggered reversals) and of the lab MMG run
    closed loop from the record's approach: both positive, the model's within a few degrees
    of the record's (issue 32: +4.2 / +6.1 against 5.75 / 9.47 on Zigzag 20/20); the
    open-loop peaks keep the old numbers under their own name (-8.0 deg)."""
    rows = lab_frame.set_index(["scenario", "model"])
    record, lab = rows.loc[("Zigzag 20/20", "recorded")], rows.loc[("Zigzag 20/20", "MMG lab")]
    assert (round(record.first_overshoot_deg, 2), round(record.second_overshoot_deg, 2)) == (5.75, 9.47)
    assert record.open_loop_first_peak_deg == record.first_overshoot_deg  # its reversals are at the check angle
    for scenario in ("Zigzag 20/20", "Zigzag 30/30"):
        rec, model = rows.loc[(scenario, "recorded")], rows.loc[(scenario, "MMG lab")]
        for index in ("first_overshoot_deg", "second_overshoot_deg"):
            assert 0.0 < model[index] < 2.0 * rec[index] and abs(model[index] - rec[index]) < 3.0, (scenario, index)
    assert lab.open_loop_first_peak_deg == pytest.approx(-8.0, abs=0.05)
    twice = rows.loc[("Zigzag 20/20", "two of it")]
    assert twice.first_overshoot_deg == lab.first_overshoot_deg and twice.first_overshoot_deg_std == 0.0


def test_reproduction_report_shows_the_record_table(runs, tmp_path):
    repro = write_reproduction(tmp_path / "repro", scale=0.4, names=("mmg_paper", "mmg_lab"))
    frame = record_comparison({"MMG": [MMG(load_ship("esso_osaka", {"Xvr": 0.4535}))]}, runs, closed_loop_dt=0.5)
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
    alone = write_record_comparison(tmp_path / "alone", models, dataset_dir.parent, closed_loop_dt=0.5)
    workers = write_record_comparison(tmp_path / "workers", models, dataset_dir.parent, workers=2, closed_loop_dt=0.5)
    assert workers.read_bytes() == alone.read_bytes()
    frame = pd.read_csv(alone)
    assert list(frame.model[:3]) == ["recorded", "MMG", "MMG again"]
    turning = frame[(frame.model == "MMG") & frame.maneuver.str.startswith("turning")]
    assert len(turning) == 2 and np.isfinite(turning.advance_m).all()


def test_seeds_and_their_ensemble_side_by_side_equal_each_model_alone(runs):
    """`group_predictions` (two gated hybrids and their mean-of-seeds ensemble as one batched
    rollout, each on its own rows) against `_predictions` of each model alone: the same
    open-loop states and closed-loop zig-zag indices to round-off, the same gate shares
    (the gates' decisions are exact either way); the gate switches the FNN off on part of
    the runs, so both decisions are taken."""
    import torch
    from sysid.dynamics.integrators import Method
    from sysid.hybrid.correction import ForceCorrection, correction_inputs
    from sysid.hybrid.ensemble import MembersSideBySide, SeedEnsemble
    from sysid.hybrid.force_models import CorrectedModel
    from sysid.hybrid.knn_gate import KNNGate
    from sysid.maneuvers.recorded import _execute_starts, _maneuvers, _predictions, group_predictions
    from sysid.mmg.wind import relative_wind

    recorded = list(runs.values())
    states = torch.tensor(np.concatenate([r.states[::4] for r in recorded[:2]]))  # the turning circles only
    inputs = torch.tensor(np.concatenate([r.inputs[::4] for r in recorded[:2]]))
    wind = torch.stack(relative_wind(states[:, 1], states[:, 3], states[:, 4], inputs[:, 2], inputs[:, 3]), -1)
    s = correction_inputs(states, inputs, wind)

    def hybrid(seed: int) -> CorrectedModel:
        torch.manual_seed(seed)
        net = ForceCorrection((16, 16), torch.float64)
        net.set_standardization(s.mean(0), s.std(0), torch.zeros(3), torch.tensor([0.5, 0.5, 2.0]))
        with torch.no_grad():
            bank = net.features(s)
        return CorrectedModel(MMG(load_ship("esso_osaka")), net, KNNGate(5, 0.99, 16, torch.float64).fit(bank))

    members = [hybrid(1), hybrid(2)]
    starts, maneuvers = _execute_starts(runs), _maneuvers(runs)
    assert MembersSideBySide(SeedEnsemble(members)).no_grad_rate(torch.zeros(3 * len(recorded), 6,
                                                                              dtype=torch.float64)) is not None
    seeds, ensemble = group_predictions(members, recorded, starts, Method.EULER, maneuvers)
    alone = [_predictions(m, recorded, starts, Method.EULER, maneuvers) for m in (*members, SeedEnsemble(members))]
    shares = []
    for together, own in zip((*seeds, ensemble), alone):
        for (x, share, closed), (x_own, share_own, closed_own) in zip(together, own):
            np.testing.assert_allclose(x, x_own, rtol=1e-9, atol=1e-9)
            assert share == share_own
            shares.append(share)
            assert (closed is None) == (closed_own is None)
            if closed is not None:
                for key, value in closed.items():
                    assert value == pytest.approx(closed_own[key], rel=1e-9, abs=1e-9, nan_ok=True)
    assert 0.0 < max(shares) and min(shares) < 1.0
