"""A run directory names its logs relative to itself (`sysid.runs.log_paths`): after the
project folder is moved or copied (the original deleted), the run evaluates on its own test
logs to the bit as before; an edited log is one warning line, a missing one a single error
line naming the run, the file and the fix (exit 2); a run written before (absolute paths)
loads as it did; the paper's data sets are recorded as before.

The truth is the same run evaluated before the move, in the same process, and the logs'
bytes. The project: the scratch tanker's ship file, two training logs and one test log
simulated from its MMG with known derivatives (`scratch_ship.simulated_logs`), a hybrid
trained 2 epochs (a few seconds)."""
import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sysid.data.recordings import read_runs
from sysid.evaluation.evaluate import evaluate_model
from sysid.records.summary import RunSummary
from sysid.runs.layout import load_model
from sysid.runs.log_paths import portable_provenance, relative_to
from sysid.runs.rundir import RunDir
from sysid.store.manifest import write_manifest
from sysid.sweep.inbox import same_trial

from cli_harness import in_process
from scratch_ship import SCRATCH, simulated_logs

TRUTH = {"N_r": -0.055}   # the ship file says -0.049
RMSE = ["rmse_u", "rmse_v", "rmse_r"]
EXPERIMENT = ("[experiment]\nname = 'first'\nmodel = 'hybrid'\nship = 'tanker.toml'\nseed = 0\n"
              "[data]\ntrain = ['logs/*.csv']\ntest = ['test']\n"
              "[training]\nepochs = 2\nwarm_start_epochs = 2\nthreads = 1\n[evaluation]\nhorizons = [30.0]\n")


def _write_project(folder):
    """A user's project at `folder`: ``tanker.toml``, ``logs/`` (turn, zigzag),
    ``test/random.csv``, ``experiment.toml`` (relative paths); returns its config."""
    (folder / "logs").mkdir(parents=True)
    (folder / "test").mkdir()
    (folder / "tanker.toml").write_text(SCRATCH)
    turn, zigzag, random = simulated_logs(folder / "tanker.toml", folder, TRUTH, seconds=120.0)
    for log in (turn, zigzag):
        log.rename(folder / "logs" / log.name)
    random.rename(folder / "test" / random.name)
    (folder / "experiment.toml").write_text(EXPERIMENT)
    return folder / "experiment.toml"


@pytest.fixture(scope="module")
def origin(tmp_path_factory):
    """A user's project (`_write_project`) and the run ``runs/first`` trained from it."""
    from sysid.cli import run as sysid
    folder = tmp_path_factory.mktemp("portable") / "tanker"
    sysid(["train", str(_write_project(folder)), "-o", str(folder / "runs" / "first"), "-q"])
    return folder


def _project(origin, place):
    """A copy of the project at `place` (a user's copy of the folder)."""
    return shutil.copytree(origin, place)


def _metrics(run) -> np.ndarray:
    """(u, v_m, r) RMSE of the run's model on its own test logs, found and checked by the run."""
    exp, model = load_model(run)
    files = RunDir(run).read_test_logs(exp)
    return evaluate_model(model, read_runs(files, exp.data.rate, exp.data.columns), [30.0],
                          traces=False).metrics[RMSE].to_numpy()


def test_the_run_names_its_logs_relative_to_itself(origin):
    run = RunDir.open(origin / "runs" / "first")
    config = run.read_config()
    assert config["data"]["train"] == ["../../logs/turn.csv", "../../logs/zigzag.csv"]
    assert config["data"]["test"] == ["../../test/random.csv"]
    assert config["experiment"]["ship"] == "../../tanker.toml"
    data = run.read_summary().data
    assert [(f.relative, f.file) for f in data.test] == [("../../test/random.csv", str(origin / "test" / "random.csv"))]
    assert [f.sha256 for f in data.test] == [hashlib.sha256((origin / "test" / "random.csv").read_bytes()).hexdigest()]
    exp = run.read_experiment()
    assert exp.data.test == (str(origin / "test" / "random.csv"),)
    assert exp.data.train == tuple(str(origin / "logs" / n) for n in ("turn.csv", "zigzag.csv"))


def test_moved_project_evaluates_to_the_bit_as_before(origin, tmp_path, capsys):
    first = _project(origin, tmp_path / "a" / "tanker")
    before = _metrics(first / "runs" / "first")
    out = in_process(capsys, "evaluate", first / "runs" / "first", "-o", tmp_path / "before.csv")
    assert out.code == 0, out.err
    moved = shutil.copytree(first, tmp_path / "b" / "t2")
    shutil.rmtree(first)
    run = moved / "runs" / "first"
    out = in_process(capsys, "evaluate", run, "-o", tmp_path / "after.csv")
    assert out.code == 0, out.err
    assert "differs from" not in out.err, out.err
    assert (tmp_path / "after.csv").read_bytes() == (tmp_path / "before.csv").read_bytes()
    after = _metrics(run)
    assert np.isfinite(after).all()
    np.testing.assert_array_equal(after, before)
    assert RunDir(run).read_experiment().data.test == (str(moved / "test" / "random.csv"),)


def test_a_moved_project_says_when_its_ship_file_was_edited(origin, tmp_path, capsys):
    """The ship file is named relative to the run too: the moved project's edited ship file
    is the one the warning names (the run still uses its copy)."""
    moved = _project(origin, tmp_path / "t2")
    ship = moved / "tanker.toml"
    ship.write_text(SCRATCH.replace("N_r = -0.049", "N_r = -0.060"))
    out = in_process(capsys, "evaluate", moved / "runs" / "first", "-o", tmp_path / "m.csv")
    assert out.code == 0, out.err
    warnings = [line for line in out.err.splitlines() if "differs from" in line]
    assert len(warnings) == 1 and str(ship) in warnings[0], out.err
    np.testing.assert_array_equal(_metrics(moved / "runs" / "first"), _metrics(origin / "runs" / "first"))


def test_a_run_copied_alone_finds_its_logs_where_they_were(origin, tmp_path, capsys):
    """The run directory without its project (the project stays): the absolute paths the
    run recorded are the fallback."""
    run = shutil.copytree(origin / "runs" / "first", tmp_path / "elsewhere" / "deep" / "first")
    out = in_process(capsys, "evaluate", run, "-o", tmp_path / "m.csv")
    assert out.code == 0 and "differs from" not in out.err, out.err
    np.testing.assert_array_equal(_metrics(run), _metrics(origin / "runs" / "first"))
    assert RunDir(run).read_experiment().data.test == (str(origin / "test" / "random.csv"),)


def test_an_edited_log_gives_one_warning(origin, tmp_path, capsys):
    project = _project(origin, tmp_path / "tanker")
    run = project / "runs" / "first"
    log = project / "test" / "random.csv"
    frame = pd.read_csv(log)
    frame.loc[10, "u_velo [m/s]"] += 0.05   # one recorded sample of u (a window's start)
    frame.to_csv(log, index=False)
    out = in_process(capsys, "evaluate", run, "-o", tmp_path / "m.csv")
    assert out.code == 0, out.err
    warnings = [line for line in out.err.splitlines() if "differs from" in line]
    assert len(warnings) == 1 and "WARNING" in warnings[0], out.err
    assert str(log) in warnings[0] and str(run) in warnings[0]
    # the results are the edited log's: its u error moved
    assert not np.array_equal(pd.read_csv(tmp_path / "m.csv")[RMSE].to_numpy(),
                              pd.read_csv(run / "metrics.csv")[RMSE].to_numpy())


def test_a_missing_log_is_one_line_naming_the_run_the_file_and_the_fix(origin, tmp_path, capsys):
    project = _project(origin, tmp_path / "tanker")
    run = project / "runs" / "first"
    moved_away = tmp_path / "random.csv"
    (project / "test" / "random.csv").rename(moved_away)
    old = _as_written_before(shutil.copytree(origin / "runs" / "first", tmp_path / "old"))
    (origin / "test" / "random.csv").rename(tmp_path / "origin_random.csv")   # the recorded place too
    try:
        out = in_process(capsys, "evaluate", run, "-o", tmp_path / "m.csv")
        before = in_process(capsys, "evaluate", old, "-o", tmp_path / "old.csv")
    finally:
        (tmp_path / "origin_random.csv").rename(origin / "test" / "random.csv")
    assert out.code == 2
    assert len(out.error_lines) == 1 and len(out.err.strip().splitlines()) == 1, out.err
    assert "Traceback" not in out.err
    line = out.error_lines[0]
    assert str(run) in line and str(project / "test" / "random.csv") in line and "--data DIR" in line
    assert not (tmp_path / "m.csv").exists()
    # a run written before: the same one line, its absolute path named
    assert before.code == 2 and len(before.err.strip().splitlines()) == 1, before.err
    assert str(old) in before.err and str(origin / "test" / "random.csv") in before.err and "--data DIR" in before.err
    # the fix: --data names the logs
    out = in_process(capsys, "evaluate", run, "--data", moved_away, "-o", tmp_path / "m.csv")
    assert out.code == 0, out.err
    np.testing.assert_allclose(pd.read_csv(tmp_path / "m.csv")[RMSE].to_numpy(),
                               pd.read_csv(run / "metrics.csv")[RMSE].to_numpy(), rtol=1e-5)


def _as_written_before(run):
    """`run` as sysid wrote it before runs named their logs relative to themselves: config.toml
    with the absolute paths, summary.json without ``relative``, the manifest written again."""
    summary = json.loads((run / "summary.json").read_text())
    data = summary["data"]
    text = (run / "config.toml").read_text()
    for entry in [*data["train"], *data["test"]]:
        text = text.replace(json.dumps(entry.pop("relative")), json.dumps(entry["file"]))
    (run / "summary.json").write_text(json.dumps(summary, indent=2))
    text = text.replace('ship = "../../tanker.toml"', f'ship = {json.dumps(summary["ship"])}')
    (run / "config.toml").write_text(text)
    (run / "manifest.json").unlink()
    write_manifest(run, "run")
    return run


def test_a_run_written_before_loads_as_it_did(origin, tmp_path, capsys):
    old = _as_written_before(shutil.copytree(origin / "runs" / "first", tmp_path / "old"))
    config = RunDir.open(old).read_config()
    assert config["data"]["test"] == [str(origin / "test" / "random.csv")]
    assert config["experiment"]["ship"] == str(origin / "tanker.toml")
    assert RunSummary.read(old / "summary.json").data.test[0].relative is None
    exp = RunDir(old).read_experiment()
    assert exp.data.test == (str(origin / "test" / "random.csv"),)
    np.testing.assert_array_equal(_metrics(old), _metrics(origin / "runs" / "first"))
    out = in_process(capsys, "evaluate", old, "-o", tmp_path / "m.csv")
    assert out.code == 0 and "differs from" not in out.err, out.err
    np.testing.assert_allclose(pd.read_csv(tmp_path / "m.csv")[RMSE].to_numpy(),
                               pd.read_csv(old / "metrics.csv")[RMSE].to_numpy(), rtol=1e-5)


def test_the_paper_data_sets_are_recorded_as_before(tmp_path):
    """D1/D2 logs are found through --data, not the run: their record is left as it is."""
    paper = {"training": "D1", "train": [{"file": "/data/frt-ds-esso/turning/a.csv", "sha256": "0" * 64}],
             "validation": "0.3 of the 30-s blocks of every training log, drawn with the seed",
             "test_set": "paper", "test": [{"file": "/data/frt-ds-esso/random/b.csv", "sha256": "1" * 64}]}
    assert portable_provenance(paper, tmp_path / "run") == paper
    own = {**paper, "training": "files", "test_set": "files"}
    recorded = portable_provenance(own, "/data/runs/first")
    assert recorded["train"][0]["relative"] == "../../frt-ds-esso/turning/a.csv"
    assert recorded["test"][0] == {"file": "/data/frt-ds-esso/random/b.csv", "sha256": "1" * 64,
                                   "relative": "../../frt-ds-esso/random/b.csv"}


def test_a_log_sharing_only_the_root_with_the_run_is_named_by_its_absolute_path():
    """A run in /scratch made from logs in /data: no move keeps ``../../data/...`` true, so
    there is no relative form (config.toml names the absolute path)."""
    own = {"training": "files", "train": [{"file": "/data/logs/a.csv", "sha256": "0" * 64}],
           "validation": "none", "test_set": "files", "test": [{"file": "/data/test/b.csv", "sha256": "1" * 64}]}
    recorded = portable_provenance(own, "/scratch/runs/first")
    assert recorded["train"] == [{"file": "/data/logs/a.csv", "sha256": "0" * 64}]
    assert recorded["test"] == [{"file": "/data/test/b.csv", "sha256": "1" * 64}]
    assert relative_to("/data/logs/a.csv", "/scratch/runs/first") is None
    assert relative_to("/data/logs/a.csv", "/data/runs/first") == "../../logs/a.csv"


def test_a_delivered_sweep_run_names_its_ship_relative_to_where_it_lives(tmp_path):
    trial = {"experiment": {"ship": str(tmp_path / "tanker.toml"), "seed": 0}, "data": {"train": ["x"]}}
    written = {"experiment": {"ship": "../../tanker.toml", "seed": 0}, "data": {"train": ["../../x"]}}
    assert same_trial(written, trial, tmp_path / "trials" / "p0")
    assert not same_trial(written, trial, tmp_path / "other" / "deeper" / "p0")
    assert not same_trial({**written, "experiment": {"ship": "../../tanker.toml", "seed": 1}}, trial,
                          tmp_path / "trials" / "p0")


def test_a_run_directory_reached_through_a_link_names_logs_its_reader_finds(tmp_path):
    """runs/ a link to another disk: the relative path recorded for a log is read against the
    run directory's resolved folder (as `load_experiment` anchors it) and must lead to the log
    itself (it led to disk/logs/a.csv, which does not exist: found only through the absolute
    hint, so lost once the project moved)."""
    from sysid.runs.log_paths import portable_provenance
    log = tmp_path / "proj" / "logs" / "a.csv"
    log.parent.mkdir(parents=True)
    log.write_text("t\n0\n")
    (tmp_path / "disk" / "runs").mkdir(parents=True)
    (tmp_path / "proj" / "runs").symlink_to(tmp_path / "disk" / "runs")
    home = tmp_path / "proj" / "runs" / "first"           # not written yet
    data = {"training": "files", "train": [{"file": str(log), "sha256": "0" * 64}]}
    relative = portable_provenance(data, home)["train"][0]["relative"]
    home.mkdir()
    assert Path(os.path.normpath(os.path.join(home.resolve(), relative))) == log
    assert (home.resolve() / relative).resolve() == log.resolve()
    # a sweep's delivered run there: its ship file, named so relative to it, is its trial's
    from sysid.runs.log_paths import relative_to
    ship = tmp_path / "proj" / "tanker.toml"
    trial = {"experiment": {"ship": str(ship), "seed": 0}, "data": {}}
    written = {"experiment": {"ship": relative_to(ship, home), "seed": 0}, "data": {}}
    assert same_trial(written, trial, home)


# -- a run written outside its project (sysid train CONFIG -o ELSEWHERE) ---------------------
#
# | moved                                  | the run finds its logs                     |
# |----------------------------------------|--------------------------------------------|
# | the run alone (the project stays)      | at their absolute paths                    |
# | both, keeping their places to each other | relative to the run, in their new place  |
# | the project alone (the run stays)      | cannot: one line, the fixes --config, --data |

@pytest.fixture(scope="module")
def outside(tmp_path_factory):
    """A study folder: the project ``tanker`` and a run written outside it,
    ``elsewhere/deep/run`` (``sysid train tanker/experiment.toml -o elsewhere/deep/run``)."""
    from sysid.cli import run as sysid
    study = tmp_path_factory.mktemp("outside") / "study"
    config = _write_project(study / "tanker")
    sysid(["train", str(config), "-o", str(study / "elsewhere" / "deep" / "run"), "-q"])
    return study


RUN = ("elsewhere", "deep", "run")


def _evaluated(capsys, run, csv, *options):
    out = in_process(capsys, "evaluate", run, "-o", csv, *options)
    assert out.code == 0 and "differs from" not in out.err and "missing" not in out.err, out.err
    return csv.read_bytes()


def test_a_run_outside_its_project_names_its_logs_relative_to_itself(outside):
    run = RunDir.open(outside.joinpath(*RUN))
    assert run.read_config()["data"]["test"] == ["../../../tanker/test/random.csv"]
    assert [(f.relative, f.file) for f in run.read_summary().data.test] == [
        ("../../../tanker/test/random.csv", str(outside / "tanker" / "test" / "random.csv"))]


def test_an_outside_run_moved_alone_finds_its_logs_where_they_are(outside, tmp_path, capsys):
    before = _evaluated(capsys, outside.joinpath(*RUN), tmp_path / "before.csv")
    study = shutil.copytree(outside, tmp_path / "study")   # the project stays where it was: the copy's own
    run = shutil.move(study.joinpath(*RUN), tmp_path / "runs" / "run")
    shutil.rmtree(study / "tanker")
    assert _evaluated(capsys, run, tmp_path / "after.csv") == before
    assert RunDir(run).read_experiment().data.test == (str(outside / "tanker" / "test" / "random.csv"),)


def test_an_outside_run_and_its_project_moved_together_evaluate_as_before(outside, tmp_path, capsys):
    first = shutil.copytree(outside, tmp_path / "a" / "study")
    before = _evaluated(capsys, first.joinpath(*RUN), tmp_path / "before.csv")
    moved = shutil.copytree(first, tmp_path / "b" / "s2")
    shutil.rmtree(first)
    assert _evaluated(capsys, moved.joinpath(*RUN), tmp_path / "after.csv") == before
    assert RunDir(moved.joinpath(*RUN)).read_experiment().data.test == (str(moved / "tanker" / "test" / "random.csv"),)


def test_an_outside_run_whose_project_moved_says_so_in_one_line_with_the_fixes(outside, tmp_path, capsys):
    run = outside.joinpath(*RUN)
    before = _evaluated(capsys, run, tmp_path / "before.csv")
    project = shutil.move(outside / "tanker", tmp_path / "ships" / "tanker")   # the run stays
    try:
        out = in_process(capsys, "evaluate", run, "-o", tmp_path / "m.csv")
        # either fix: the project's config where it is now, or its test logs
        fixed = (_evaluated(capsys, run, tmp_path / "config.csv", "--config", project / "experiment.toml"),
                 _evaluated(capsys, run, tmp_path / "data.csv", "--data", project / "test"))
    finally:
        shutil.move(project, outside / "tanker")
    assert out.code == 2 and len(out.err.strip().splitlines()) == 1 and "Traceback" not in out.err, out.err
    line = out.error_lines[0]
    assert str(run) in line and str(outside / "tanker" / "test" / "random.csv") in line
    assert "--config DIR/experiment.toml" in line and "--data DIR" in line
    assert not (tmp_path / "m.csv").exists()
    assert fixed == (before, before)
