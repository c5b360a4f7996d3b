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
import math
import os
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from sysid.config.choices import TestLogs
from sysid.data.datasets import TEST_FILES, test_files, training_files
from sysid.data.recordings import Run, duplicate_runs, expand_paths, protocol_windows
from sysid.errors import ConfigError, DataError
from sysid.mmg.coverage import windows_touching

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
    test_source: TestLogs

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
        test, test_source = config_paths(d.test, "test", exp.source), TestLogs.FILES
    elif dataset:
        test, test_source = tuple(test_files(data).values()), TestLogs.PAPER
    else:
        test, test_source = (), TestLogs.NONE
    split = DataSplit(source, train, validation, test, test_source)
    check_disjoint_files(split, exp.source)
    return split


def check_disjoint_files(split: DataSplit, source: str = "") -> None:
    """`DataError` naming both files when one file is in two parts (training, validation,
    test) or twice in one, or two training or validation files have identical bytes.

    Test files are compared by path only, never opened: training and sweeps read no test
    file. Their samples are checked against the training logs when a run is evaluated
    (`check_disjoint_runs` in `sysid.runs.lifecycle.run_experiment`)."""
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
            if part == TEST:
                continue
            digest = file_sha256(path)
            if digest in digests:
                other, other_part = digests[digest]
                raise DataError(f"{where}{path} ({part}) and {other} ({other_part}) have identical content "
                                f"(SHA-256 {digest[:12]}...): the same log under two names; remove one")
            digests[digest] = (path, part)


def maneuver_group(run: Run) -> str:
    """The group a training log is held out within: the name of its folder (the paper's data
    sets: berthing, turning, zigzag, random)."""
    return run.path.parent.name


@dataclass(frozen=True)
class HeldOutFiles:
    """Training logs split into training and validation by whole files (``[training]
    validation = "files"``): the runs of each part, and per group the held-out names."""

    train: tuple[Run, ...]
    validation: tuple[Run, ...]
    groups: dict[str, list[str]]   # group -> names of its held-out logs (copies included)


def hold_out_files(runs: Sequence[Run], fraction: float, seed: int) -> HeldOutFiles:
    """Whole training logs held out as validation, stratified by `maneuver_group`.

    Of a group's n logs (an exact copy of the start of another log, `duplicate_runs`, is not
    counted: it follows its original), round(fraction n) are held out, at least 1 when n >= 2
    and at most n - 1, so no group is validation only; a group of one log stays training.
    Each group draws with its own generator, seeded by (`seed`, the group's name), from its
    logs sorted by name: the draw depends on neither the order of `runs` nor the other groups
    (D1 and D2 hold out the same berthing, turning and zigzag logs)."""
    original = {}
    for copy, of in duplicate_runs(list(runs)):
        original.setdefault(copy, of)

    def root(name: str) -> str:  # a copy of a copy follows the first original
        seen = set()
        while name in original and name not in seen:
            seen.add(name)
            name = original[name]
        return name

    members: dict[str, list[str]] = {}
    for run in runs:
        if root(run.name) == run.name:
            members.setdefault(maneuver_group(run), []).append(run.name)
    held: set[str] = set()
    for group, names in sorted(members.items()):
        names = sorted(names)
        if len(names) < 2:
            continue
        n_val = min(len(names) - 1, max(1, int(math.floor(fraction * len(names) + 0.5))))
        rng = np.random.default_rng([seed, zlib.crc32(group.encode())])
        held.update(names[i] for i in sorted(rng.choice(len(names), n_val, replace=False)))
    validation = tuple(r for r in runs if root(r.name) in held)
    groups: dict[str, list[str]] = {}
    for r in validation:
        groups.setdefault(maneuver_group(r), []).append(r.name)
    return HeldOutFiles(tuple(r for r in runs if root(r.name) not in held), validation,
                        {g: sorted(v) for g, v in sorted(groups.items())})


SHARED_ROWS = 30   # consecutive samples two logs of different parts may not have in common


def _row_keys(run: Run) -> np.ndarray:
    """One 64-bit key per sample of `run`: its states and inputs to 1e-6 (in their SI units),
    so a copy through another format or unit (rounding at 1e-12) keeps almost every key; (n,)."""
    values = np.nan_to_num(np.concatenate([run.states, run.inputs], axis=1), nan=1e300, posinf=1e300, neginf=-1e300)
    grid = np.round(np.clip(values, -1e12, 1e12) * 1e6).astype(np.int64).view(np.uint64)
    weights = np.random.default_rng(36).integers(1, 2 ** 63, size=grid.shape[1], dtype=np.uint64) | np.uint64(1)
    with np.errstate(over="ignore"):
        return (grid * weights).sum(axis=1, dtype=np.uint64)


def _window_keys(keys: np.ndarray, length: int) -> np.ndarray:
    """A key for each run of `length` consecutive samples (a polynomial hash of the sample
    keys, wrapping at 2^64); (n - length + 1,)."""
    powers = np.cumprod(np.full(length, 0x100000001B3, dtype=np.uint64), dtype=np.uint64)
    with np.errstate(over="ignore"):
        return np.lib.stride_tricks.sliding_window_view(keys, length) @ powers


def _samples(run: Run) -> np.ndarray:
    return np.concatenate([run.states, run.inputs], axis=1)


def shared_rows(a: Run, b: Run, length: int = SHARED_ROWS) -> tuple[int, int, int] | None:
    """Where `a` and `b` hold the same samples (states and inputs) in a run of at least
    `length` consecutive rows, or the whole of the shorter of the two: (first row of `a`,
    first row of `b`, rows in common, equal to 1e-9), or None. One log cut from another (rows
    300 on), a copy, a copy in another format or unit all share such a run; two recordings
    never do. Runs of `length` rows are matched by their hash (`_window_keys`), then compared."""
    n = min(len(a), len(b), length)
    if n < 1:
        return None
    keys_a, keys_b = _row_keys(a), _row_keys(b)
    _, at_a, at_b = np.intersect1d(_window_keys(keys_a, n), _window_keys(keys_b, n), return_indices=True)
    if not len(at_a):
        return None
    samples_a, samples_b = _samples(a), _samples(b)
    for i, j in zip(at_a, at_b):
        first_a, first_b = i - min(i, j), j - min(i, j)       # where this diagonal enters both logs
        rows = min(len(a) - first_a, len(b) - first_b)
        equal = np.isclose(samples_a[first_a:first_a + rows], samples_b[first_b:first_b + rows],
                           rtol=1e-9, atol=1e-9).all(axis=1)
        k = i - first_a                                      # the matched run's row on the diagonal
        if not equal[k:k + n].all():
            continue                                         # a hash collision
        breaks = np.flatnonzero(~equal)
        start = int(breaks[breaks < k].max() + 1) if (breaks < k).any() else 0
        stop = int(breaks[breaks >= k + n].min()) if (breaks >= k + n).any() else rows
        return int(first_a + start), int(first_b + start), int(stop - start)
    return None


def check_disjoint_runs(parts: dict[str, Sequence[Run]], source: str = "") -> None:
    """`DataError` naming both logs when a log of one part holds samples of a log of another
    part: the same recording under another name or format, or a piece cut from it (a run of
    `SHARED_ROWS` consecutive samples, or the whole shorter log, in common: `shared_rows`)."""
    where = f"{source}: " if source else ""
    named = [(part, run) for part, runs in parts.items() for run in runs]
    for k, (part_a, a) in enumerate(named):
        for part_b, b in named[k + 1:]:
            if part_a == part_b or a is b:
                continue
            found = shared_rows(a, b)
            if found is None:
                continue
            if part_a == TRAINING or (part_a == VALIDATION and part_b == TEST):  # name the held-out log first
                (part_a, a), (part_b, b), found = (part_b, b), (part_a, a), (found[1], found[0], found[2])
            i, j, n = found
            if n == len(a) == len(b):
                what = "the same samples as"
            elif n == len(a):
                what = f"the samples of rows {j + 1}-{j + n} of"
            else:
                what = f"in its rows {i + 1}-{i + n} the samples of rows {j + 1}-{j + n} of"
            raise DataError(f"{where}{a.path} ({part_a}) holds {what} {b.path} ({part_b}): the same recording "
                            "in two parts; remove one, or cut the logs so that no samples are shared")


def log_conditions(run: Run, astern: Callable[[Run], np.ndarray] | None, horizons: Sequence[float]) -> dict:
    """The conditions of one log a run records beside its file (`provenance`): the rudder
    check the user overrode, its samples outside a one-quadrant propeller (`astern`), and its
    protocol windows at `horizons` [s] holding one ({"30": windows, ...})."""
    out: dict = {}
    if run.track is not None and (rudder := run.track.rudder_overridden) is not None:
        out["rudder_sign_checked"] = round(float(rudder.correlation), 4)
    if astern is not None:
        flagged = astern(run)
        out["astern_samples"] = int(flagged.sum())
        if horizons:
            out["astern_windows"] = {f"{h:g}": int(windows_touching(flagged, protocol_windows(len(run), H), H).sum())
                                     for h in horizons if (H := int(round(h / run.dt)))}
    return out


def provenance(source: str, train: Sequence[Run], validation: Sequence[Run], test: Sequence[Run],
               val_fraction: float, block_s: float, held_out: HeldOutFiles | None = None,
               split_seed: int = 0, astern: Callable[[Run], np.ndarray] | None = None,
               horizons: Sequence[float] = ()) -> dict:
    """What a run was trained, validated and tested on, for summary.json: where the training
    data came from ("files", "D1", "D2", "-"), every log with its SHA-256, how validation
    was drawn and which test set it was ("files", "paper" or "none"). `held_out`: the
    validation logs were drawn from the training logs (``[training] validation = "files"``):
    ``held_out`` names them per group with the share and ``split_seed`` of the draw.
    Per log, when it applies: ``rudder_sign_checked``, the partial correlation of a rudder
    check the user overrode (``[data] rudder_sign_checked``); with `astern` (a one-quadrant
    propeller: (N,) True for a run's samples outside its quadrant) ``astern_samples``, and for
    a test log ``astern_windows``, its test windows at each of `horizons` [s] holding one."""
    def files(runs, windows: bool = False):
        return [{"file": str(r.path), "sha256": r.sha256 or file_sha256(r.path),
                 **log_conditions(r, astern, horizons if windows else ())} for r in runs]

    stems = {r.path.stem for r in test}
    validation_text = files(validation) if validation else (
        f"{val_fraction:g} of the {block_s:g}-s blocks of every training log, drawn with the seed"
        if train else "none")
    out = {"training": source, "train": files(train), "validation": validation_text,
           "test_set": (TestLogs.NONE if not test else TestLogs.PAPER if stems == PAPER_TEST_STEMS else TestLogs.FILES).value,
           "test": files(test, windows=True)}
    if held_out is not None:
        out["held_out"] = {"val_fraction": val_fraction, "split_seed": split_seed, "groups": held_out.groups}
    return out
