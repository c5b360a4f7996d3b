"""Fuzzing the numbers a user gives sysid: options and config values that are NaN, inf,
huge, fractional where whole samples are meant, in the wrong units (degrees for radians),
or beyond what this machine has. Every case exits 2 with one error line naming the option
or the file and column, no traceback, and nothing written (`sysid.config.checks`)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analytic_runs import analytic_run
from cli_fixtures import sysid  # noqa: F401 (fixtures)
from cli_harness import assert_refused, leftovers
from preprocessing import synth
from preprocessing.sensors import SensorLayout
from sysid.config.checks import cpu_cores
from tiny_experiment import tiny_config


@pytest.fixture(scope="module")
def zigzag(dataset_dir):
    """A 140-s zigzag test run (10 Hz): heading -1.01..0.55 rad, yaw rate up to 0.112 rad/s."""
    return dataset_dir / "zigzag" / "zigzag_31-Jul-2020_13_04_24.csv"


# -- synth-raw -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """A 60-s processed run at 10 Hz (analytic truth, public header)."""
    path = tmp_path_factory.mktemp("processed") / "run.csv"
    frame = analytic_run(60.0)
    frame.columns = [f"{c} [{u}]" for c, u in synth.schema.PROCESSED.items()]
    frame.to_csv(path, index=False)
    return path


SYNTH_CASES = {  # name -> (options, what the error line names)
    "gnss noise nan": (("--gnss-noise", "nan"), "--gnss-noise nan: must be a finite number >= 0"),
    "gnss noise inf": (("--gnss-noise", "inf"), "--gnss-noise inf"),
    "gnss noise -1": (("--gnss-noise", "-1"), "--gnss-noise -1"),
    "gnss noise 1e300": (("--gnss-noise", "1e300"), "<= 100 m"),
    "correlated noise nan": (("--gnss-correlated", "nan"), "--gnss-correlated nan"),
    "dropout duration nan": (("--dropout", "10:nan"), "--dropout 10:nan: DURATION nan"),
    "dropout duration inf": (("--dropout", "10:inf"), "--dropout 10:inf: DURATION inf"),
    "dropout start nan": (("--dropout", "nan:3"), "--dropout nan:3: START nan"),
    "dropout start -inf": (("--dropout", "-inf:3"), "--dropout -inf:3: START -inf"),
    "more outliers than rows": (("--outliers", "100000"), "--outliers 100000"),
    "negative seed": (("--seed", "-1"), "--seed -1"),
    "reference latitude nan": (("--latlon", "--reference", "nan,135"), "--reference nan,135: LAT nan"),
    "reference longitude 500": (("--latlon", "--reference", "34,500"), "LON 500: must be a finite number >= -180"),
}


@pytest.mark.parametrize("case", list(SYNTH_CASES))
def test_synth_raw_refuses_non_finite_and_out_of_range_numbers(sysid, processed, tmp_path, case):
    options, says = SYNTH_CASES[case]
    out = tmp_path / "raw.csv"
    assert_refused(sysid("synth-raw", processed, "-o", out, *options), 2, says,
                   absent=(out, tmp_path / "raw.truth.csv"))


# -- preprocess: a rate that leaves one sample ----------------------------------------------
def test_preprocess_rate_that_leaves_one_row_is_refused(sysid, tmp_path):
    raw = synth.synthesise(analytic_run(60.0), SensorLayout(), synth.SynthSettings(seed=5)).raw
    raw.to_csv(tmp_path / "run.csv", index=False)
    out = tmp_path / "processed"
    # 0.01 Hz divides 10 Hz, but a 60-s log then holds one sample (t = 0)
    assert_refused(sysid("preprocess", tmp_path / "run.csv", "-o", out, "--rate", "0.01"), 2,
                   "run.csv", "--rate 0.01 Hz leaves fewer than 2 samples", absent=(out,))
    done = sysid("preprocess", tmp_path / "run.csv", "-o", out, "--rate", "0.1")  # every 10 s: 7 samples
    assert done.code == 0, done.err
    assert len(pd.read_csv(out / "run.csv")) == 7


# -- export ------------------------------------------------------------------------------
EXPORT_CASES = {
    "dt nan": (("--dt", "nan"), "--dt nan: must be a finite number > 0 and <= 10 s"),
    "dt inf": (("--dt", "inf"), "--dt inf"),
    "dt huge": (("--dt", "1e9"), "--dt 1e+09: must be a finite number > 0 and <= 10 s"),
    "dt 0": (("--dt", "0"), "--dt 0"),
    "dt -1": (("--dt", "-1"), "--dt -1"),
    "dt within the bound but unstable": (("--dt", "10"), "--dt 10 s (euler): 100 steps of a straight run"),
    "batch 0": (("--batch", "0"), "--batch 0"),
    "batch huge": (("--batch", "100000000"), "--batch 100000000: must be a whole number >= 1 and <= 4096"),
}


@pytest.mark.parametrize("case", list(EXPORT_CASES))
def test_export_refuses_bad_steps_and_batches(sysid, trained, tmp_path, case):
    options, says = EXPORT_CASES[case]
    out = tmp_path / "model.pt2"
    assert_refused(sysid("export", trained, "-o", out, "--portable", *options), 2, says, absent=(out,))


@pytest.mark.parametrize("name", ["export", "model.pt", "model.pt2.bak"])
def test_export_refuses_a_file_not_ending_in_pt2(sysid, trained, tmp_path, name):
    """torch loads a package or program by its .pt2 suffix (else it warns, and its next
    versions refuse): another name is one line before anything is compiled, nothing written."""
    out = tmp_path / name
    assert_refused(sysid("export", trained, "-o", out, "--portable"), 2,
                   f"-o {out}: an exported step is a .pt2 file; name it e.g. -o {out.with_suffix('.pt2')}",
                   absent=(out,))


# -- horizons: whole samples, and no longer than the data ----------------------------------
def test_fractional_horizon_is_refused_by_evaluate_simulate_and_train(sysid, files, tmp_path):
    out = tmp_path / "out.csv"
    assert_refused(sysid("evaluate", "--data", files["test"], "--horizon", "1.4", "-o", out), 2,
                   "--horizon 1.4: not a whole number of the data's 1-s samples (the nearest is 1 s)", absent=(out,))
    assert_refused(sysid("simulate", "--log", files["test"], "--start", "10", "--horizon", "30.5", "-o", out), 2,
                   "--horizon 30.5: not a whole number", absent=(out,))
    # at --rate 10 the samples are 0.1 s apart: 2.5 s is 25 of them
    done = sysid("simulate", "--log", files["test"], "--start", "10", "--horizon", "2.5", "--rate", "10", "-o", out)
    assert done.code == 0, done.err
    assert len(pd.read_csv(out)) == 26
    config, run = tmp_path / "h.toml", tmp_path / "run"
    config.write_text(tiny_config(files, evaluation={"horizons": "[30.0, 1.4]"}))
    outcome = sysid("train", config, "-o", run, "--test", files["test"])
    assert_refused(outcome, 2, "h.toml: [evaluation] horizons 1.4: not a whole number", absent=(run,))
    assert "epoch" not in outcome.out and leftovers(tmp_path) == []  # refused before training


def test_training_horizon_longer_than_the_test_file_is_refused_before_training(sysid, files, tmp_path):
    config, run = tmp_path / "long.toml", tmp_path / "run"
    config.write_text(tiny_config(files, evaluation={"horizons": "[30.0, 1000.0]"}))  # the test file: 128 s
    outcome = sysid("train", config, "-o", run, "--test", files["test"])
    assert_refused(outcome, 2, "long.toml: [evaluation] horizons", "berthing_12-Nov-2020_11_49_21.csv holds 128 samples",
                   "fewer than one 1000-s window", absent=(run,))
    assert "epoch" not in outcome.out and leftovers(tmp_path) == []


def test_evaluate_states_a_file_too_short_for_a_horizon(sysid, files, zigzag, tmp_path):
    out = tmp_path / "m.csv"
    outcome = sysid("evaluate", "--data", files["test"], zigzag, "--horizon", "30", "--horizon", "135", "-o", out)
    assert outcome.code == 0, outcome.err
    warnings = [line for line in outcome.err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "berthing_12-Nov-2020_11_49_21.csv: 128 samples" in warnings[0]
    assert "fewer than one 135-s window" in warnings[0]
    table = pd.read_csv(out)
    empty = table[table.rmse_u.isna()]
    assert list(zip(empty.file, empty.horizon_s, empty.n_windows)) == [("berthing_12-Nov-2020_11_49_21", 135, 0)]
    assert np.isfinite(table.drop(empty.index)[["rmse_u", "rmse_v", "rmse_r"]].to_numpy()).all()


# -- units that look wrong: the same line from evaluate and from train ----------------------
def _converted(source, folder, column, factor):
    frame = pd.read_csv(source)
    frame[column] = frame[column] * factor
    path = folder / "converted.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("column, channel, hint", [
    ("psi_hat [rad]", "psi", 'unit = "deg"'),      # beyond one turn either way
    ("r_angvelo [rad/s]", "r", 'unit = "deg/s"'),  # beyond 172 deg/s
], ids=["heading in degrees", "yaw rate in deg/s"])
def test_degrees_are_refused_alike_by_evaluate_and_train(sysid, files, zigzag, tmp_path, column, channel, hint):
    bad = _converted(zigzag, tmp_path, column, 180 / np.pi)
    peak = np.abs(pd.read_csv(bad)[column]).max()  # the zigzag's largest heading / yaw rate, now in degrees
    says = f"column '{column}' (channel {channel}) reaches {peak:.4g} "
    out, run = tmp_path / "m.csv", tmp_path / "run"
    lines = [assert_refused(sysid("evaluate", "--data", bad, "--horizon", "30", "-o", out), 2, says, "wrong units?",
                                   hint, absent=(out,))]
    config = tmp_path / "deg.toml"
    config.write_text(tiny_config({"train": bad}))  # degrees in the training data
    lines.append(assert_refused(sysid("train", config, "-o", run, "--test", files["test"]), 2, says, absent=(run,)))
    config.write_text(tiny_config(files))  # degrees in the test data
    lines.append(assert_refused(sysid("train", config, "-o", run, "--test", bad), 2, says, absent=(run,)))
    assert len(set(lines)) == 1 and f"{bad}: " in lines[0]


def test_an_unwrapped_heading_in_radians_is_no_unit_error(sysid, dataset_dir, tmp_path):
    """A heading past one turn that changes at the yaw rate (a continuous heading) is read
    as it is: the same metrics as the wrapped file (u, v_m and r do not see the wrap)."""
    wrapped = dataset_dir / "turning" / "turn_14-Oct-2020_14_56_07.csv"
    frame = pd.read_csv(wrapped)
    psi = frame["psi_hat [rad]"]
    frame.loc[psi.notna(), "psi_hat [rad]"] = np.unwrap(psi.dropna().to_numpy())  # down to -8.3 rad
    assert frame["psi_hat [rad]"].abs().max() > 2 * np.pi
    unwrapped = tmp_path / "turn_14-Oct-2020_14_56_07.csv"
    frame.to_csv(unwrapped, index=False)
    tables = []
    for path, out in ((wrapped, tmp_path / "a.csv"), (unwrapped, tmp_path / "b.csv")):
        done = sysid("evaluate", "--data", path, "--horizon", "30", "-o", out)
        assert done.code == 0 and "warning" not in done.err, done.err
        tables.append(pd.read_csv(out))
    pd.testing.assert_frame_equal(*tables, rtol=1e-9)
    degrees = _converted(unwrapped, tmp_path, "psi_hat [rad]", 180 / np.pi)  # the same turn in degrees
    assert_refused(sysid("evaluate", "--data", degrees, "--horizon", "30", "-o", tmp_path / "c.csv"), 2,
                   "(channel psi) reaches", 'wrong units? name its unit in [data.columns], e.g. psi = { column = "...", unit = "deg" }')


def test_simulate_rate_that_is_no_whole_sample_or_leaves_one_row(sysid, files, tmp_path):
    out = tmp_path / "sim.csv"
    assert_refused(sysid("simulate", "--log", files["test"], "--start", "10", "--horizon", "20", "--rate", "3", "-o", out),
                   2, "rate 3 Hz is not a whole number of this file's 0.1-s samples", absent=(out,))
    assert_refused(sysid("simulate", "--log", files["test"], "--start", "0", "--horizon", "20", "--rate", "0.001",
                         "-o", out), 2, "rate 0.001 Hz leaves 1 sample of this 128-s run", absent=(out,))


# -- resources: threads, jobs and workers bounded by this machine ---------------------------
def test_resource_options_beyond_this_machine_are_refused(sysid, files, tmp_path):
    cores = cpu_cores()
    too_many = str(cores + 1)
    machine = f"this machine lets sysid use {cores} CPU core"
    config, run = tmp_path / "tiny.toml", tmp_path / "run"
    config.write_text(tiny_config(files))
    for threads in (too_many, "100000"):
        assert_refused(sysid("train", config, "-o", run, "--test", files["test"], "--threads", threads), 2,
                       f"--threads {threads}: must be a whole number >= 0 and <= {cores}", machine, absent=(run,))
    config.write_text(tiny_config(files, training={"threads": "100000"}))
    outcome = sysid("train", config, "-o", run, "--test", files["test"])
    assert_refused(outcome, 2, "tiny.toml: [training] threads = 100000", machine, absent=(run,))
    assert "epoch" not in outcome.out
    out = tmp_path / "out"
    assert_refused(sysid("reproduce", "-o", out, "--jobs", "100000"), 2, "--jobs 100000", machine, absent=(out,))
    assert_refused(sysid("preprocess", files["test"], "-o", out, "--jobs", too_many), 2, f"--jobs {too_many}",
                   machine, absent=(out,))
    assert_refused(sysid("sweep", tmp_path / "any.toml", "-o", out, "--workers", "100000"), 2,
                   "--workers 100000", machine, absent=(out,))
    assert leftovers(tmp_path) == []
