"""``[data]`` of an experiment config: train / validation / test lists, a validation fraction,
the older ``files`` name, ``[data.columns]``, and the resolved config that round-trips."""
from __future__ import annotations

import math
import tomllib

import pytest

from sysid.config.experiment import load_experiment, parse_experiment
from sysid.data.columns import ColumnSpec
from sysid.errors import ConfigError


def _write(path, text):
    path.write_text("[experiment]\nmodel = 'hybrid'\n" + text)
    return path


def test_validation_as_files_or_a_fraction(tmp_path):
    files = load_experiment(_write(tmp_path / "a.toml", "[data]\ntrain = ['a.csv']\nvalidation = ['v/*.csv']\n"))
    assert files.data.validation == (str(tmp_path / "v" / "*.csv"),) and files.training.val_fraction == 0.3
    fraction = load_experiment(_write(tmp_path / "b.toml", "[data]\ntrain = ['a.csv']\nvalidation = 0.25\n"))
    assert fraction.data.validation == () and fraction.training.val_fraction == 0.25
    with pytest.raises(ConfigError, match=r"\[data\] validation = 0.25 and \[training\] val_fraction = 0.4 disagree"):
        load_experiment(_write(tmp_path / "c.toml", "[data]\ntrain = ['a.csv']\nvalidation = 0.25\n"
                                                     "[training]\nval_fraction = 0.4\n"))
    with pytest.raises(ConfigError, match=r"\[data\] validation files need \[data\] train files"):
        load_experiment(_write(tmp_path / "d.toml", "[data]\nvalidation = ['v.csv']\n"))


def test_validation_by_blocks_or_by_held_out_files(tmp_path):
    from sysid.config.choices import Validation
    default = load_experiment(_write(tmp_path / "a.toml", "[data]\ntrain = ['a.csv']\n"))
    assert default.training.validation is Validation.BLOCKS and default.training.split_seed == 0
    files = load_experiment(_write(tmp_path / "b.toml", "[data]\ntrain = ['a.csv']\n"
                                                        "[training]\nvalidation = 'files'\nsplit_seed = 4\n"))
    assert files.training.validation is Validation.FILES and files.training.split_seed == 4
    (tmp_path / "c.toml").write_text(files.to_toml())
    assert load_experiment(tmp_path / "c.toml").training == files.training
    with pytest.raises(ConfigError, match=r"b\.toml: \[data\] validation names the validation logs and \[training\] "
                                          r"validation = \"files\" draws them from the training logs: keep one"):
        load_experiment(_write(tmp_path / "b.toml", "[data]\ntrain = ['a.csv']\nvalidation = ['v.csv']\n"
                                                    "[training]\nvalidation = 'files'\n"))
    with pytest.raises(ConfigError, match=r"\[training\] split_seed = -1: must be >= 0"):
        load_experiment(_write(tmp_path / "d.toml", "[data]\ntrain = ['a.csv']\n[training]\nsplit_seed = -1\n"))


def test_files_is_the_older_name_of_train(tmp_path):
    exp = load_experiment(_write(tmp_path / "old.toml", "[data]\nfiles = ['logs/a.csv']\n"))
    assert exp.data.train == (str(tmp_path / "logs" / "a.csv"),)
    with pytest.raises(ConfigError, match=r"\[data\] files and train both list training logs"):
        load_experiment(_write(tmp_path / "both.toml", "[data]\nfiles = ['a.csv']\ntrain = ['b.csv']\n"))


def test_columns_parse_and_the_resolved_config_round_trips(tmp_path):
    exp = load_experiment(_write(tmp_path / "c.toml", "[data]\ntrain = ['a.csv']\ntest = ['t.parquet']\n"
                                 "[data.columns]\nt = 'time [min]'\nu = { column = 'STW', unit = 'knots' }\n"
                                 "wind_velo_true = 0.0\n"))
    columns = exp.data.columns
    assert columns.spec("u") == ColumnSpec("u", "STW", "knots")
    assert columns.spec("t").resolved_unit == "min" and columns.spec("t").factor == 60.0
    assert columns.spec("u").factor == pytest.approx(1852.0 / 3600.0, rel=1e-15)
    assert columns.spec("wind_velo_true").constant == 0.0
    assert columns.spec("psi").column == "psi_hat [rad]"   # unmapped: the processed schema's column
    again = parse_experiment(tomllib.loads(exp.to_toml()), "resolved")
    assert again.data == exp.data and again.experiment == exp.experiment
    assert math.isclose(again.data.columns.spec("r").factor, 1.0)


@pytest.mark.parametrize("table, message", [
    ("speed = 'v'", r"unknown channel 'speed'"),
    ("u = { column = 'STW', unit = 'furlongs' }", r"u: unit 'furlongs' is not a unit sysid knows; channel u is a "
                                                   r"speed: use one of m/s, knots"),
    ("r = { column = 'ROT', unit = 'deg' }", r"r: unit 'deg' is a unit of angle; channel r is an angular rate"),
    ("u = { column = 'STW', units = 'knots' }", r"u: unknown key\(s\) \['units'\]"),
    ("u = 'a'\nv = 'a'", r"column 'a' is mapped onto more than one channel"),
    ("t = 0.0", r"t: time cannot be a constant"),
])
def test_bad_column_maps_name_the_config_the_channel_and_the_fix(tmp_path, table, message):
    with pytest.raises(ConfigError, match=r"bad\.toml: \[data.columns\] " + message):
        load_experiment(_write(tmp_path / "bad.toml", "[data]\ntrain = ['a.csv']\n[data.columns]\n" + table + "\n"))


def test_own_logs_without_a_ship_are_warned_of_the_paper_ship_they_get(tmp_path, caplog):
    """Your logs in [data] train and no [experiment] ship: the config resolves to the bundled
    Esso Osaka, and one WARNING names the config, the key, that ship and the fix. A config
    that names its ship, or the paper's data set, is not warned."""
    import logging
    caplog.set_level(logging.WARNING, logger="sysid")
    exp = load_experiment(_write(tmp_path / "own.toml", "[data]\ntrain = ['logs/*.csv']\n"))
    assert exp.experiment.ship == "esso_osaka"
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert said == [f"{tmp_path / 'own.toml'}: [experiment] ship is not set, so your logs are modelled with the "
                    "bundled esso_osaka (the paper's Esso Osaka 3 m model): set ship = \"my_ship.toml\" (your ship "
                    "file; `sysid init` writes one), or ship = \"esso_osaka\" to keep it"]
    caplog.clear()
    load_experiment(_write(tmp_path / "named.toml", "ship = 'esso_osaka'\n[data]\ntrain = ['logs/*.csv']\n"))
    parse_experiment({"experiment": {"model": "hybrid", "dataset": "D2"}})
    assert [r for r in caplog.records if r.levelno == logging.WARNING] == []
