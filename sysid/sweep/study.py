"""`run_sweep`: a sweep file to trained trials and a results table, resumable.

Output directory::

    manifest.json     written when the sweep starts: sweep.toml and base.toml (kind "sweep")
    sweep.toml        the sweep file as given (a resumed sweep must match it)
    base.toml         the base experiment, every option resolved
    trials/{point}/seed{k}/   one ordinary run directory per trial (`sysid.runs.rundir`)
    trials.log        journal: one JSON line per trial event (started, resumed, trained, reused)
    results.csv       one row per trial: varied values, seed, status, validation loss, epochs
    points.csv        one row per configuration: validation loss over its seeds
    summary.json      counts, the chosen configuration and its runs
    .ray/             Ray Tune's experiment state
"""
from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Callable

from sysid.config.choices import Search
from sysid.errors import ConfigError, OutputError
from sysid.store.files import write_text
from sysid.store.manifest import write_manifest
from sysid.store.staging import check_target
from sysid.sweep.plan import sweep_trials
from sysid.sweep.results import SweepResults, collect_results, scanned_trials, write_results
from sysid.sweep.summary import SweepSummary
from sysid.sweep.runner import default_workers, run_optuna, run_trials
from sysid.sweep.spec import SweepSpec
from sysid.sweep.trial import TrialContext

SWEEP_KIND = "sweep"  # the kind in the sweep directory's manifest


def prepare_output(spec: SweepSpec, out: Path, resume: bool, overwrite: bool) -> None:
    """Refuse to mix sweeps: an existing output is continued only with `resume` (and the same
    sweep file) or replaced with `overwrite` (only if sysid sealed it as a sweep). A new sweep
    directory is sealed (``manifest.json`` of kind "sweep", listing its sweep and base files)
    as soon as it is made: it is sysid's from then on."""
    marker = out / "sweep.toml"
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a directory; choose another output path")
    if resume:
        if not marker.is_file():
            raise OutputError(f"{out}: no sweep to resume here (no sweep.toml); start it without --resume")
        if marker.read_text() != spec.text:
            raise ConfigError(f"{spec.source}: differs from {marker}, the sweep file this sweep was started "
                              "with; resume with that file, or start a new sweep in another directory")
        return
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise OutputError(f"{out}: already exists; pass --resume to continue that sweep, --overwrite to "
                              "replace it, or choose another output path")
        check_target(out, overwrite, [spec.source, spec.base_path], SWEEP_KIND)
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(spec.base.to_toml(), out / "base.toml")
    write_text(spec.text, marker)
    write_manifest(out, SWEEP_KIND)


def run_sweep(spec: SweepSpec, out: str | os.PathLike, workers: int | None = None, address: str | None = None,
              resume: bool = False, overwrite: bool = False, data: str | os.PathLike | None = None,
              log: Callable[[str], None] = print) -> tuple[SweepResults, SweepSummary]:
    """Train every trial of `spec` (on Ray) into `out`; returns the results and summary."""
    from sysid.data.datasets import data_root

    started = time.perf_counter()
    out = Path(out)
    data = str(data_root(data))  # a clear error before Ray starts when the data are missing
    prepare_output(spec, out, resume, overwrite)
    workers = workers or default_workers()
    context = TrialContext(str(out.resolve()), data, spec.source)
    if spec.search is Search.OPTUNA:
        log(f"sweep {spec.name}: optuna, {spec.samples} configurations x {len(spec.seeds)} seeds, "
            f"{workers} workers" + (f" on {address}" if address else ""))
        errors = run_optuna(spec, context, workers, address, resume=resume, log=log)
        trials = scanned_trials(spec, out)
    else:
        trials = sweep_trials(spec)
        log(f"sweep {spec.name}: {spec.search}, {len(trials) // len(spec.seeds)} configurations x "
            f"{len(spec.seeds)} seeds = {len(trials)} trials, {workers} workers" + (f" on {address}" if address else ""))
        errors = run_trials(trials, context, workers, address, spec.max_retries, log=log)
    results = collect_results(spec, out, trials, errors)
    summary = write_results(spec, out, results, time.perf_counter() - started)
    return results, summary
