"""The logs a run directory was made from: how it records their paths, and how it finds
them again after the project folder or the run is moved or copied.

A run records every log of ``[data] train``, ``validation`` and ``test`` relative to the run
directory itself, the folder its config.toml is in (``../../logs/turn.csv`` for the run
``runs/first`` of a project with ``logs/``): config.toml names them so, as any config names
its logs relative to its own folder, and summary.json ``data`` keeps beside each one the
absolute path it had when the run was made (``file``) and the SHA-256 of its bytes
(`sysid.records.summary.LogFile`). A log that shares no folder with the run but the file
system's root (a run written with ``-o /scratch/...`` from a project in ``/work``) has no
relative form: config.toml names it by its absolute path. A run written before (absolute
paths, no ``relative``) reads as it always did.

Where a log is looked for, in this order: relative to the run directory (a project moved
or copied with its runs, or a run outside its project moved together with it, keeping
their places to each other, uses the logs beside it, even edited: warned), then the
absolute path it had when the run was made (a run moved or copied alone). A project moved
while the run stays elsewhere cannot be followed: the run says so in one line with the fixes
(its project's config where it is now, ``--config``, or ``--data``).

`found_again` gives the config's files where they are now (nothing opened), `checked`
the logs a command is about to read: a missing one is a `DataError` naming the run, the
file and the fix, an edited one (other bytes than the run recorded) one warning line.
The paper's data sets (D1/D2, found through ``--data``) are not recorded here.
"""
from __future__ import annotations

import glob
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from sysid.errors import DataError
from sysid.records.summary import DataSummary, LogFile
from sysid.store.manifest import sha256_of

PARTS = ("train", "validation", "test")   # the [data] lists that name logs


def relative_to(path: str | os.PathLike, home: str | os.PathLike) -> str | None:
    """`path` (made absolute) relative to the directory `home` with its links resolved, as
    a config names it (`load_experiment` anchors relative paths at the config's resolved
    folder), with ``/`` separators; None when it has no relative form worth keeping: another
    drive, or no folder in common but the file system's root (``../../../work/tanker/...``
    from a run in ``/scratch``: no move keeps that path, the absolute one says it plainly)."""
    path, home = os.path.abspath(path), str(Path(home).resolve())
    try:
        common = os.path.commonpath([path, home])
    except ValueError:
        return None
    if common == Path(common).anchor:
        return None
    return Path(os.path.relpath(path, home)).as_posix()


def portable_provenance(data: dict, home: str | os.PathLike) -> dict:
    """The logs of `data` (`sysid.data.splits.provenance`) with ``relative`` (to `home`,
    the run directory where it will live) beside each ``file``, made absolute. Logs of
    the paper's data sets (training on "D1" / "D2", its six test logs) keep their record
    as it is: they are found through ``--data``, not through the run."""
    def recorded(entry: dict) -> dict:
        absolute = os.path.abspath(entry["file"])
        relative = relative_to(absolute, home)
        return {**entry, "file": absolute, **({"relative": relative} if relative is not None else {})}

    out = dict(data)
    for part in PARTS:
        own = data.get("test_set") == "files" if part == "test" else data.get("training") == "files"
        if isinstance(out.get(part), list) and own:
            out[part] = [recorded(entry) for entry in out[part]]
    return out


@dataclass(frozen=True)
class RecordedLog:
    """A log as a run recorded it. path : where the run's config names it (anchored at the
    run directory); hint : its absolute path when the run was made (None: the same, or not
    recorded); sha256 : of its bytes then (None: not recorded)."""

    path: Path
    hint: Path | None = None
    sha256: str | None = None

    def candidates(self) -> list[Path]:
        return [self.path] + ([self.hint] if self.hint is not None and self.hint != self.path else [])

    def found(self) -> Path | None:
        """Where the log is now: the config's path, else the hint; None: at neither."""
        return next((p for p in self.candidates() if p.is_file()), None)

    def checked(self, run: Path, part: str) -> Path:
        """The log to read (`found`): `DataError` when it is at neither place, one warning
        line when its bytes are not those the run recorded (it was edited)."""
        path = self.found()
        if path is None:
            where = f" (nor at {self.hint}, where it was when the run was made)" if len(self.candidates()) > 1 else ""
            raise DataError(f"{run}: its {_PART_NAMES[part]} log {self.path} is missing{where}: move it back, "
                            f"give the config of its project where it is now (--config DIR/experiment.toml), or "
                            f"name the logs to use with --data DIR")
        if self.sha256 is not None and sha256_of(path) != self.sha256:
            logging.getLogger(__name__).warning(
                f"{path} differs from the {_PART_NAMES[part]} log the run {run} was made with (its SHA-256 in "
                f"summary.json): the results are of the edited file (to reproduce the run's, put the original back)")
        return path


_PART_NAMES = {"train": "training", "validation": "validation", "test": "test"}


def _records(data: DataSummary | None) -> list[LogFile]:
    if data is None:
        return []
    return [*data.train, *data.validation_logs, *data.test]


def recorded_logs(config: Iterable[str], data: DataSummary | None, run: Path) -> list[RecordedLog]:
    """The logs a run's config lists (`config`: one [data] list, anchored at the run
    directory `run`), each with its hint and SHA-256 from summary.json ``data``: matched by
    ``relative`` (anchored at `run`), or in a run written before, by ``file``."""
    by_path: dict[str, LogFile] = {}
    for record in _records(data):
        if record.relative is not None:
            by_path.setdefault(os.path.normpath(os.path.join(run.resolve(), record.relative)), record)
        if record.file is not None:
            by_path.setdefault(os.path.normpath(record.file), record)
    out = []
    for item in config:
        record = by_path.get(os.path.normpath(item))
        hint = Path(record.file) if record is not None and record.file is not None else None
        out.append(RecordedLog(Path(item), hint, record.sha256 if record is not None else None))
    return out


def found_again(config: tuple[str, ...], data: DataSummary | None, run: Path) -> tuple[str, ...]:
    """A run's [data] list with each log where it is now (`RecordedLog.found`; one at
    neither place, a pattern or a folder stays as the config names it)."""
    out = []
    for item, log in zip(config, recorded_logs(config, data, run)):
        now = None if glob.has_magic(item) else log.found()
        out.append(str(now) if now is not None else item)
    return tuple(out)


def checked(config: tuple[str, ...], data: DataSummary | None, run: Path, part: str) -> list[Path]:
    """The files of a run's [data] `part` list a command reads (`RecordedLog.checked`;
    patterns and folders, of runs written before their logs were listed, as they match)."""
    from sysid.data.recordings import expand_paths   # numpy, pandas: only when logs are read

    out: list[Path] = []
    for item, log in zip(config, recorded_logs(config, data, run)):
        if glob.has_magic(item) or Path(item).is_dir():
            out += expand_paths([item])
        else:
            out.append(log.checked(run, part))
    return out
