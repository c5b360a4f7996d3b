"""The one TOML reader behind experiment configs, ship files and sweep files: a bad file is
one line naming the file and what is wrong with it, with the loader's own error type."""
from __future__ import annotations

import tomllib

import pytest

from sysid.config.experiment import load_experiment
from sysid.errors import ConfigError, ShipDefinitionError
from sysid.mmg.ship import load_ship
from sysid.sweep.spec import load_sweep

def _toml_error(text: str) -> str:
    """What Python's TOML parser says of `text` (its line and column)."""
    with pytest.raises(tomllib.TOMLDecodeError) as err:
        tomllib.loads(text)
    return str(err.value)


BROKEN = "[experiment\nmodel = 'mmg'\n"  # the table header is not closed
LOADERS = [(load_experiment, ConfigError, "config file"), (load_ship, ShipDefinitionError, "ship file"),
           (load_sweep, ConfigError, "sweep file")]


@pytest.mark.parametrize("load, error, what", LOADERS, ids=["experiment", "ship", "sweep"])
def test_bad_toml_files_are_one_line_naming_the_file(tmp_path, load, error, what):
    cases = {
        "utf16.toml": ("[experiment]\nmodel = 'mmg'\n".encode("utf-16"),
                       f"not UTF-8 text (binary, or another encoding such as UTF-16); a {what} is a UTF-8 TOML file"),
        "broken.toml": (BROKEN.encode(), f"not valid TOML ({_toml_error(BROKEN)})"),
    }
    for name, (content, said) in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(error) as err:
            load(path)
        assert str(err.value) == f"{path}: {said}"
        assert "\n" not in str(err.value)
    if load is not load_ship:  # a ship name or path is resolved (and its absence said) first
        with pytest.raises(error, match=f"missing.toml: {what} not found$"):
            load(tmp_path / "missing.toml")
