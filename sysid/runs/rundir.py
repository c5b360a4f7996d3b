"""`RunDir`: the files of a run directory (layout: `sysid.runs.layout`) and the one reader
of them. The report, sweeps, seed runs, model loading and the CLI open a run here.

Every read is checked: a missing or corrupt file raises `CheckpointError` naming it, and a
run whose manifest is missing or disagrees with its files is refused by `RunDir.open`
(`IncompleteOutputError`). A pure reader: importing it loads neither torch nor training
code (the weights and the kNN bank are read with torch only when asked for).

A run keeps a copy of the ship file it was made with (``ship/NAME.toml``); its experiment
(`RunDir.read_experiment`) names that copy, so the run's MMG and physics baseline stay
those it was trained and judged with after the original is moved or edited. A run written
before the copy was kept names the original, as its config.toml does.

The logs a run was made from are named relative to the run directory, with their absolute
path and SHA-256 in summary.json (`sysid.runs.log_paths`): `read_experiment` finds them
where they are now, `read_test_logs` checks the ones a command reads.
"""
from __future__ import annotations

import hashlib
import logging
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import pandas as pd

from sysid.config.experiment import Experiment, is_ship_path, load_experiment
from sysid.errors import CheckpointError, ConfigError, IncompleteOutputError
from sysid.records.columns import (BASELINE_METRICS_COLUMNS, HISTORY_COLUMNS, METRICS_COLUMNS,  # noqa: F401
                                   REQUIRED_METRICS_COLUMNS, TRACE_COLUMNS, baseline_folder, trace_name)
from sysid.records.summary import DataSummary, RunSummary
from sysid.runs import log_paths
from sysid.store.manifest import MANIFEST, has_manifest, verify_manifest

if TYPE_CHECKING:
    from sysid.runs.knn_bank import KnnBank


def read_table(path: Path, columns: list[str], required: bool = True) -> pd.DataFrame | None:
    """A CSV table with (at least) `columns`; None when absent and not `required`;
    `CheckpointError` naming the file otherwise."""
    if not path.is_file():
        if required:
            raise CheckpointError(f"{path}: file not found")
        return None
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: not a readable CSV ({exc})") from None
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise CheckpointError(f"{path}: missing column(s) {missing}")
    return frame


def with_divergence(frame: pd.DataFrame) -> pd.DataFrame:
    """A metrics table with its ``diverged`` and ``diverged_at_s`` columns (False, NaN when
    absent: a run written before divergence was marked)."""
    if "diverged" not in frame.columns:
        frame = frame.assign(diverged=False)
    if "diverged_at_s" not in frame.columns:
        frame = frame.assign(diverged_at_s=float("nan"))
    return frame.assign(diverged=frame["diverged"].fillna(False).astype(bool))


SHIP_FOLDER = "ship"   # a run's copy of its ship file: ship/NAME.toml


def ship_copy_name(ship: str) -> str:
    """The file name of a run's copy of the ship file `ship` (``[experiment] ship``): the
    file's own name (so a ship file without ``[ship] name`` keeps its name, the file's
    stem), ``NAME.toml`` for a bundled ship."""
    return Path(ship).name if is_ship_path(ship) else f"{ship}.toml"


_told: set[tuple[str, int, str]] = set()   # (original, its mtime_ns, the copy's SHA-256) already said


def _say_if_edited(ship: str, copy: Path, run: Path) -> None:
    """One warning line when the ship file `ship` the run at `run` was made from still
    exists and differs from the run's `copy` of it; said once per process for an original
    and the copies with the same bytes (an ensemble's members, a run loaded twice)."""
    from sysid.errors import ShipDefinitionError
    from sysid.mmg.ship import resolve_ship_path  # no torch

    try:
        original = resolve_ship_path(ship)
        kept = copy.read_bytes()
        edited = original.read_bytes() != kept
        key = (str(original.resolve()), original.stat().st_mtime_ns, hashlib.sha256(kept).hexdigest())
    except (ShipDefinitionError, OSError):  # moved away, renamed or unreadable: the copy is all there is
        return
    if edited and key not in _told:
        _told.add(key)
        logging.getLogger(__name__).warning(
            f"{original} differs from {copy}, the copy of it the run was made with: the run uses its copy "
            f"(to judge the run against the edited file: sysid evaluate {run} --ship {original})")


def _file(name: str, what: str) -> property:
    """A property: the path of `name` in the run directory."""
    return property(lambda self: self.path / name, doc=f"{name}: {what}.")


@dataclass(frozen=True)
class RunDir:
    """A run directory at `path`: its files' paths, and their checked readers."""

    path: Path
    REQUIRED: ClassVar[tuple[str, ...]] = ("config.toml", "summary.json", "metrics.csv")

    def __post_init__(self):
        object.__setattr__(self, "path", Path(self.path))  # a str given is a Path here

    @classmethod
    def open(cls, path: str | os.PathLike) -> "RunDir":
        """The run directory at `path`, verified against its manifest (every listed file
        present and unchanged, the `REQUIRED` ones listed)."""
        path = Path(path)
        if not path.is_dir():
            raise CheckpointError(f"{path}: run directory not found")
        verify_manifest(path, "run", cls.REQUIRED)
        return cls(path)

    @classmethod
    def complete(cls, path: str | os.PathLike) -> "RunDir | None":
        """The run directory at `path` when it is complete, else None (never written,
        interrupted, changed afterwards)."""
        if not has_manifest(path):
            return None
        try:
            return cls.open(path)
        except (IncompleteOutputError, CheckpointError, OSError):
            return None

    # -- the files -----------------------------------------------------------------
    config = _file("config.toml", "the resolved experiment config")
    summary = _file("summary.json", "`RunSummary`")
    model = _file("model.pt", "the state dict without the kNN bank (trained runs only)")
    knn = _file("knn.pt", "`KnnBank` (hybrid and NN runs with a gate)")
    standardization = _file("standardization.json", "the FNN's input and output mean and std")
    history = _file("history.csv", "losses per stage and epoch (trained runs only)")
    metrics = _file("metrics.csv", "`sysid.records.columns.METRICS_COLUMNS`")
    baseline_metrics = _file("baseline_metrics.csv", "the physics baselines on the same test logs "
                             "(`BASELINE_METRICS_COLUMNS`; runs with a verdict and test logs)")
    traces = _file("traces", "one CSV per (test file, horizon)")
    baseline_traces = _file("baseline_traces", "each physics baseline's traces on the same windows, one "
                            "folder per baseline (`baseline_folder`; runs written before sysid kept them: none)")
    ship_folder = _file(SHIP_FOLDER, "the copy of the ship file the run was made with "
                        "(runs written before sysid kept it: none)")
    manifest = _file(MANIFEST, "every other file with its SHA-256, written last")

    def ship_copy(self, ship: str) -> Path:
        """Where the run keeps its copy of the ship file `ship` (``[experiment] ship``)."""
        return self.ship_folder / ship_copy_name(ship)

    def trace(self, file_stem: str, horizon_s: float) -> Path:
        """The trace of a test file at a horizon [s]."""
        return self.traces / trace_name(file_stem, horizon_s)

    # -- reading them --------------------------------------------------------------
    def read_summary(self) -> RunSummary:
        return RunSummary.read(self.summary)

    def read_config_text(self) -> str:
        if not self.config.is_file():
            raise CheckpointError(f"{self.config}: file not found")
        return self.config.read_text()

    def read_config(self) -> dict:
        """config.toml as a TOML table (as written: every section, defaults filled in)."""
        try:
            return tomllib.loads(self.read_config_text())
        except tomllib.TOMLDecodeError as exc:
            raise CheckpointError(f"{self.config}: not valid TOML ({exc})") from None

    def read_experiment(self, ship: str | None = None) -> Experiment:
        """config.toml as an `Experiment` whose ship is the run's copy of its ship file
        (`ship_copy`; a run without one: the file config.toml names, found again as its
        logs are), or `ship` when given
        (a ship file or bundled name the user chose instead). When the original ship file
        still exists and differs from the copy, one warning line names both. Its ``[data]``
        logs are where they are now (`sysid.runs.log_paths.found_again`: relative to the run
        directory, else where they were when it was made)."""
        try:
            exp = load_experiment(self.config)
        except ConfigError as exc:
            raise CheckpointError(f"{self.path}: bad run config ({exc})") from None
        data = self._logs_recorded()
        exp = exp.replace(data={part: log_paths.found_again(getattr(exp.data, part), data, self.path)
                                for part in log_paths.PARTS if getattr(exp.data, part)})
        if ship is not None:
            return exp.replace(experiment={"ship": str(ship)})
        copy = self.ship_copy(exp.experiment.ship)
        original = self._ship_found_again(exp.experiment.ship)
        if not copy.is_file():   # written before runs kept their ship file
            return exp.replace(experiment={"ship": original})
        _say_if_edited(original, copy, self.path)
        return exp.replace(experiment={"ship": str(copy.absolute())})

    def _ship_found_again(self, ship: str) -> str:
        """The ship file config.toml names (relative to the run directory), else where it
        was when the run was made (summary.json ``ship``), else as named."""
        if not is_ship_path(ship) or Path(ship).is_file() or not self.summary.is_file():
            return ship
        then = self.read_summary().ship
        return then if then is not None and is_ship_path(then) and Path(then).is_file() else ship

    def _logs_recorded(self) -> DataSummary | None:
        """summary.json ``data`` (None: a run without it, or without summary.json yet)."""
        return self.read_summary().data if self.summary.is_file() else None

    def read_test_logs(self, exp: Experiment) -> list[Path]:
        """The run's ``[data] test`` logs (of `exp`, its `read_experiment`) to read again:
        `DataError` naming the run, the missing file and the fix; one warning line for a
        log whose bytes differ from those the run recorded (`sysid.runs.log_paths.checked`)."""
        return log_paths.checked(exp.data.test, self._logs_recorded(), self.path, "test")

    def read_metrics(self) -> pd.DataFrame:
        """metrics.csv as written (RMSE of u, v_m [m/s] and r [rad/s]); a run written before
        divergence was marked reads as not diverged."""
        return with_divergence(read_table(self.metrics, REQUIRED_METRICS_COLUMNS))

    def read_baseline_metrics(self) -> pd.DataFrame | None:
        """baseline_metrics.csv (`BASELINE_METRICS_COLUMNS`), None for a run without one."""
        frame = read_table(self.baseline_metrics, ["baseline"] + REQUIRED_METRICS_COLUMNS, required=False)
        return with_divergence(frame) if frame is not None else None

    def read_history(self) -> pd.DataFrame | None:
        """history.csv, None for an untrained run. Runs written before ``val_loss_multistep``
        named the per-epoch ``early_stopping_loss`` ``val_loss``: read under the new name."""
        history = read_table(self.history, HISTORY_COLUMNS[:2], required=False)
        if history is None:
            return None
        history = history.rename(columns={"val_loss": "early_stopping_loss"})
        if "early_stopping_loss" not in history.columns:
            raise CheckpointError(f"{self.history}: missing column(s) ['early_stopping_loss']")
        return history

    def read_trace(self, file_stem: str, horizon_s: float) -> pd.DataFrame | None:
        """A trace (`TRACE_COLUMNS`), None when the run has none for that file and horizon."""
        return read_table(self.trace(file_stem, horizon_s), TRACE_COLUMNS, required=False)

    def baseline_trace(self, label: str, file_stem: str, horizon_s: float) -> Path:
        """The trace of the physics baseline `label` on a test file at a horizon [s]."""
        return self.baseline_traces / baseline_folder(label) / trace_name(file_stem, horizon_s)

    def read_baseline_trace(self, label: str, file_stem: str, horizon_s: float) -> pd.DataFrame | None:
        """A physics baseline's trace (`TRACE_COLUMNS`) on the windows of the run's own trace,
        None when the run has none for that baseline, file and horizon."""
        return read_table(self.baseline_trace(label, file_stem, horizon_s), TRACE_COLUMNS, required=False)

    def read_model_state(self) -> dict:
        """model.pt: the state dict (plain tensors, all finite)."""
        from sysid.runs.tensor_files import check_finite, load_tensors  # torch: only when asked
        state = load_tensors(self.model)
        if not isinstance(state, dict):
            raise CheckpointError(f"{self.model}: not a state dict")
        check_finite(state, self.model)
        return state

    def read_knn_bank(self, width: int | None = None) -> KnnBank:
        """knn.pt, checked (`KnnBank`); `width`: F of the model's gate vectors, if known."""
        from sysid.runs.knn_bank import KnnBank  # torch: only when asked
        return KnnBank.load(self.knn, width)


_WRITER_NAMES = ("load_model", "save_model", "model_state", "run_summary", "write_run")


def __getattr__(name: str):
    """The writer's names, which lived here before (`sysid.runs.layout`): loaded on first use,
    so importing `RunDir` still loads no torch."""
    if name in _WRITER_NAMES:
        import importlib
        return getattr(importlib.import_module("sysid.runs.layout"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
