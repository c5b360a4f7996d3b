"""A user's sweep on their own logs, with no paper data set anywhere: a project folder that
also holds a folder named ``sysid`` (a package that is not sysid: importing it fails), the
user's logs (real FRT-DS-ESSO berthing runs renamed, in knots, degrees, rpm and deg/s,
`own_logs`), a tiny hybrid base config that maps them with ``[data.columns]`` and validates
on ``[data] validation`` logs, and a sweep of two learning rates (two trials, one seed)."""
from __future__ import annotations

import sys
from pathlib import Path

from own_logs import columns_table, write_own_log

TRAIN = ("berthing_12-Nov-2020_11_07_23.csv", "berthing_12-Nov-2020_11_14_47.csv")
VALIDATION = "berthing_12-Nov-2020_13_09_11.csv"
SYSID = str(Path(sys.executable).with_name("sysid"))   # the console script: the installed sysid


def own_sweep_project(project: Path, dataset_dir: Path, epochs: int = 2, logs_folder: str = "my logs",
                      name: str = "own") -> Path:
    """Write the project into `project` (the logs in `logs_folder`, the sweep named `name`);
    returns its sweep file."""
    (project / "sysid").mkdir(parents=True)
    (project / "sysid" / "__init__.py").write_text(
        "raise ImportError('this folder is not sysid: the installed sysid was to be imported')\n")
    logs = project / logs_folder
    logs.mkdir()
    for i, log in enumerate(TRAIN):
        write_own_log(dataset_dir / "berthing" / log, logs / f"harbour_{i}.csv")
    write_own_log(dataset_dir / "berthing" / VALIDATION, logs / "harbour_check.csv")
    (project / "base.toml").write_text(
        "[experiment]\nname = 'mine'\nmodel = 'hybrid'\nseed = 0\nship = 'esso_osaka'\n"
        f"[data]\ntrain = ['{logs_folder}/harbour_0.csv', '{logs_folder}/harbour_1.csv']\n"
        f"validation = ['{logs_folder}/harbour_check.csv']\n"
        + columns_table() +
        f"[network]\nhidden = [8]\n[training]\nepochs = {epochs}\nwarm_start_epochs = 1\nbatch_size = 64\n"
        "[gate]\nk = 3\nspace = 'inputs'\n[evaluation]\nhorizons = [30.0]\n")
    sweep = project / "own.toml"
    sweep.write_text(f"[sweep]\nname = '{name}'\nbase = 'base.toml'\nseeds = [0]\nmax_retries = 1\n"
                     "[vary]\n'training.learning_rate' = [1e-3, 3e-3]\n")
    return sweep


def no_paper_data(env: dict, nowhere: Path) -> dict:
    """`env` with the paper's data set nowhere: SYSID_DATA names an empty folder."""
    nowhere.mkdir(parents=True, exist_ok=True)
    return {**{k: v for k, v in env.items() if k != "PYTHONPATH" or v}, "SYSID_DATA": str(nowhere)}


def validation_files(run_dir: Path) -> list[str]:
    """The ``[data] validation`` logs a trial's summary says it was validated on (names)."""
    import json
    data = json.loads((run_dir / "summary.json").read_text())["data"]
    return sorted(Path(f["file"]).name for f in data["validation"])


