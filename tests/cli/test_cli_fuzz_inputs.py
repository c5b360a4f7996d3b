"""Fuzzing `sysid forces`, `simulate`, `evaluate --model mmg` and `preprocess` with bad
inputs, bad options and bad output paths: every case exits 2 (1 for a file that fails in
preprocessing) with one error line
naming the file or option, no traceback, and nothing partial or stale left behind."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cli_harness import BINARY, assert_refused, in_process, leftovers
from preprocessing import synth
from preprocessing.sensors import SensorLayout
from sysid.store.manifest import verify_manifest
from analytic_runs import analytic_run

FORCE_COLUMNS = ["x", "u", "y", "v", "psi", "r", "n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true"]


@pytest.fixture
def sysid(capsys):
    return lambda *args: in_process(capsys, *args)


def force_rows(n: int = 6) -> pd.DataFrame:
    """Plausible states of the 3 m model: ahead at 0.5-0.7 m/s, small yaw, 10 rps."""
    t = np.arange(n, dtype=float)
    return pd.DataFrame({"x": t, "u": 0.5 + 0.02 * t, "y": 0.1 * t, "v": 0.01, "psi": 0.2, "r": 0.003,
                         "n_prop": 10.0, "delta_rudder": 0.1, "wind_velo_true": 1.5, "wind_dir_true": 2.0})


def csv_text(frame: pd.DataFrame) -> str:
    return frame.to_csv(index=False)


def edited(column: str, value) -> bytes:
    frame = force_rows().astype(object)
    frame.loc[2, column] = value
    return csv_text(frame).encode()


# name -> (bytes of the input file, extra options, exit code, what the error line names)
FORCE_INPUT_CASES = {
    "empty file": (b"", (), 2, "in.csv: empty file"),
    "header only": (",".join(FORCE_COLUMNS).encode() + b"\n", (), 2, "no data rows"),
    "binary": (BINARY, (), 2, "binary, not a text CSV"),
    "utf-16": (csv_text(force_rows()).encode("utf-16"), (), 2, "UTF-16/32 encoded"),
    "missing column": (csv_text(force_rows().drop(columns="delta_rudder")).encode(), (), 2, "delta_rudder"),
    "text in a number column": (edited("u", "fast"), (), 2, "column 'u' is not a finite number at line 4"),
    "empty cell": (edited("r", ""), (), 2, "column 'r' is not a finite number at line 4"),
    "inf cell": (edited("v", "inf"), (), 2, "column 'v' is not a finite number"),
    "ragged rows": ((csv_text(force_rows()) + "1,2,3,4,5,6,7,8,9,10,11,12\n").encode(), (), 2,
                    "not a readable CSV"),
    "u = 1e300 gives inf forces": (edited("u", 1e300), (), 2, "line 4"),
    "n_prop = 1e200 gives inf forces": (edited("n_prop", 1e200), (), 2, "beyond the model's range"),
    "chunk 0": (csv_text(force_rows()).encode(), ("--chunk", "0"), 2, "--chunk 0"),
    "chunk -5": (csv_text(force_rows()).encode(), ("--chunk", "-5"), 2, "--chunk -5"),
    "bogus quadrature": (csv_text(force_rows()).encode(), ("--quadrature", "gauss"), 2, "--quadrature 'gauss'"),
    "unknown ship parameter": (csv_text(force_rows()).encode(), ("--set", "X_zz=1"), 2, "X_zz"),
    "override not a number": (csv_text(force_rows()).encode(), ("--set", "X_vr=abc"), 2, "X_vr"),
    "unknown ship": (csv_text(force_rows()).encode(), ("--ship", "no_such_ship"), 2, "no_such_ship"),
}


@pytest.mark.parametrize("case", list(FORCE_INPUT_CASES))
def test_forces_refuses_bad_input(sysid, tmp_path, case):
    content, options, code, says = FORCE_INPUT_CASES[case]
    src, out = tmp_path / "in.csv", tmp_path / "out" / "forces.csv"
    src.write_bytes(content)
    outcome = sysid("forces", src, "-o", out, *options)
    line = assert_refused(outcome, code, says, absent=(out,))
    if not says.startswith("--"):
        assert "in.csv" in line or "X_zz" in line or "X_vr" in line or "no_such_ship" in line


def test_forces_input_missing_or_a_directory(sysid, tmp_path):
    out = tmp_path / "forces.csv"
    assert_refused(sysid("forces", tmp_path / "nope.csv", "-o", out), 2, "nope.csv: file not found", absent=(out,))
    (tmp_path / "adir").mkdir()
    assert_refused(sysid("forces", tmp_path / "adir", "-o", out), 2, "adir: is a directory, not a file", absent=(out,))


@pytest.mark.parametrize("where", ["under /proc", "an existing directory", "below a file"])
def test_forces_output_that_cannot_be_written(sysid, tmp_path, where):
    src = tmp_path / "in.csv"
    src.write_text(csv_text(force_rows()))
    out = {"under /proc": "/proc/sysid-fuzz/forces.csv", "an existing directory": tmp_path / "taken",
           "below a file": tmp_path / "in.csv" / "forces.csv"}[where]
    if where == "an existing directory":
        out.mkdir()
    outcome = sysid("forces", src, "-o", out)
    assert_refused(outcome, 2)
    assert str(out).split("/")[-2] in outcome.error_lines[0] or str(out) in outcome.error_lines[0]
    assert leftovers(tmp_path) == []


def test_forces_flags_implausible_states_and_writes_exact_numbers(sysid, tmp_path):
    frame = force_rows()
    frame.loc[1, "u"] = 150.0  # finite forces, but no 3 m model goes 150 m/s
    src, out = tmp_path / "in.csv", tmp_path / "forces.csv"
    src.write_text(csv_text(frame))
    outcome = sysid("forces", src, "-o", out)
    assert outcome.code == 0, outcome.err
    warnings = [line for line in outcome.err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "in.csv" in warnings[0] and "'u'" in warnings[0] and "line 3" in warnings[0]
    written = pd.read_csv(out)
    assert np.isfinite(written.drop(columns=FORCE_COLUMNS).to_numpy()).all()
    np.testing.assert_array_equal(written[FORCE_COLUMNS].to_numpy(), frame.to_numpy(dtype=float))


# -- simulate and evaluate --model mmg on a real processed file ----------------------------
@pytest.fixture(scope="module")
def berthing(dataset_dir):
    return dataset_dir / "berthing" / "berthing_12-Nov-2020_11_07_23.csv"


@pytest.fixture
def bad_logs(tmp_path):
    paths = {"binary": BINARY, "utf-16": "t [s],u_velo [m/s]\n0,1\n".encode("utf-16"), "empty": b""}
    for name, content in paths.items():
        (tmp_path / f"{name}.csv").write_bytes(content)
    return tmp_path


SIMULATE_CASES = {
    "rate 0": (("--rate", "0"), "--rate 0"),
    "rate -1": (("--rate", "-1"), "--rate -1"),
    "horizon 0": (("--horizon", "0"), "--horizon 0"),
    "horizon -30": (("--horizon", "-30"), "--horizon -30"),
    "horizon nan": (("--horizon", "nan"), "--horizon nan"),
    "start outside the run": (("--start", "1e9"), "outside the run"),
    "horizon past the end": (("--horizon", "1e6"), "runs past the end"),
    "bogus integrator": (("--integrator", "leapfrog"), "--integrator 'leapfrog'"),
}


@pytest.mark.parametrize("case", list(SIMULATE_CASES))
def test_simulate_refuses_bad_options(sysid, berthing, tmp_path, case):
    options, says = SIMULATE_CASES[case]
    args = {"--start": "10", "--horizon": "30"}
    for flag, value in zip(options[::2], options[1::2]):
        args[flag] = value
    out = tmp_path / "sim.csv"
    flat = [x for kv in args.items() for x in kv]
    assert_refused(sysid("simulate", "--log", berthing, *flat, "-o", out), 2, says, absent=(out,))


@pytest.mark.parametrize("log", ["missing", "binary", "utf-16", "empty"])
def test_simulate_refuses_bad_logs(sysid, bad_logs, log):
    path, out = bad_logs / f"{log}.csv", bad_logs / "sim.csv"
    assert_refused(sysid("simulate", "--log", path, "--start", "0", "--horizon", "5", "-o", out),
                   2, f"{log}.csv", absent=(out,))


EVALUATE_CASES = {
    "horizon 0": (("--horizon", "0"), "--horizon 0"),
    "horizon -30": (("--horizon", "-30"), "--horizon -30"),
    "horizon longer than every file": (("--horizon", "100000"), "no file is long enough"),
    "nn without a run": (("--model", "nn"), "--model 'nn'"),
}


@pytest.mark.parametrize("case", list(EVALUATE_CASES))
def test_evaluate_refuses_bad_options(sysid, berthing, tmp_path, case):
    options, says = EVALUATE_CASES[case]
    out = tmp_path / "metrics.csv"
    assert_refused(sysid("evaluate", "--data", berthing, *options, "-o", out), 2, says, absent=(out,))


def test_evaluate_refuses_missing_and_empty_data(sysid, tmp_path):
    out = tmp_path / "metrics.csv"
    assert_refused(sysid("evaluate", "--data", tmp_path / "nope", "-o", out), 2, "nope: no such file", absent=(out,))
    (tmp_path / "empty").mkdir()
    assert_refused(sysid("evaluate", "--data", tmp_path / "empty", "-o", out), 2, "holds no .csv", absent=(out,))


# -- preprocess ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def raw_logs(tmp_path_factory):
    """A clean 60-s raw log, the same log with a 3-s hole (two segments), and bad files."""
    folder = tmp_path_factory.mktemp("raw")
    truth = analytic_run(60.0)
    clean = synth.synthesise(truth, SensorLayout(), synth.SynthSettings(seed=5)).raw
    holed = synth.synthesise(truth, SensorLayout(), synth.SynthSettings(
        seed=5, dropouts=((30.0, 3.0),), dropout_rows=True)).raw
    clean.to_csv(folder / "run.csv", index=False)
    (folder / "holed").mkdir()
    holed.to_csv(folder / "holed" / "run.csv", index=False)
    (folder / "empty.csv").write_bytes(b"")
    (folder / "binary.csv").write_bytes(BINARY)
    (folder / "utf16.csv").write_bytes(clean.head(50).to_csv(index=False).encode("utf-16"))
    backwards = clean.copy()
    backwards.loc[300, "t [s]"] = 0.0
    backwards.to_csv(folder / "backwards.csv", index=False)
    return folder


PREPROCESS_OPTION_CASES = {
    "rate 0": (("--rate", "0"), "--rate 0"),
    "rate -1": (("--rate", "-1"), "--rate -1"),
    "rate 3 does not divide 10 Hz": (("--rate", "3"), "--rate 3"),
    "max-gap -1": (("--max-gap", "-1"), "--max-gap -1"),
    "jobs 0": (("--jobs", "0"), "--jobs 0"),
    "bad reference": (("--reference", "north"), "--reference 'north'"),
}


@pytest.mark.parametrize("case", list(PREPROCESS_OPTION_CASES))
def test_preprocess_refuses_bad_options(sysid, raw_logs, tmp_path, case):
    options, says = PREPROCESS_OPTION_CASES[case]
    out = tmp_path / "processed"
    assert_refused(sysid("preprocess", raw_logs / "run.csv", "-o", out, *options), 2, says, absent=(out,))


@pytest.mark.parametrize("bad", ["empty.csv", "binary.csv", "utf16.csv", "backwards.csv"])
def test_preprocess_bad_file_alone_writes_nothing(sysid, raw_logs, tmp_path, bad):
    out = tmp_path / "processed"
    assert_refused(sysid("preprocess", raw_logs / bad, "-o", out), 2, bad, absent=(out,))


def test_preprocess_bad_file_among_good_ones(sysid, raw_logs, tmp_path):
    out = tmp_path / "processed"
    outcome = sysid("preprocess", raw_logs / "run.csv", raw_logs / "binary.csv", "-o", out)
    assert_refused(outcome, 2, "binary.csv")
    files = verify_manifest(out, "preprocessing")["files"]  # the good file: complete and sealed
    assert sorted(files) == ["run.csv", "run.report.json"]
    assert leftovers(tmp_path) == [] and leftovers(out) == []


def test_preprocess_missing_input_and_duplicate_names(sysid, raw_logs, tmp_path):
    out = tmp_path / "processed"
    assert_refused(sysid("preprocess", tmp_path / "nope.csv", "-o", out), 2, "nope.csv: file not found", absent=(out,))
    assert_refused(sysid("preprocess", raw_logs / "run.csv", raw_logs / "holed" / "run.csv", "-o", out),
                   2, "same file name", absent=(out,))


@pytest.mark.parametrize("where", ["a file", "under /proc", "below a file"])
def test_preprocess_output_that_cannot_be_written(sysid, raw_logs, tmp_path, where):
    (tmp_path / "taken").write_text("a file")
    out = {"a file": tmp_path / "taken", "under /proc": "/proc/sysid-fuzz",
           "below a file": tmp_path / "taken" / "processed"}[where]
    line = assert_refused(sysid("preprocess", raw_logs / "run.csv", "-o", out), 2)
    assert str(out) in line
    assert (tmp_path / "taken").read_text() == "a file" and leftovers(tmp_path) == []


def test_preprocess_rerun_is_refused_or_replaces_everything(sysid, raw_logs, tmp_path):
    out = tmp_path / "processed"
    first = sysid("preprocess", raw_logs / "holed" / "run.csv", "-o", out)
    assert first.code == 0, first.err
    assert {"run_seg1.csv", "run_seg2.csv"} <= set(verify_manifest(out)["files"])
    assert_refused(sysid("preprocess", raw_logs / "run.csv", "-o", out), 2, "already exists", "--overwrite")
    assert (out / "run_seg2.csv").is_file()  # refused: the old output is untouched
    again = sysid("preprocess", raw_logs / "run.csv", "-o", out, "--overwrite")
    assert again.code == 0, again.err
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "run.csv", "run.report.json"]  # no stale segN
    verify_manifest(out, "preprocessing")
    assert leftovers(tmp_path) == []


def test_preprocess_overwrite_never_deletes_inputs_or_foreign_folders(sysid, raw_logs, tmp_path):
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "chapter1.tex").write_text("text")
    assert_refused(sysid("preprocess", raw_logs / "run.csv", "-o", mine, "--overwrite"), 2, "not written by sysid")
    out = tmp_path / "processed"
    assert sysid("preprocess", raw_logs / "run.csv", "-o", out).code == 0
    inside = out / "run.csv"
    assert_refused(sysid("preprocess", inside, "-o", out, "--overwrite"), 2, f"{out}: holds {inside}, an input")
    assert inside.is_file() and (mine / "chapter1.tex").is_file()


def test_evaluate_refuses_a_changed_preprocessing_output(sysid, raw_logs, tmp_path):
    out = tmp_path / "processed"
    assert sysid("preprocess", raw_logs / "run.csv", "-o", out).code == 0
    frame = pd.read_csv(out / "run.csv")
    frame.iloc[5, 2] += 0.1
    frame.to_csv(out / "run.csv", index=False)
    metrics = tmp_path / "m.csv"
    assert_refused(sysid("evaluate", "--data", out, "--horizon", "10", "-o", metrics), 2,
                   f"{out}: run.csv does not match its checksum", absent=(metrics,))


def test_evaluate_ignores_a_staging_directory_left_by_a_killed_job(sysid, raw_logs, tmp_path):
    out = tmp_path / "processed"
    assert sysid("preprocess", raw_logs / "run.csv", "-o", out).code == 0
    staging = tmp_path / "data" / ".processed.staging-killed"
    staging.mkdir(parents=True)
    (staging / "half.csv").write_text("t [s]\n0\n")
    (tmp_path / "data" / "run.csv").write_bytes((out / "run.csv").read_bytes())
    metrics = tmp_path / "m.csv"
    outcome = sysid("evaluate", "--data", tmp_path / "data", "--horizon", "10", "-o", metrics)
    assert outcome.code == 0, outcome.err
    assert list(pd.read_csv(metrics).file) == ["run"]
