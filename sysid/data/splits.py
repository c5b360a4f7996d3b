"""Which logs an experiment trains, validates and tests on, and the check that no log is in
two of them.

The training data are the config's ``[data] train`` logs or the paper's data set
(``[experiment] dataset = "D1" | "D2"``); validation is ``[data] validation`` (whole logs)
or blocks of the training logs; the test set is ``[data] test``, else the paper's six test
files when the config names a paper data set, else there is none. A log in two of the sets
(the same file, a file with identical bytes, or the same samples) is an error naming both.
"""
from __future__ import annotations

import glob
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from sysid.data.datasets import TEST_FILES, test_files, training_files
from sysid.data.recordings import Run, duplicate_runs, expand_paths
from sysid.errors import ConfigError, DataError

TRAINING, VALIDATION, TEST = "training", "validation", "test"
PAPER_TEST_STEMS = frozenset(Path(f).stem for f in TEST_FILES.values())


@dataclass(frozen=True)
class DataSplit:
    """The files of each part. source : "files" (the config's logs) or "D1"/"D2" (the
    paper's); test_source : "files", "paper" (the paper's six test files) or "none"."""

    source: str
    train: tuple[Path, ...]
    validation: tuple[Path, ...]
    test: tuple[Path, ...]
    test_source: str

    def parts(self) -> dict[str, tuple[Path, ...]]:
        return {TRAINING: self.train, VALIDATION: self.validation, TEST: self.test}


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def config_paths(items: Sequence[str], key: str, source: str) -> tuple[Path, ...]:
    """`expand_paths` of a config's ``[data] key`` list; a missing file is named with the key
    and the config whose folder it was resolved against."""
    for item in items:
        if not glob.has_magic(str(item)) and not Path(item).exists():
            raise DataError(f"{item}: file not found ([data] {key} in {source or 'the config'}; relative "
                            "paths are relative to the config file's folder)")
    return tuple(expand_paths(items))


def data_split(exp, data: str | os.PathLike | None = None) -> DataSplit:
    """The experiment's files (globs and directories expanded; paths in the config are
    already absolute, `sysid.config.experiment.load_experiment`), checked to be disjoint.
    `data` is the FRT-DS-ESSO root for the paper's data sets."""
    d = exp.data
    dataset = exp.experiment.dataset
    if d.train:
        source, train = "files", config_paths(d.train, "train", exp.source)
    elif dataset and exp.needs_training:
        source, train = dataset, tuple(training_files(dataset, data))
    elif exp.needs_training:
        raise ConfigError(f"{exp.source or 'experiment'}: no training data: list your logs in [data] train "
                          "(paths relative to the config), or set [experiment] dataset = \"D1\" or \"D2\" "
                          "for the paper's")
    else:
        source, train = ("-", ())
    validation = config_paths(d.validation, "validation", exp.source)
    if d.test:
        test, test_source = config_paths(d.test, "test", exp.source), "files"
    elif dataset:
        test, test_source = tuple(test_files(data).values()), "paper"
    else:
        test, test_source = (), "none"
    split = DataSplit(source, train, validation, test, test_source)
    check_disjoint_files(split, exp.source)
    return split


def check_disjoint_files(split: DataSplit, source: str = "") -> None:
    """`DataError` naming both files when one file, or two files with identical bytes, are
    in two parts (training, validation, test) or twice in one."""
    where = f"{source}: " if source else ""
    seen: dict[Path, str] = {}
    digests: dict[str, tuple[Path, str]] = {}
    for part, files in split.parts().items():
        for path in files:
            real = Path(path).resolve()
            if real in seen:
                raise DataError(f"{where}{path} is listed in {seen[real]} and in {part}: a log may be in one "
                                "part only (remove it from one of the lists)")
            seen[real] = part
            digest = file_sha256(path)
            if digest in digests:
                other, other_part = digests[digest]
                raise DataError(f"{where}{path} ({part}) and {other} ({other_part}) have identical content "
                                f"(SHA-256 {digest[:12]}...): the same log under two names; remove one")
            digests[digest] = (path, part)


def check_disjoint_runs(parts: dict[str, Sequence[Run]], source: str = "") -> None:
    """`DataError` naming both logs when the samples of a log of one part are those (or the
    start) of a log of another part: the same recording under another name or format."""
    where = f"{source}: " if source else ""
    part_of = {id(run): part for part, runs in parts.items() for run in runs}
    runs = [run for group in parts.values() for run in group]
    by_name = {}
    for run in runs:
        by_name.setdefault(run.name, []).append(run)
    for copy, original in duplicate_runs(runs):
        for a in by_name[copy]:
            for b in by_name[original]:
                if a is not b and part_of[id(a)] != part_of[id(b)]:
                    raise DataError(f"{where}{a.path} ({part_of[id(a)]}) holds the same samples as {b.path} "
                                    f"({part_of[id(b)]}): the same recording in two parts; remove one")


def provenance(source: str, train: Sequence[Run], validation: Sequence[Run], test: Sequence[Run],
               val_fraction: float, block_s: float) -> dict:
    """What a run was trained, validated and tested on, for summary.json: where the training
    data came from ("files", "D1", "D2", "-"), every log with its SHA-256, how validation
    was drawn and which test set it was ("files", "paper" or "none")."""
    def files(runs):
        return [{"file": str(r.path), "sha256": file_sha256(r.path)} for r in runs]

    stems = {r.path.stem for r in test}
    validation_text = files(validation) if validation else (
        f"{val_fraction:g} of the {block_s:g}-s blocks of every training log, drawn with the seed"
        if train else "none")
    return {"training": source, "train": files(train), "validation": validation_text,
            "test_set": "none" if not test else ("paper" if stems == PAPER_TEST_STEMS else "files"),
            "test": files(test)}
