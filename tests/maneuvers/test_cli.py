"""``sysid maneuver``: the directory it writes (row and column names, empty cells where an
index does not apply, criteria, trajectories, report, manifest) and one clear line for
every bad option, with nothing written."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from cli_harness import assert_refused, in_process  # noqa: E402

from sysid.maneuvers import INDEX_COLUMNS  # noqa: E402
from sysid.mmg.ship import ships_dir  # noqa: E402


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("maneuvers") / "kvlcc2"
    from sysid.cli import run
    run(["maneuver", "kvlcc2_l7", "-o", str(out), "--turning", "35", "10", "--zigzag", "10/10",
         "--side", "starboard", "--duration", "60", "--dt", "0.2", "--eager"])
    return out


def test_directory_holds_indices_criteria_trajectories_and_report(written):
    indices = pd.read_csv(written / "indices.csv")
    assert list(indices.maneuver) == ["turning_35_starboard", "turning_10_starboard", "zigzag_10_10_starboard"]
    assert list(indices.columns[3:3 + len(INDEX_COLUMNS)]) == list(INDEX_COLUMNS)
    turn = indices.set_index("maneuver").loc["turning_35_starboard"]
    assert 2.0 < turn.advance_m / 7.0 < 4.5 and turn.tactical_diameter_m > turn.transfer_m > 0
    assert pd.isna(turn.first_overshoot_deg) and pd.isna(turn.head_reach_m)  # empty: not a zig-zag, no stop
    assert turn.imo_advance == "met" and turn.imo_tactical_diameter == "met"
    zigzag = indices.set_index("maneuver").loc["zigzag_10_10_starboard"]
    assert 0 < zigzag.first_overshoot_deg < 10 and pd.isna(zigzag.advance_m)
    assert zigzag.imo_first_overshoot in ("met", "not met")  # kvlcc2_l7 gives a scale: assessed
    assert indices.gate_off_share.isna().all()  # the MMG has no gate
    criteria = pd.read_csv(written / "criteria.csv")
    assert {"advance_m", "tactical_diameter_m", "initial_turning_distance_m", "first_overshoot_deg",
            "second_overshoot_deg"} <= set(criteria["index"])
    row = criteria[(criteria.maneuver == "turning_35_starboard") & (criteria["index"] == "advance_m")].iloc[0]
    assert row.limit == pytest.approx(4.5 * 7.0) and row.ratio == pytest.approx(turn.advance_m / 7.0, rel=1e-6)
    traj = pd.read_csv(written / "trajectories.csv")
    one = traj[traj.maneuver == "turning_35_starboard"]
    assert len(one) == 301 and one.t.iloc[-1] == pytest.approx(60.0)
    assert one.u.iloc[0] == pytest.approx(1.17248) and one.psi.iloc[0] == 0.0
    assert np.degrees(one.rudder_angle.max()) == pytest.approx(35.0)
    summary = json.loads((written / "maneuvers.json").read_text())
    assert summary["sources"]["speed"].startswith("ship file") and summary["sources"]["rps"].startswith("straight")
    assert summary["conditions"]["rudder_rate_deg_s"] == pytest.approx(2.32 * math.sqrt(45.714))
    manifest = json.loads((written / "manifest.json").read_text())
    assert manifest["kind"] == "maneuvers" and "report.pdf" in manifest["files"]
    html = (written / "report.html").read_text()
    assert "IMO MSC.137(76) criteria" in html and "x0 (north) [m]" in html and "<svg" in html


def test_report_command_rebuilds_a_maneuvers_report(written, tmp_path, capsys):
    outcome = in_process(capsys, "report", written, "-o", tmp_path / "again")
    assert outcome.code == 0, outcome.err
    assert (tmp_path / "again" / "report.pdf").stat().st_size > 10_000


@pytest.mark.parametrize("args, named", [
    (["--dt", "0"], "--dt"), (["--dt", "nan"], "--dt"), (["--speed", "-1"], "--speed"),
    (["--rudder-rate", "inf"], "--rudder-rate"), (["--duration", "1e9"], "--duration"),
    (["--zigzag", "10"], "--zigzag"), (["--zigzag", "10/abc"], "--zigzag"), (["--turning", "95"], "95"),
    (["--wind", "3"], "--wind"), (["--wind", "-2,40"], "--wind"), (["--side", "up"], "--side"),
    (["--integrator", "rk5"], "--integrator"), (["--crash-stop"], "ahead motion"),
])
def test_bad_options_are_one_clear_line_and_nothing_written(tmp_path, capsys, args, named):
    out = tmp_path / "out"
    outcome = in_process(capsys, "maneuver", "kvlcc2_l7", "-o", out, "--eager", "--duration", "5", *args)
    assert_refused(outcome, 2, named, absent=(out,))


def test_missing_approach_speed_names_the_ship_file_and_the_fix(tmp_path, capsys):
    text = (ships_dir() / "kvlcc2_l7.toml").read_text().replace("approach_speed = 1.17248", "")
    ship = tmp_path / "ship.toml"
    ship.write_text(text)
    outcome = in_process(capsys, "maneuver", ship, "-o", tmp_path / "out", "--eager")
    line = assert_refused(outcome, 2, str(ship), "--speed", absent=(tmp_path / "out",))
    assert "approach_speed" in line
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("scale = 45.714", "scale = 0.5"))
    assert_refused(in_process(capsys, "maneuver", bad, "-o", tmp_path / "o2"), 2, "[maneuvering] scale")


def test_a_maneuver_that_diverged_is_one_warning_line_and_marked_in_the_indices(tmp_path, capsys):
    """The kvlcc2_l7 ship file with N_r = +0.3 (yaw unstable): the turn passes 3 U0 within
    seconds; the line names the maneuver and the time, indices.csv marks it."""
    source = (ships_dir() / "kvlcc2_l7.toml").read_text()
    assert "N_r = -0.049" in source
    ship = tmp_path / "unstable.toml"
    ship.write_text(source.replace("N_r = -0.049", "N_r = 0.3"))
    out = tmp_path / "out"
    result = in_process(capsys, "maneuver", ship, "-o", out, "--turning", "35", "--side", "starboard", "--eager",
                        "--no-report", "--duration", "60", "--dt", "0.2", "--rps", "11.8")
    assert result.code == 0, result.err
    table = pd.read_csv(out / "indices.csv")
    assert table["diverged"].tolist() == [True] and 0 < table["diverged_at_s"][0] < 60
    warnings = [line for line in result.err.splitlines() if line.startswith("WARNING: diverged")]
    assert len(warnings) == 1
    assert f"turning_35_starboard (kvlcc2_l7) at t = {table['diverged_at_s'][0]:.1f} s" in warnings[0]


@pytest.fixture(scope="module")
def beside(trained, tmp_path_factory):
    """``sysid maneuver`` of the session's tiny trained hybrid: its directory and output."""
    import contextlib
    import io
    from sysid.cli import run
    out = tmp_path_factory.mktemp("beside") / "m"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        run(["maneuver", str(trained), "-o", str(out), "--turning", "35", "--zigzag", "10/10", "--side", "starboard",
             "--dt", "0.5", "--duration", "120", "--eager"])
    return out, printed.getvalue()


def test_a_learned_model_is_shown_beside_its_physics_baseline_run_as_a_ship_file(beside, trained, tmp_path, capsys):
    """The baseline's rows in the run's maneuvers directory are those of ``sysid maneuver
    SHIPFILE`` run on its own (an independent path) under the same conditions given as
    options; the learned model's rows and columns are those of before, the baseline's after."""
    from sysid.maneuvers import BASELINE_LABEL, load_maneuver_model

    out, _ = beside
    ship = load_maneuver_model(trained).ship
    assert not ship.overrides  # the tiny run changes no MMG coefficient: its baseline is the ship file's MMG
    summary = json.loads((out / "maneuvers.json").read_text())
    assert summary["baseline"]["model"] == BASELINE_LABEL and summary["baseline"]["left_out"] == []
    c = summary["conditions"]
    alone = tmp_path / "alone"
    done = in_process(capsys, "maneuver", ship.source, "-o", alone, "--turning", "35", "--zigzag", "10/10", "--side",
                      "starboard", "--dt", "0.5", "--duration", "120", "--eager", "--no-report",
                      "--speed", repr(c["speed_m_s"]), "--rps", repr(c["rps"]), "--rudder-rate",
                      repr(c["rudder_rate_deg_s"]))
    assert done.code == 0, done.err
    assert "physics baseline" not in done.out  # a ship file is the physics model: nothing beside it
    indices = pd.read_csv(out / "indices.csv")
    assert list(indices.model) == [trained.name] * 2 + [BASELINE_LABEL] * 2
    assert list(indices.columns[3:3 + len(INDEX_COLUMNS)]) == list(INDEX_COLUMNS)
    mine = indices[indices.model == BASELINE_LABEL].drop(columns="model").reset_index(drop=True)
    theirs = pd.read_csv(alone / "indices.csv").drop(columns="model")
    shared = [c for c in theirs.columns if c.endswith(("_m", "_deg", "_ratio"))]
    assert theirs.tactical_diameter_m.notna().any() and theirs.first_overshoot_deg.notna().any()
    pd.testing.assert_frame_equal(mine[["maneuver", *shared]], theirs[["maneuver", *shared]], rtol=1e-12)
    assert list(mine.imo_advance[:1]) == list(theirs.imo_advance[:1])
    traj = pd.read_csv(out / "trajectories.csv")
    ours = traj[traj.model == BASELINE_LABEL].drop(columns="model").reset_index(drop=True)
    np.testing.assert_allclose(ours[["t", "x", "u", "y", "v", "psi", "r"]],
                               pd.read_csv(alone / "trajectories.csv")[["t", "x", "u", "y", "v", "psi", "r"]],
                               rtol=1e-9, atol=1e-12)
    criteria = pd.read_csv(out / "criteria.csv")
    assert set(criteria.model) == {trained.name, BASELINE_LABEL}


def test_the_printout_and_the_report_name_the_baseline(beside, trained, tmp_path, capsys):
    """Printed: a row per model and a table of both models' indices with the difference;
    the report: the table, the legend and the summary name the baseline; --no-baseline
    leaves it out (said)."""
    from sysid.maneuvers import BASELINE_LABEL

    out, printed = beside
    indices = pd.read_csv(out / "indices.csv").set_index(["maneuver", "model"])
    advance = [indices.loc[("turning_35_starboard", m), "advance_m"] for m in (trained.name, BASELINE_LABEL)]
    line = next(row for row in printed.splitlines() if row.split()[:2] == ["turning_35_starboard", "advance_m"])
    assert line.split()[2:] == ["m", f"{advance[0]:.3f}", f"{advance[1]:.3f}", f"{advance[0] - advance[1]:.3f}"]
    assert f"{trained.name} beside its physics baseline {BASELINE_LABEL}" in printed
    html = (out / "report.html").read_text()
    assert f"{trained.name} beside its physics baseline {BASELINE_LABEL}" in html
    assert f"dashed: physics baseline {BASELINE_LABEL}" in html and "Physics baseline" in html
    assert f"Maneuver indices: {trained.name}" in html and f"Maneuver indices: {BASELINE_LABEL}" in html
    assert "x0 (north) [m]" in html and "t from the execute [s]" in html  # the figures keep their units
    bare = in_process(capsys, "maneuver", trained, "-o", tmp_path / "bare", "--turning", "35", "--side", "starboard",
                      "--dt", "0.5", "--duration", "60", "--eager", "--no-report", "--no-baseline")
    assert bare.code == 0, bare.err
    assert "--no-baseline" in bare.out
    assert list(pd.read_csv(tmp_path / "bare" / "indices.csv").model) == [trained.name]
    assert json.loads((tmp_path / "bare" / "maneuvers.json").read_text())["baseline"] is None
