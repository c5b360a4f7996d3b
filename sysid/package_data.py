"""Files installed with the package (package data under ``sysid/configs``): the bundled ship
definitions (``ships/NAME.toml``), the paper's Tables 7/8 (``paper/tables_7_8.csv``), the
protocol's experiment configs (``experiments/``) and example sweeps (``sweeps/``).

Read through `importlib.resources`, so they are found the same way in a source checkout, an
editable install and a wheel. ``$SYSID_CONFIGS`` (a directory with the same layout) replaces
the bundled files. In a source checkout, ``configs/`` at the repository root is a link to
``sysid/configs``.
"""
from __future__ import annotations

import os
from importlib.resources import files
from pathlib import Path

KINDS = ("ships", "paper", "experiments", "sweeps")


def configs_root() -> Path:
    """The directory holding ships/, paper/, experiments/ and sweeps/ (``$SYSID_CONFIGS`` wins).

    The package is installed as plain files (setuptools never zips it), so the resource
    directory is a real directory."""
    env = os.environ.get("SYSID_CONFIGS")
    if env:
        return Path(env)
    return Path(str(files("sysid") / "configs"))


def bundled_dir(kind: str) -> Path:
    """One of the bundled directories: ``bundled_dir("ships")``."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind of bundled file {kind!r}: choose one of {', '.join(KINDS)}")
    return configs_root() / kind
