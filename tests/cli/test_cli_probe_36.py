"""The bad-input probe of issue 36, case by case: lock files planted as links, names that
would become paths, a test log cut from a training log, a column read for two channels,
outputs that are not what was asked, a full disk, and messages that blamed the wrong thing.
Every refusal exits 2 with one error line naming the file or option and the real cause;
nothing a user owns is changed and nothing half-written (or an empty folder) is left."""
from __future__ import annotations

import errno
import json
import os
import pathlib
import shutil

import numpy as np
import pandas as pd
import pytest

from cli_fixtures import sysid  # noqa: F401 (fixture)
from cli_harness import BINARY, assert_refused, leftovers
from tiny_experiment import tiny_config
from sysid.config.experiment import load_experiment
from sysid.store.manifest import write_manifest

FORCE_COLUMNS = ["x", "u", "y", "v", "psi", "r", "n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true"]
THESIS = "\\documentclass{article} the user's own file\n"


def force_csv(path: pathlib.Path, **columns) -> pathlib.Path:
    """Six plausible states of the 3 m model (SI units); `columns` replace whole columns."""
    t = np.arange(6, dtype=float)
    frame = pd.DataFrame({"x": t, "u": 0.5 + 0.02 * t, "y": 0.1 * t, "v": 0.01, "psi": 0.2, "r": 0.003,
                          "n_prop": 10.0, "delta_rudder": 0.1, "wind_velo_true": 1.5, "wind_dir_true": 2.0})
    frame = frame.assign(**columns)[FORCE_COLUMNS]
    frame.to_csv(path, index=False)
    return path


def write_config(path: pathlib.Path, files, **sections) -> pathlib.Path:
    path.write_text(tiny_config(files, **sections))
    return path


@pytest.fixture(scope="module")
def mmg_run(tmp_path_factory):
    """A run directory of the bundled ship's MMG (`sysid train`, nothing to train or test)."""
    from sysid.cli import run
    folder = tmp_path_factory.mktemp("mmg_run")
    (folder / "mmg.toml").write_text("[experiment]\nname = 'mmg'\nmodel = 'mmg'\n")
    run(["train", str(folder / "mmg.toml"), "-o", str(folder / "run")])
    return folder / "run"


# -- lock files: created by sysid, never through a link --------------------------------------
def _command(kind: str, tmp_path: pathlib.Path, files) -> tuple[list, pathlib.Path]:
    """(arguments, output) of a command whose output is `kind`'s."""
    if kind == "forces":
        return ["forces", force_csv(tmp_path / "good.csv"), "-o", tmp_path / "out.csv"], tmp_path / "out.csv"
    if kind == "train":
        config = write_config(tmp_path / "tiny.toml", files)
        return ["train", config, "-o", tmp_path / "run"], tmp_path / "run"
    return ["maneuver", "esso_osaka", "-o", tmp_path / "m", "--turning", "35", "--no-report"], tmp_path / "m"


LOCKS = {"forces": ".out.csv.lock", "train": ".run.lock", "maneuver": ".m.lock"}


@pytest.mark.parametrize("plant", ["symlink to a user file", "hard link", "dangling symlink"])
@pytest.mark.parametrize("kind", list(LOCKS))
def test_a_lock_file_planted_as_a_link_is_refused_and_its_target_untouched(sysid, files, tmp_path, kind, plant):
    args, out = _command(kind, tmp_path, files)
    lock, thesis, elsewhere = tmp_path / LOCKS[kind], tmp_path / "thesis.tex", tmp_path / "elsewhere.txt"
    thesis.write_text(THESIS)
    if plant == "symlink to a user file":
        lock.symlink_to(thesis)
    elif plant == "hard link":
        os.link(thesis, lock)
    else:
        lock.symlink_to(elsewhere)
    line = assert_refused(sysid(*args), 2, str(lock), absent=())
    assert ("symbolic link" if "symlink" in plant else "hard link") in line
    assert thesis.read_text() == THESIS and os.stat(thesis).st_nlink == (2 if plant == "hard link" else 1)
    assert not elsewhere.exists() and not out.exists()
    assert lock.is_symlink() == ("symlink" in plant)  # left as it was found


def test_a_lock_file_of_other_content_is_refused_and_a_stale_one_taken_over(sysid, tmp_path):
    src, out, lock = force_csv(tmp_path / "good.csv"), tmp_path / "out.csv", tmp_path / ".out.csv.lock"
    lock.write_text(THESIS)  # a plain file, but no lock sysid wrote
    line = assert_refused(sysid("forces", src, "-o", out), 2, str(lock), "other than a sysid process id")
    assert lock.read_text() == THESIS and not out.exists() and "forces" not in line
    lock.write_text("4194303\n")  # left by a sysid process that was killed: nobody holds it
    done = sysid("forces", src, "-o", out)
    assert done.code == 0, done.err
    assert not lock.exists() and len(pd.read_csv(out)) == 6


# -- names that become paths -----------------------------------------------------------------
def test_init_ship_name_states_the_ascii_rule(sysid, tmp_path):
    line = assert_refused(sysid("init", tmp_path / "proj", "--ship", "船_Ärö"), 2, "--ship '船_Ärö'")
    assert "ASCII letters (A-Z, a-z) and digits (0-9)" in line
    assert not (tmp_path / "proj").exists()  # a refused command leaves no folder


@pytest.mark.parametrize("name", ["../escaped", "a/b", "..", "résumé", "with space", ""])
def test_an_experiment_name_is_one_safe_path_component(sysid, files, tmp_path, name):
    config = write_config(tmp_path / "named.toml", files, experiment={"name": json.dumps(name), "model": "'mmg'"})
    line = assert_refused(sysid("train", config, "-o", tmp_path / "run"), 2, "named.toml: [experiment] name",
                          absent=(tmp_path / "run",))
    assert "ASCII letters" in line


def test_init_in_a_folder_with_a_space_writes_a_name_that_loads(sysid, tmp_path):
    done = sysid("init", tmp_path / "my project")
    assert done.code == 0, done.err
    assert load_experiment(tmp_path / "my project" / "experiment.toml").experiment.name == "my_project"


# -- overlap: a test or validation log cut from a training log --------------------------------
@pytest.fixture
def cut_logs(files, tmp_path):
    """Rows 300 on and rows 300-1199 of the training log (10 Hz), as new files."""
    frame = pd.read_csv(files["train"])
    frame.iloc[300:].to_csv(tmp_path / "tail.csv", index=False)
    frame.iloc[300:1200].to_csv(tmp_path / "middle.csv", index=False)
    return tmp_path / "tail.csv", tmp_path / "middle.csv"


@pytest.mark.parametrize("part", ["test", "validation"])
@pytest.mark.parametrize("piece", ["tail", "middle"])
def test_a_log_cut_from_a_training_log_is_refused(sysid, files, tmp_path, cut_logs, part, piece):
    cut = cut_logs[0] if piece == "tail" else cut_logs[1]
    config = write_config(tmp_path / "cut.toml", files, data={part: json.dumps([str(cut)]),
                                                              "train": json.dumps([str(files["train"])])},
                          evaluation={"horizons": "[10.0]"})
    text = config.read_text().replace(f"files = {json.dumps([str(files['train'])])}\n", "")
    config.write_text(text)
    out = tmp_path / "run"
    line = assert_refused(sysid("train", config, "-o", out), 2, f"{cut} ({part})", f"{files['train']} (training)",
                          absent=(out,))
    first = 31  # 10 Hz read at 1 Hz: data row 301 is the 31st sample
    n = 162 if piece == "tail" else 90
    assert f"the samples of rows {first}-{first + n - 1} of" in line


# -- columns -----------------------------------------------------------------------------------
def test_a_column_read_for_two_channels_is_refused(sysid, files, tmp_path):
    config = write_config(tmp_path / "twice.toml", files, **{"data.columns": {"u": "'vm_velo [m/s]'"}})
    line = assert_refused(sysid("train", config, "-o", tmp_path / "run"), 2,
                          "twice.toml: [data.columns] u = 'vm_velo [m/s]'", absent=(tmp_path / "run",))
    assert "also read for channel v" in line


def test_a_boolean_revolutions_column_is_refused(sysid, files, tmp_path):
    frame = pd.read_csv(files["test"])
    frame["n_prop [rps]"] = frame["n_prop [rps]"] > 5.0
    frame.to_csv(tmp_path / "bool.csv", index=False)
    out = tmp_path / "metrics.csv"
    assert_refused(sysid("evaluate", "--data", tmp_path / "bool.csv", "-o", out), 2,
                   "bool.csv: column 'n_prop [rps]' (channel n_prop) holds true/false values", absent=(out,))


@pytest.mark.parametrize("kind", ["timestamp", "duration"])
def test_a_parquet_time_column_of_timestamps_or_durations_reads_in_seconds(sysid, files, tmp_path, kind):
    frame = pd.read_csv(files["test"])
    seconds = pd.to_timedelta(frame["t [s]"], unit="s")
    frame["t [s]"] = pd.Timestamp("2020-11-12 11:49:21") + seconds if kind == "timestamp" else seconds
    frame.to_parquet(tmp_path / "log.parquet")
    shutil.copy(files["test"], tmp_path / "log.csv")
    runs = {}
    for name in ("log.parquet", "log.csv"):
        done = sysid("evaluate", "--data", tmp_path / name, "--horizon", "30", "-o", tmp_path / f"{name}.metrics.csv")
        assert done.code == 0, done.err
        runs[name] = pd.read_csv(tmp_path / f"{name}.metrics.csv")
    # the same samples, so the same windows and errors as the log's own CSV
    np.testing.assert_array_equal(runs["log.parquet"][["n_windows", "rmse_u", "rmse_v", "rmse_r"]].to_numpy(),
                                  runs["log.csv"][["n_windows", "rmse_u", "rmse_v", "rmse_r"]].to_numpy())


# -- outputs not what was asked ------------------------------------------------------------------
def test_forces_warns_of_a_rudder_in_degrees_and_q_silences_the_result_line(sysid, tmp_path):
    src, out = force_csv(tmp_path / "rud.csv", delta_rudder=35.0), tmp_path / "out.csv"
    done = sysid("forces", src, "-o", out)
    assert done.code == 0, done.err
    warning = [line for line in done.err.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1 and "'delta_rudder'" in warning[0] and "degrees?" in warning[0]
    quiet = sysid("-q", "forces", force_csv(tmp_path / "good.csv"), "-o", tmp_path / "quiet.csv")
    assert quiet.code == 0 and quiet.out == "" and quiet.err == ""
    np.testing.assert_array_equal(pd.read_csv(tmp_path / "quiet.csv")[FORCE_COLUMNS].to_numpy(),
                                  pd.read_csv(tmp_path / "good.csv").to_numpy())


def test_simulate_refuses_uneven_steps_in_its_horizon(sysid, files, tmp_path):
    frame = pd.read_csv(files["test"])
    t = frame["t [s]"].to_numpy().copy()
    t[200:] += 0.1  # one 10-Hz row later: 1.1 s between two 1-Hz samples
    frame["t [s]"] = t
    frame.to_csv(tmp_path / "jitter.csv", index=False)
    out = tmp_path / "sim.csv"
    assert_refused(sysid("simulate", "--log", tmp_path / "jitter.csv", "--start", "10", "--horizon", "30",
                         "-o", out), 2, "jitter.csv: samples at t = 19 and 20.1 s are 1.1 s apart", absent=(out,))
    done = sysid("simulate", "--log", tmp_path / "jitter.csv", "--start", "30", "--horizon", "30", "-o", out)
    assert done.code == 0, done.err  # an even stretch after it
    assert np.allclose(np.diff(pd.read_csv(out)["t"]), 1.0)


def test_evaluate_refuses_a_horizon_of_one_sample(sysid, files, tmp_path):
    out = tmp_path / "metrics.csv"
    assert_refused(sysid("evaluate", "--data", files["test"], "--horizon", "1", "-o", out), 2,
                   "--horizon 1: a window of one 1-s sample is its start state alone", absent=(out,))


def test_train_refuses_an_ensemble_config_it_would_write_unreadable(sysid, files, tmp_path):
    config = write_config(tmp_path / "ens.toml", files, ensemble={"members": "['../a', '../b']"})
    assert_refused(sysid("train", config, "-o", tmp_path / "run"), 2, "ens.toml: [ensemble] members",
                   absent=(tmp_path / "run",))


def test_an_ensemble_that_names_itself_is_refused(sysid, mmg_run, files, tmp_path):
    run = tmp_path / "ens"
    shutil.copytree(mmg_run, run)
    config = run / "config.toml"
    config.write_text(config.read_text().replace("[ensemble]\nmembers = []", "[ensemble]\nmembers = [\".\"]"))
    write_manifest(run, "run")
    out = tmp_path / "metrics.csv"
    assert_refused(sysid("evaluate", run, "--data", files["test"], "-o", out), 2,
                   "[ensemble] members names '.', which is this run itself", absent=(out,))


def test_a_refused_report_leaves_no_folder(sysid, tmp_path):
    (tmp_path / "notarun").mkdir()
    out = tmp_path / "reports" / "first"
    assert_refused(sysid("report", tmp_path / "notarun", "-o", out), 2, "notarun")
    assert not (tmp_path / "reports").exists()


# -- messages that named the wrong cause -----------------------------------------------------------
def test_maneuver_step_too_long_for_the_ship(sysid, tmp_path):
    out = tmp_path / "m"
    assert_refused(sysid("maneuver", "esso_osaka", "-o", out, "--turning", "35", "--dt", "10", "--no-report"), 2,
                   "dt 10 s: the ship runs 1.2 ship lengths per step", "dt <= 0.857 s", absent=(out,))


def test_maneuver_wind_direction_beyond_a_turn(sysid, tmp_path):
    out = tmp_path / "m"
    assert_refused(sysid("maneuver", "esso_osaka", "-o", out, "--turning", "35", "--wind", "5,1e300"), 2,
                   "--wind '5,1e300': direction 1e+300 deg must be in [-360, 360]", absent=(out,))


def test_a_named_pipe_is_not_a_missing_file(sysid, tmp_path):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    out = tmp_path / "out.csv"
    for args in (("forces", fifo, "-o", out), ("evaluate", "--data", fifo, "-o", out)):
        assert_refused(sysid(*args), 2, f"{fifo}: is a named pipe, not a regular file", absent=(out,))


SYNTH_CASES = {  # name -> (how the processed log is changed, what the line says)
    "empty": (lambda path, frame: path.write_bytes(b""), "empty file"),
    "binary": (lambda path, frame: path.write_bytes(BINARY), "binary, not a text CSV"),
    "NaN run": (lambda path, frame: frame.assign(**{"u_velo [m/s]": frame["u_velo [m/s]"].where(
        (frame.index < 100) | (frame.index >= 110))}).to_csv(path, index=False),
                "column u_velo is empty, NaN or not a number at line 102 (10 bad rows)"),
    "duplicated time": (lambda path, frame: frame.assign(**{"t [s]": np.where(
        frame.index == 101, frame["t [s]"].shift(1), frame["t [s]"])}).to_csv(path, index=False),
                        "column t is not strictly increasing at line 103 (t = 10 s after 10 s)"),
}


@pytest.mark.parametrize("case", list(SYNTH_CASES))
def test_synth_raw_refuses_a_bad_processed_log(sysid, files, tmp_path, case):
    change, says = SYNTH_CASES[case]
    src, out = tmp_path / "in.csv", tmp_path / "raw.csv"
    change(src, pd.read_csv(files["train"]))
    assert_refused(sysid("synth-raw", src, "-o", out), 2, f"{src}: {says}", absent=(out, tmp_path / "raw.truth.csv"))


TRAIN_CONFIG_CASES = {  # name -> (sections changed, what the line says)
    "device a typo": ({"training": {"device": "'cudax'"}}, "[training] device = 'cudax': must be auto, cpu, cuda"),
    "seed 2^32": ({"experiment": {"seed": str(2 ** 32)}}, "[experiment] seed = 4294967296: must be >= 0 and < 2^32"),
    "block_s 1e-9": ({"training": {"block_s": "1e-9"}},
                     "[training] block_s = 1e-09 s: a validation block holds 0 of the data's 1-s samples"),
}


@pytest.mark.parametrize("case", list(TRAIN_CONFIG_CASES))
def test_train_names_the_key_at_fault(sysid, files, tmp_path, case):
    sections, says = TRAIN_CONFIG_CASES[case]
    config = write_config(tmp_path / "bad.toml", files, **sections)
    assert_refused(sysid("train", config, "-o", tmp_path / "run"), 2, says, absent=(tmp_path / "run",))


# -- a full disk: one line naming the output, nothing half-written ----------------------------------
def _full_disk(monkeypatch, module, name):
    """`module.name` (a write) fails as on a full disk."""
    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(module, name, no_space)


def test_export_onto_a_full_disk(sysid, mmg_run, tmp_path, monkeypatch):
    _full_disk(monkeypatch, pathlib.Path, "write_bytes")
    out = tmp_path / "out" / "model.pt2"
    assert_refused(sysid("export", mmg_run, "-o", out, "--portable"), 2, f"{out}: no space left on device",
                   absent=(out.parent,))


def test_report_onto_a_full_disk(sysid, mmg_run, tmp_path, monkeypatch):
    _full_disk(monkeypatch, pathlib.Path, "write_text")
    out = tmp_path / "report"
    assert_refused(sysid("report", mmg_run, "-o", out), 2, "report.html: no space left on device", absent=(out,))


def test_preprocess_onto_a_full_disk(sysid, files, tmp_path, monkeypatch):
    from preprocessing import writer
    raw = tmp_path / "raw.csv"
    assert sysid("synth-raw", files["train"], "-o", raw).code == 0
    _full_disk(monkeypatch, writer, "_atomic")
    out = tmp_path / "processed"
    line = assert_refused(sysid("preprocess", raw, "-o", out), 2, f"{out}: no space left on device", absent=(out,))
    assert leftovers(tmp_path) == [] and "raw.csv" not in line.split(":")[0]


def test_train_refuses_evaluation_horizons_of_one_sample(sysid, files, tmp_path):
    config = write_config(tmp_path / "h1.toml", files, evaluation={"horizons": "[1.0, 30.0]"})
    assert_refused(sysid("train", config, "-o", tmp_path / "run"), 2,
                   "h1.toml: [evaluation] horizons must be >= 2 samples at [data] rate (2 s)", absent=(tmp_path / "run",))
