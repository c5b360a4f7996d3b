"""Your logs on real data: the column/unit map, the Parquet reader, paths relative to the
config from another working directory, and the training/test overlap error."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from sysid.config.experiment import load_experiment
from sysid.data.columns import parse_columns
from sysid.data.recordings import read_run
from sysid.data.splits import TEST, TRAINING, check_disjoint_runs, data_split
from sysid.errors import ConfigError, DataError
from sysid.runs.lifecycle import evaluation_runs, training_runs
from own_logs import DEG, KNOT, columns_table, write_own_log

ZIGZAG = "zigzag/zigzag_31-Jul-2020_13_57_45.csv"     # none of these is a paper test file
BERTHING = "berthing/berthing_12-Nov-2020_13_37_05.csv"


def _config(path, train, test=(), extra=""):
    path.write_text("[experiment]\nmodel = 'hybrid'\n"
                    f"[data]\ntrain = {json.dumps([str(f) for f in train])}\ntest = {json.dumps([str(f) for f in test])}\n"
                    + extra)
    return path


def test_column_map_reads_renamed_columns_in_knots_and_degrees(dataset_dir, tmp_path):
    own = write_own_log(dataset_dir / ZIGZAG, tmp_path / "my_zigzag.csv")
    written = pd.read_csv(own)
    original = pd.read_csv(dataset_dir / ZIGZAG)
    # the log really is in the user's units: 1 knot = 0.5144 m/s, 1 deg = 0.01745 rad
    assert written["surge speed"].iloc[100] == pytest.approx(original["u_velo [m/s]"].iloc[100] / KNOT, rel=1e-12)
    assert written["heading"].iloc[100] == pytest.approx(original["psi_hat [rad]"].iloc[100] / DEG, rel=1e-12)
    assert written["shaft"].iloc[100] == pytest.approx(original["n_prop [rps]"].iloc[100] * 60.0, rel=1e-12)
    config = _config(tmp_path / "exp.toml", [own], extra=columns_table())
    mine = training_runs(load_experiment(config))[0]
    truth = read_run(dataset_dir / ZIGZAG)
    assert mine.name == "my_zigzag" and len(mine) == len(truth) > 100
    np.testing.assert_allclose(mine.t, truth.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mine.states, truth.states, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(mine.inputs, truth.inputs, rtol=1e-12, atol=1e-15)
    # no relative wind in the log: computed from the state and true wind, near the recorded one
    assert np.median(np.abs(mine.relative_wind[:, 0] - truth.relative_wind[:, 0])) < 0.2   # m/s


def test_parquet_log_reads_as_its_csv(dataset_dir, tmp_path):
    frame = pd.read_csv(dataset_dir / BERTHING)
    frame.to_parquet(tmp_path / "berthing.parquet", index=False)
    as_parquet, as_csv = read_run(tmp_path / "berthing.parquet"), read_run(dataset_dir / BERTHING)
    assert len(as_parquet) == len(as_csv) > 50
    np.testing.assert_array_equal(as_parquet.states, as_csv.states)
    np.testing.assert_array_equal(as_parquet.inputs, as_csv.inputs)
    # Parquet with the user's names and units, through [data.columns]
    own = write_own_log(dataset_dir / BERTHING, tmp_path / "own.parquet")
    mapped = read_run(own, columns=parse_columns(_table(), "exp.toml"))
    np.testing.assert_allclose(mapped.states, as_csv.states, rtol=1e-12, atol=1e-15)
    broken = tmp_path / "broken.parquet"
    broken.write_bytes(b"PAR1 not really")
    with pytest.raises(DataError, match=r"broken\.parquet: not a readable Parquet file"):
        read_run(broken)


def _table() -> dict:
    import tomllib
    return tomllib.loads(columns_table())["data"]["columns"]


def test_column_errors_name_the_file_the_column_and_the_fix(dataset_dir, tmp_path):
    own = write_own_log(dataset_dir / BERTHING, tmp_path / "own.csv")
    table = _table()
    with pytest.raises(DataError, match=r"own\.csv: no column 't \[s\]' for channel t, 'x_position_mid \[m\]' for "
                                        r"channel x, .*for channel wind_dir_true \(the file has .*'surge speed'.*\[data.columns\], "
                                        r"e\.g\. t = \{ column"):
        read_run(own)   # no map: the processed schema's headers are missing
    wrong = {**table, "u": {"column": "surge spd", "unit": "knots"}}
    with pytest.raises(DataError, match=r"own\.csv: no column 'surge spd' for channel u .*correct u in \[data.columns\]"):
        read_run(own, columns=parse_columns(wrong, "exp.toml"))
    with pytest.raises(ConfigError, match=r"exp\.toml: \[data.columns\] psi: unit 'knots' is a unit of speed; "
                                          r"channel psi is an angle: use one of rad, deg"):
        parse_columns({**table, "psi": {"column": "heading", "unit": "knots"}}, "exp.toml")
    # degrees read as radians: the plausibility check names the column and the unit to set
    as_radians = {**table, "delta_rudder": {"column": "rudder", "unit": "rad"}}
    with pytest.raises(DataError, match=r"own\.csv: column 'rudder' \[rad\] \(channel delta_rudder\) reaches .* "
                                        r"wrong units\? .*unit = \"deg\""):
        read_run(own, columns=parse_columns(as_radians, "exp.toml"))


def test_every_bad_column_is_named_in_one_line(dataset_dir, tmp_path):
    """Degrees read as radians in two columns (rudder, true wind direction), text in two columns: each
    problem is one error naming every column it concerns."""
    import pandas as pd

    own = write_own_log(dataset_dir / BERTHING, tmp_path / "own.csv")
    table = _table()
    as_radians = {**table, "delta_rudder": {"column": "rudder", "unit": "rad"},
                  "wind_dir_true": {"column": "true wind from", "unit": "rad"}}
    with pytest.raises(DataError) as found:
        read_run(own, columns=parse_columns(as_radians, "exp.toml"))
    line = str(found.value)
    assert "\n" not in line and line.count("reaches") == 2
    assert "column 'true wind from' [rad] (channel wind_dir_true) reaches" in line
    assert "column 'rudder' [rad] (channel delta_rudder) reaches" in line
    assert 'wind_dir_true = { column = "...", unit = "deg" }' in line and 'delta_rudder = { column = "...", unit = "deg" }' in line
    frame = pd.read_csv(own, dtype=str)
    frame.loc[3, "shaft"], frame.loc[5, "heading"] = "12 rpm", "NNE"
    texts = tmp_path / "texts.csv"
    frame.to_csv(texts, index=False)
    with pytest.raises(DataError, match=r"texts\.csv: not a number in 2 column\(s\): column 'heading' \(channel psi\) "
                                        r"holds 'NNE' at line 7; column 'shaft' \(channel n_prop\) holds '12 rpm' "
                                        r"at line 5; write numbers only"):
        read_run(texts, columns=parse_columns(table, "exp.toml"))


def test_relative_paths_resolve_against_the_config_from_another_directory(dataset_dir, tmp_path, monkeypatch):
    project = tmp_path / "project"
    (project / "logs").mkdir(parents=True)
    (project / "configs").mkdir()
    for name in ("turn_a.csv", "turn_b.csv"):
        shutil.copy(dataset_dir / ZIGZAG if name == "turn_a.csv" else dataset_dir / BERTHING, project / "logs" / name)
    shutil.copy(dataset_dir / "berthing/berthing_12-Nov-2020_13_09_11.csv", project / "logs" / "held_out.csv")
    config = project / "configs" / "exp.toml"
    config.write_text("[experiment]\nmodel = 'hybrid'\nship = '../ships/my_ship.toml'\n"
                      "[data]\ntrain = ['../logs/turn_*.csv']\ntest = ['../logs/held_out.csv']\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    exp = load_experiment("../project/configs/exp.toml")
    assert exp.experiment.ship == str(project / "ships" / "my_ship.toml")
    split = data_split(exp)
    assert list(split.train) == [project / "logs" / "turn_a.csv", project / "logs" / "turn_b.csv"]
    assert list(split.test) == [project / "logs" / "held_out.csv"] and split.source == "files"
    runs, tests = training_runs(exp), evaluation_runs(exp)
    np.testing.assert_array_equal(runs[0].states, read_run(dataset_dir / ZIGZAG).states)
    assert [r.name for r in tests] == ["held_out"]
    # the same config from its own folder: the same files
    monkeypatch.chdir(project / "configs")
    assert data_split(load_experiment("exp.toml")).train == split.train


def test_a_log_in_training_and_test_is_an_error_naming_both(dataset_dir, tmp_path):
    zigzag, berthing = dataset_dir / ZIGZAG, dataset_dir / BERTHING
    same = _config(tmp_path / "same.toml", [zigzag, berthing], [zigzag])
    with pytest.raises(DataError, match=rf"{zigzag.name} is listed in training and in test"):
        data_split(load_experiment(same))
    copy = tmp_path / "renamed_log.csv"
    shutil.copy(zigzag, copy)
    twice = _config(tmp_path / "twice.toml", [zigzag, berthing, copy])
    with pytest.raises(DataError, match=rf"renamed_log\.csv \(training\) and .*{zigzag.name} \(training\) have "
                                        r"identical content \(SHA-256"):
        data_split(load_experiment(twice))
    # a renamed copy as a test log: the split opens no test file (training reads none), the
    # samples' check when the run is evaluated names both
    split = data_split(load_experiment(_config(tmp_path / "renamed.toml", [zigzag, berthing], [copy])))
    with pytest.raises(DataError, match=rf"renamed_log\.csv \(test\) holds the same samples as .*{zigzag.name} "
                                        r"\(training\)"):
        check_disjoint_runs({TRAINING: [read_run(p) for p in split.train], TEST: [read_run(p) for p in split.test]})
    # the same recording in another format and other units: the same samples
    own = write_own_log(zigzag, tmp_path / "converted.parquet")
    converted = read_run(own, columns=parse_columns(_table(), "exp.toml"))
    with pytest.raises(DataError, match=r"converted\.parquet \(test\) holds the same samples as .*"
                                        rf"{zigzag.name} \(training\)"):
        check_disjoint_runs({TRAINING: [read_run(zigzag), read_run(berthing)], TEST: [converted]})


def test_the_paper_test_set_only_for_a_paper_data_set(dataset_dir, tmp_path):
    own = _config(tmp_path / "own.toml", [dataset_dir / BERTHING])
    split = data_split(load_experiment(own))
    assert split.test == () and split.test_source == "none"
    paper = tmp_path / "paper.toml"
    paper.write_text("[experiment]\nmodel = 'hybrid'\ndataset = 'D1'\n")
    split = data_split(load_experiment(paper))
    assert split.test_source == "paper" and len(split.test) == 6 and split.source == "D1"
    both = tmp_path / "both.toml"
    both.write_text(paper.read_text() + f"[data]\ntrain = [{json.dumps(str(dataset_dir / BERTHING))}]\n")
    with pytest.raises(ConfigError, match=r"dataset = 'D1' and \[data\] train both name training data"):
        load_experiment(both)


def test_a_log_at_another_rate_is_resampled_with_a_message_or_refused(dataset_dir, tmp_path):
    """The dataset's 10 Hz processed logs read at 1 Hz: every 10th sample from the first, said
    once (a stage line naming the file and both rates); a rate that is not a whole number of
    the file's samples, or above its own, is refused in one line."""
    import logging

    import pandas as pd

    from sysid.data import recordings

    source = dataset_dir / BERTHING
    raw = pd.read_csv(source)
    heard: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: heard.append(record.getMessage())
    logger = logging.getLogger("sysid")
    logger.addHandler(handler)
    old_level = logger.level
    logger.setLevel(logging.INFO)
    recordings._NOTED.clear()
    try:
        run = read_run(source)
        again = read_run(source)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old_level)
    assert run.stride == 10 and run.dt == pytest.approx(1.0)
    np.testing.assert_array_equal(run.t, raw["t [s]"].to_numpy()[:len(run.t) * 10:10])
    np.testing.assert_array_equal(again.states, run.states)
    said = [line for line in heard if "read at 1 Hz" in line]
    assert len(said) == 1 and source.name in said[0] and "10 Hz" in said[0] and "every 10th sample" in said[0]
    with pytest.raises(DataError, match=r"rate 3 Hz is not a whole number of this file's 0\.1-s samples"):
        read_run(source, rate=3.0)
    one_hz = tmp_path / "one_hz.csv"
    raw.iloc[::10].to_csv(one_hz, index=False)
    assert read_run(one_hz).stride == 1
    with pytest.raises(DataError, match=r"one_hz\.csv: rate 10 Hz is not a whole number .*divides 1 Hz"):
        read_run(one_hz, rate=10.0)
