"""Stage 1 of training: windows of T+1 samples (T Euler steps) slid by ``stride_s`` within
each file, cut into training and validation so that no validation window overlaps a
training one, with the training samples and a `SplitReport`.

Each file's time axis is cut into ``block_s`` blocks, a seeded ``val_fraction`` of them
validation, and a window lies wholly in one part; or, given validation logs, every window of
those is validation and every window of the training logs training. Exact copies of another
file (``turn_cut_...``) and windows touching frozen-GNSS segments are left out and reported.
Each validation window keeps its log and start time (`WindowOrigins`): the verdict judges
validation per log.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch

from sysid.config.choices import Validation
from sysid.config.experiment import Experiment
from sysid.data.recordings import Run, duplicate_runs, sliding_windows, stack_windows, window_touches
from sysid.data.splits import HeldOutFiles, hold_out_files
from sysid.dynamics.rollouts import WindowOrigins, WindowSet
from sysid.mmg.coverage import astern_samples, one_quadrant_propeller, windows_touching
from sysid.errors import ConfigError, DataError


@dataclass
class SplitReport:
    """How the files were cut: per file its training/validation window counts and quality
    issues; files left out as copies of another; windows left out at frozen GNSS."""

    files: list[dict] = field(default_factory=list)
    dropped_copies: list[str] = field(default_factory=list)
    suspect_windows: int = 0
    astern_windows: int | None = None    # windows outside a one-quadrant propeller (None: four-quadrant)
    astern_excluded: bool | None = None  # those windows left out ([data] exclude_astern) or kept


def _block_parts(n: int, block: int, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    """(n,) True for samples in validation blocks: the run is cut into blocks of `block`
    samples and a `val_fraction` share of them, drawn at random, is held out."""
    n_blocks = max(2, math.ceil(n / max(block, 1)))
    n_val = min(n_blocks - 1, max(1, int(round(val_fraction * n_blocks))))
    val_blocks = np.zeros(n_blocks, dtype=bool)
    val_blocks[rng.choice(n_blocks, n_val, replace=False)] = True
    return np.repeat(val_blocks, math.ceil(n / n_blocks))[:n]


def objective_horizons(exp: Experiment) -> tuple[float, ...]:
    """The horizons [s] of ``val_loss_multistep``: ``[training] objective_s`` when set, else
    ``[evaluation] horizons``, the horizons the verdict judges on the test logs (one
    definition of good for validation, sweeps and the verdict)."""
    t = exp.training
    return (float(t.objective_s),) if t.objective_s > 0 else tuple(float(h) for h in exp.evaluation.horizons)


def held_out_validation(exp: Experiment, runs: Sequence[Run]) -> HeldOutFiles | None:
    """With ``[training] validation = "files"``: the training logs `runs` split into training
    and held-out validation logs (`sysid.data.splits.hold_out_files`, ``val_fraction`` of each
    folder's logs, drawn with ``split_seed``); else None."""
    t = exp.training
    return hold_out_files(runs, t.val_fraction, t.split_seed) if t.validation is Validation.FILES else None


def _validation_samples(run: Run, length: int, val_fraction: float, block_s: float, rng: np.random.Generator,
                        validation_runs: Sequence[Run]) -> np.ndarray:
    """(n,) True for the samples of `run` that are validation: all or none of a validation
    or training log, else the seeded validation blocks."""
    if validation_runs:
        return np.full(len(run), any(run is v for v in validation_runs))
    block = int(round(block_s / run.dt))
    if block < length:  # no window would lie wholly in one block: none in either part
        raise ConfigError(f"[training] block_s = {block_s:g} s: a validation block holds {block} of the "
                          f"data's {run.dt:g}-s samples, fewer than one {length}-sample training window; "
                          f"set block_s >= {length * run.dt:g} s (default 30)")
    return _block_parts(len(run), block, val_fraction, rng)


def _cut_run(run: Run, part_of: np.ndarray, length: int, stride: int, exclude_suspect: bool,
             report: SplitReport, astern: np.ndarray | None = None) -> tuple[dict[str, np.ndarray], int]:
    """(the first samples of the windows of `run` in each part ("train", "val"), the number of
    those windows holding a sample flagged in `astern` (N,), left out when
    ``report.astern_excluded``): a window lies wholly in one part, so no validation window
    overlaps a training one."""
    starts = sliding_windows(len(run), length, stride)
    ends = starts + length - 1
    cut, outside = {}, 0
    for part, flag in (("train", False), ("val", True)):
        inside = np.concatenate([[0], np.cumsum(part_of == flag)])
        mine = starts[inside[ends + 1] - inside[starts] == length]
        if exclude_suspect:
            bad = window_touches(run, mine, length)
            report.suspect_windows += int(bad.sum())
            mine = mine[~bad]
        if astern is not None:
            beyond = windows_touching(astern, mine, length)
            outside += int(beyond.sum())
            mine = mine[~beyond] if report.astern_excluded else mine
        cut[part] = mine
    return cut, outside


def _training_samples(run: Run, part_of: np.ndarray, exclude_suspect: bool, dtype, device,
                      astern: np.ndarray | None = None):
    """The training part's samples of `run`, (n, 6) states and (n, 4) inputs, without those
    within 1 s of a frozen-GNSS segment, nor those flagged in `astern` (N,) (None: none)."""
    keep = ~part_of
    for a, b in run.suspect if exclude_suspect else []:
        keep &= ~((run.t >= a - 1.0) & (run.t <= b + 1.0))
    if astern is not None:
        keep &= ~astern
    return (torch.as_tensor(run.states[keep], dtype=dtype, device=device),
            torch.as_tensor(run.inputs[keep], dtype=dtype, device=device))


@dataclass(frozen=True)
class AsternSamples:
    """The samples outside a one-quadrant propeller model (`sysid.mmg.coverage.astern_samples`:
    n_prop < 0 or u < 0) for the ship's component families `models`; `exclude`: windows
    holding one are left out of training and validation (``[data] exclude_astern``)."""

    models: tuple[tuple[str, str], ...]
    exclude: bool = True

    def of(self, run: Run) -> np.ndarray:
        """(N,) True for the samples of `run` outside the propeller model's quadrant."""
        return astern_samples(dict(self.models), run.states[:, 1], run.inputs[:, 0])


def astern_of(exp: Experiment, models: Mapping[str, str]) -> AsternSamples | None:
    """The `AsternSamples` of a ship with component families `models` under `exp`'s ``[data]
    exclude_astern``; None under a four-quadrant propeller (no sample is outside it)."""
    if not one_quadrant_propeller(models):
        return None
    return AsternSamples(tuple(sorted(models.items())), exp.data.exclude_astern)


def _file_entry(run: Run, cut: dict[str, np.ndarray], outside: int, flagged: np.ndarray | None,
                report: SplitReport) -> dict:
    """A training file's row of the `SplitReport`: its windows per part and data issues; under
    a one-quadrant propeller its windows and samples outside the propeller's quadrant (its
    windows added to the report's ``astern_windows``)."""
    entry = {"file": run.name, "train_windows": len(cut["train"]), "val_windows": len(cut["val"]),
             "issues": run.issues}
    if flagged is not None:
        entry["astern_windows"], entry["astern_samples"] = outside, int(flagged.sum())
        report.astern_windows = (report.astern_windows or 0) + outside
    return entry


@dataclass(frozen=True, eq=False)
class WindowCut:
    """Stage 1 cut: training and validation `WindowSet`s, the training samples (N, 6) states
    and (N, 4) inputs, the `SplitReport`, and where each validation window was cut."""

    train: WindowSet
    val: WindowSet
    samples: tuple[torch.Tensor, torch.Tensor]
    report: SplitReport
    val_origins: WindowOrigins


def split_windows(runs: Sequence[Run], steps: int, stride_s: float, val_fraction: float,
                  exclude_suspect: bool = True, dtype=torch.float64, block_s: float = 30.0, seed: int = 0,
                  device: str | torch.device = "cpu", validation_runs: Sequence[Run] = (),
                  astern: AsternSamples | None = None):
    """Training and validation `WindowSet`s, the training samples (N, 6)/(N, 4), and a
    `SplitReport` (`cut_windows` without the validation windows' origins)."""
    cut = cut_windows(runs, steps, stride_s, val_fraction, exclude_suspect, dtype, block_s, seed, device,
                      validation_runs, astern)
    return cut.train, cut.val, cut.samples, cut.report


def _check_names(runs: Sequence[Run]) -> None:
    """A `DataError` for a log given twice, or two logs of one name, among the training and
    validation logs: a log is named by its file name in the windows' origins."""
    named: dict[str, Run] = {}
    for run in runs:
        if run.name in named and named[run.name] is not run:
            other = named[run.name].path
            if Path(other).resolve() == Path(run.path).resolve():
                raise DataError(f"{run.path}: given twice among the training and validation logs (a log validates "
                                "only what it did not train): keep it in one list")
            raise DataError(f"{run.path}: the same name as {other} among the training and validation logs; sysid "
                            f"names a log by its file name ({run.name!r}): rename one of them")
        named[run.name] = run


def cut_windows(runs: Sequence[Run], steps: int, stride_s: float, val_fraction: float,
                exclude_suspect: bool = True, dtype=torch.float64, block_s: float = 30.0, seed: int = 0,
                device: str | torch.device = "cpu", validation_runs: Sequence[Run] = (),
                astern: AsternSamples | None = None) -> WindowCut:
    """The `WindowCut` of `runs` into windows of `steps` + 1 samples slid by `stride_s` [s].

    Each file is cut into blocks of `block_s`; a random `val_fraction` of the blocks (seeded)
    is validation. Windows lie wholly inside one part, so none overlaps across the split.
    Given `validation_runs`, those are validation whole and `runs` training whole. The
    windows follow the files' order, each file's in time order. Two logs of one name are a
    `DataError`: the validation windows' origins name their log by it. With `astern` (a
    one-quadrant propeller), windows holding a sample outside its quadrant are counted per
    file and, when it excludes them, left out with those samples.
    """
    rng = np.random.default_rng(seed)
    report = SplitReport(astern_windows=None if astern is None else 0,
                         astern_excluded=None if astern is None else astern.exclude)
    validation_runs = list(validation_runs)
    _check_names(list(runs) + validation_runs)
    copies = {copy for copy, _ in duplicate_runs(list(runs) + validation_runs)}
    parts: dict[str, list] = {"train": [], "val": []}
    samples: tuple[list, list] = ([], [])
    val_logs: list[str] = []
    val_starts: list[np.ndarray] = []
    dt = None
    length = steps + 1
    for run in list(runs) + validation_runs:
        if run.name in copies:
            report.dropped_copies.append(run.name)
            continue
        dt = run.dt if dt is None else dt
        if abs(run.dt - dt) > 1e-9:
            raise DataError(f"{run.path}: sample period {run.dt} s differs from {dt} s")
        part_of = _validation_samples(run, length, val_fraction, block_s, rng, validation_runs)
        flagged = astern.of(run) if astern is not None else None
        cut, outside = _cut_run(run, part_of, length, max(1, int(round(stride_s / run.dt))), exclude_suspect,
                                report, flagged)
        for part, mine in cut.items():
            if len(mine):
                parts[part].append(stack_windows(run, mine, length, dtype, device))
        val_logs += [run.name] * len(cut["val"])
        val_starts.append(run.t[cut["val"]])
        dropped = flagged if report.astern_excluded else None
        for kept, sample in zip(samples, _training_samples(run, part_of, exclude_suspect, dtype, device, dropped)):
            kept.append(sample)
        report.files.append(_file_entry(run, cut, outside, flagged, report))
    if not parts["train"]:
        raise DataError("no training windows: the files are shorter than one window")
    if not parts["val"]:
        raise DataError("no validation windows: the validation logs are shorter than one window"
                        if validation_runs else "no validation windows: the files are too short for the 70/30 split")
    return WindowCut(_window_set(parts["train"], dt), _window_set(parts["val"], dt),
                     (torch.cat(samples[0]), torch.cat(samples[1])), report,
                     WindowOrigins(tuple(val_logs), np.concatenate(val_starts)))


def _window_set(chunks: list, dt) -> WindowSet:
    """One `WindowSet` of the (states, inputs) windows of several files, (length, W, .) each."""
    return WindowSet(torch.cat([c[0] for c in chunks], 1), torch.cat([c[1] for c in chunks], 1), dt)
