"""Where the FRT-DS-ESSO data lives, and the benchmark protocol's file sets.

The data is never part of the project. It is found, in order: the path given,
``$SYSID_DATA``, or ``../shared/data/frt-ds-esso`` from the working directory or from the
project root. The paper's Tables 4 and 5 name the files (docs: the paper's protocol).
"""
from __future__ import annotations

import os
from pathlib import Path

from sysid.errors import DataError

# scenario -> file (relative to the dataset's data/ directory)
TEST_FILES: dict[str, str] = {
    "Berthing": "berthing/berthing_12-Nov-2020_11_49_21.csv",
    "Turning 20": "turning/turn_14-Oct-2020_14_56_07.csv",
    "Turning 35": "turning/turn_14-Sep-2020_14_50_41.csv",
    "Zigzag 20/20": "zigzag/zigzag_31-Jul-2020_13_04_24.csv",
    "Zigzag 30/30": "zigzag/zigzag_31-Jul-2020_13_14_21.csv",
    "Random": "random/random_06-Aug-2020_16_24_25_1.csv",
}

_D1_BERTHING = [f"berthing/berthing_12-Nov-2020_{t}.csv" for t in
                ("11_07_23", "11_14_47", "11_21_46", "11_38_50", "13_09_11", "13_21_03", "13_37_05")]
_D1_ZIGZAG = [f"zigzag/zigzag_31-Jul-2020_{t}.csv" for t in
              ("13_22_52", "13_29_19", "13_42_53", "13_57_45", "14_03_39", "14_10_05")]
_D2_RANDOM = ["random/random_03-Aug-2020_11_04_37.csv"] + [
    f"random/random_06-Aug-2020_16_24_25_{i}.csv" for i in (3, 4, 5, 6)] + [
    "random/random_31-Jul-2020_12_29_58.csv", "random/random_31-Jul-2020_12_48_39.csv"]


def data_root(path: str | os.PathLike | None = None) -> Path:
    """The dataset's root directory (the one holding ``data/``), or a clear error."""
    candidates: list[Path] = []
    if path is not None:
        candidates.append(Path(path))
    elif os.environ.get("SYSID_DATA"):
        candidates.append(Path(os.environ["SYSID_DATA"]))
    else:
        candidates += [Path.cwd() / "../shared/data/frt-ds-esso",
                       Path(__file__).resolve().parents[2] / "../shared/data/frt-ds-esso"]
    for c in candidates:
        if (c / "data").is_dir():
            return c.resolve()
        if c.is_dir() and c.name == "data" and any(c.glob("*/*.csv")):
            return c.parent.resolve()
    tried = ", ".join(str(c) for c in candidates)
    raise DataError(
        f"FRT-DS-ESSO dataset not found (looked in {tried}); pass --data DIR or set SYSID_DATA "
        "to the directory that holds data/berthing, data/turning, ...")


def data_dir(path: str | os.PathLike | None = None) -> Path:
    """The ``data/`` directory with the maneuver sub-directories."""
    return data_root(path) / "data"


def turning_files(root: Path) -> list[str]:
    """Every turning file of the dataset (both ``turn_cut_*`` included), sorted."""
    return sorted(str(p.relative_to(root)) for p in (root / "turning").glob("*.csv"))


def training_files(name: str, path: str | os.PathLike | None = None) -> list[Path]:
    """The paper's training set ``D1`` or ``D2`` as absolute paths."""
    root = data_dir(path)
    tests = set(TEST_FILES.values())
    d1 = _D1_BERTHING + [f for f in turning_files(root) if f not in tests] + _D1_ZIGZAG
    sets = {"D1": d1, "D2": d1 + _D2_RANDOM}
    if name not in sets:
        raise DataError(f"unknown data set {name!r}: choose D1 or D2")
    files = [root / f for f in sets[name]]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        raise DataError(f"data set {name}: missing file(s) {missing}")
    return files


def test_files(path: str | os.PathLike | None = None) -> dict[str, Path]:
    """The six test scenarios of the paper's Table 5, scenario -> path."""
    root = data_dir(path)
    return {k: root / v for k, v in TEST_FILES.items()}
