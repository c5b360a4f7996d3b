"""A run directory keeps the ship file it was made with (``ship/NAME.toml``, in its
manifest): after the project folder is moved, or the ship file edited, the run evaluates
and maneuvers with the MMG and physics baseline it was trained and judged beside. The
truth is what the run wrote when it was made (metrics.csv, baseline_metrics.csv) and its
maneuvers before the move; an older run without the copy loads from its config's path.

The run: the scratch tanker's N_r identified by Levenberg-Marquardt (2 iterations) from two
logs simulated with known derivatives, tested on a third (a few seconds)."""
import json
import shutil

import numpy as np
import pandas as pd
import pytest
import torch

from sysid import MMG, load_ship
from sysid.data.recordings import read_runs
from sysid.dynamics.integrators import Integrator
from sysid.evaluation.evaluate import evaluate_model
from sysid.evaluation.verdict import SHIP_FILE_MMG
from sysid.hybrid.ensemble import _common_mmg
from sysid.hybrid.force_models import build_model
from sysid.config.experiment import parse_experiment
from sysid.maneuvers import load_maneuver_model
from sysid.report.build import ship_size
from sysid.report.source import read_source
from sysid.runs.layout import load_model
from sysid.runs.lifecycle import physics_baselines
from sysid.runs.rundir import RunDir
from sysid.store.manifest import verify_manifest, write_manifest

from cli_harness import in_process
from scratch_ship import SCRATCH, simulated_logs

TRUTH = {"Y_v": -0.36, "N_r": -0.055}   # the ship file says -0.315, -0.049
# the ship file without its [ship] name: the ship is called by the file's stem, "tanker"
SHIP = SCRATCH.replace('name = "scratch_tanker"\n', "") + "\n[maneuvering]\napproach_speed = 0.9\n"
EDITED = SHIP.replace("N_r = -0.049", "N_r = -0.060").replace("N_v = -0.137", "N_v = -0.150")
RMSE = ["rmse_u", "rmse_v", "rmse_r"]
MANEUVER = ["--turning", "35", "--side", "starboard", "--duration", "40", "--dt", "0.4", "--no-report", "--eager"]


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    """A user's project folder: ``tanker.toml``, logs, ``identify.toml`` (ship =
    "tanker.toml", relative), the run ``runs/first`` and its maneuvers ``before/``."""
    from sysid.cli import run as sysid
    folder = tmp_path_factory.mktemp("own") / "project"
    folder.mkdir()
    (folder / "tanker.toml").write_text(SHIP)
    logs = simulated_logs(folder / "tanker.toml", folder, TRUTH, seconds=120.0)
    (folder / "identify.toml").write_text(
        "[experiment]\nname = 'first'\nmodel = 'mmg'\nship = 'tanker.toml'\nseed = 0\n"
        f"[data]\ntrain = {json.dumps([p.name for p in logs[:2]])}\ntest = [{json.dumps(logs[2].name)}]\n"
        "[identify]\nparameters = ['N_r']\nsolver = 'levenberg_marquardt'\niterations = 2\n"
        "[evaluation]\nhorizons = [30.0]\n")
    sysid(["train", str(folder / "identify.toml"), "-o", str(folder / "runs" / "first"), "-q"])
    sysid(["maneuver", str(folder / "runs" / "first"), "-o", str(folder / "before"), "-q", *MANEUVER])
    return folder


def _baseline_rmse(run_dir, test_log) -> np.ndarray:
    """(u, v_m, r) RMSE of the run's physics baseline (the ship file's MMG) on `test_log` at 30 s."""
    exp, model = load_model(run_dir)
    baseline = physics_baselines(exp, model, torch.float64)[SHIP_FILE_MMG]
    evaluation = evaluate_model(baseline, read_runs([test_log], exp.data.rate), [30.0],
                                Integrator(exp.evaluation.integrator), traces=False)
    return evaluation.metrics[RMSE].to_numpy()


def _written(run_dir, table: str) -> np.ndarray:
    frame = pd.read_csv(run_dir / table)
    return frame[RMSE].to_numpy()


def test_the_run_keeps_its_ship_file_in_its_manifest(project):
    run = project / "runs" / "first"
    copy = run / "ship" / "tanker.toml"
    assert copy.read_text() == SHIP
    assert "ship/tanker.toml" in verify_manifest(run, "run")["files"]
    assert RunDir(run).ship_copy(str(project / "tanker.toml")) == copy
    # the config names the file it was made from, as before
    assert json.loads((run / "summary.json").read_text())["ship"] == str(project / "tanker.toml")
    exp = RunDir.open(run).read_experiment()
    assert exp.experiment.ship == str(copy.absolute())


def test_moved_project_evaluates_and_maneuvers_as_before(project, tmp_path, capsys):
    moved = tmp_path / "moved"
    shutil.move(project, moved)   # the run's config names project/tanker.toml, gone now
    try:
        run = moved / "runs" / "first"
        out = in_process(capsys, "evaluate", run, "--data", moved / "random.csv", "-o", tmp_path / "m.csv")
        assert out.code == 0, out.err
        assert "WARNING" not in out.err and "differs" not in out.err
        np.testing.assert_allclose(_written(tmp_path, "m.csv"), _written(run, "metrics.csv"), rtol=1e-5)
        np.testing.assert_allclose(_baseline_rmse(run, moved / "random.csv"),
                                   _written(run, "baseline_metrics.csv"), rtol=1e-5)
        out = in_process(capsys, "maneuver", run, "-o", tmp_path / "after", *MANEUVER)
        assert out.code == 0, out.err
        before = pd.read_csv(moved / "before" / "indices.csv")
        after = pd.read_csv(tmp_path / "after" / "indices.csv")
        numbers = before.select_dtypes("number").columns
        assert len(numbers) and len(before)
        pd.testing.assert_frame_equal(after[numbers], before[numbers])
        subject = load_maneuver_model(run)
        assert subject.ship.name == "tanker"   # the file's stem, as when it was trained
        assert subject.ship.source == str(run.absolute() / "ship" / "tanker.toml")
        assert ship_size(read_source(run)) == (4.0, 0.72)   # the report's outlines: L_pp, B [m] of SHIP
    finally:
        shutil.move(moved, project)


def test_edited_ship_file_leaves_the_run_as_judged_and_says_so(project, tmp_path, capsys):
    run = project / "runs" / "first"
    test_log = project / "random.csv"
    original = project / "tanker.toml"
    original.write_text(EDITED)
    try:
        out = in_process(capsys, "evaluate", run, "--data", test_log, "-o", tmp_path / "m.csv")
        assert out.code == 0, out.err
        warnings = [line for line in out.err.splitlines() if "differs from" in line]
        assert len(warnings) == 1, out.err
        assert str(original) in warnings[0] and str(run / "ship" / "tanker.toml") in warnings[0]
        np.testing.assert_allclose(_written(tmp_path, "m.csv"), _written(run, "metrics.csv"), rtol=1e-5)
        kept = _baseline_rmse(run, test_log)
        np.testing.assert_allclose(kept, _written(run, "baseline_metrics.csv"), rtol=1e-5)
        # the edited file, given explicitly, is the baseline: the edited ship's MMG on the same windows
        exp, model = load_model(run, ship=str(original))
        edited = evaluate_model(physics_baselines(exp, model, torch.float64)[SHIP_FILE_MMG],
                                read_runs([test_log]), [30.0], traces=False).metrics[RMSE].to_numpy()
        direct = evaluate_model(MMG(load_ship(original)), read_runs([test_log]), [30.0],
                                traces=False).metrics[RMSE].to_numpy()
        np.testing.assert_allclose(edited, direct, rtol=1e-12)
        assert abs(edited[0, 2] - kept[0, 2]) > 1e-4   # N_r and N_v moved the yaw rate's error
        out = in_process(capsys, "evaluate", run, "--data", test_log, "--ship", original, "-o", tmp_path / "e.csv")
        assert out.code == 0 and "differs from" not in out.err, out.err
        # edited again: runs with the same copy (an ensemble's seeds) say it once per process
        original.write_text(EDITED.replace("N_v = -0.150", "N_v = -0.140"))
        seeds = [shutil.copytree(run, tmp_path / "seeds" / f"seed{k}") for k in (0, 1)]
        out = in_process(capsys, "maneuver", tmp_path / "seeds", "-o", tmp_path / "mnv", *MANEUVER)
        assert out.code == 0, out.err
        assert sum("differs from" in line for line in out.err.splitlines()) == 1, out.err
        assert str(seeds[0] / "ship" / "tanker.toml") in out.err
    finally:
        original.write_text(SHIP)


def test_run_without_its_copy_loads_from_the_config_path(project, tmp_path, capsys):
    """A run written before runs kept their ship file: no ship/ folder in it or its manifest."""
    old = shutil.copytree(project / "runs" / "first", tmp_path / "old")
    shutil.rmtree(old / "ship")
    (old / "manifest.json").unlink()
    write_manifest(old, "run")
    exp, _ = load_model(old)
    assert exp.experiment.ship == str(project / "tanker.toml")
    np.testing.assert_allclose(_baseline_rmse(old, project / "random.csv"),
                               _written(old, "baseline_metrics.csv"), rtol=1e-5)
    out = in_process(capsys, "evaluate", old, "--data", project / "random.csv", "-o", tmp_path / "m.csv")
    assert out.code == 0 and "WARNING" not in out.err, out.err
    np.testing.assert_allclose(_written(tmp_path, "m.csv"), _written(old, "metrics.csv"), rtol=1e-5)


def test_members_reading_their_own_copies_share_one_mmg(tmp_path):
    """An ensemble's members, each loaded from its run's copy of one ship file, have one MMG
    (the ensemble's shared-MMG path), though each read it from another path."""
    models = []
    for k in range(2):
        (tmp_path / f"seed{k}").mkdir()
        ship = tmp_path / f"seed{k}" / "tanker.toml"
        ship.write_text(SHIP)
        exp = parse_experiment({"experiment": {"name": "h", "model": "hybrid", "ship": str(ship), "seed": k}},
                               "h.toml")
        models.append(build_model(exp))
    assert models[0].mmg.ship.source != models[1].mmg.ship.source
    assert _common_mmg(models)
    (tmp_path / "seed1" / "tanker.toml").write_text(EDITED)
    exp = parse_experiment({"experiment": {"name": "h", "model": "hybrid", "ship": str(tmp_path / "seed1" / "tanker.toml")}},
                           "h.toml")
    assert not _common_mmg([models[0], build_model(exp)])
