"""`run_sweep`: a sweep file to trained trials and a results table, resumable.

Output directory::

    manifest.json     written when the sweep starts: sweep.toml and base.toml (kind "sweep")
    sweep.toml        the sweep file as given (a resumed sweep must match it)
    base.toml         the base experiment, every option resolved
    trials/{point}/seed{k}/   one ordinary run directory per trial (`sysid.runs.layout`)
    trials.log        journal: one JSON line per trial event (started, resumed, trained, reused)
    results.csv       one row per trial: varied values, seed, status, validation loss, epochs
    points.csv        one row per configuration: validation loss over its seeds
    sweep.json        counts, the chosen configuration and its runs, where Tune's experiment is
    tune/             Ray Tune's experiment (unless --storage puts it elsewhere):
                      tune.ExperimentAnalysis reads every trial's per-epoch validation loss

Order of work: everything is checked (sweep file, data, output path, Ray's address) and the
data are read before anything is written; a sweep that fails before its first trial
starts leaves no output behind.
"""
from __future__ import annotations

import math
import os
import shutil
import time
import tomllib
from pathlib import Path
from typing import Callable

from sysid.config.choices import Search
from sysid.errors import ConfigError, OutputError
from sysid.config.experiment import parse_experiment
from sysid.store.files import write_text
from sysid.store.manifest import write_manifest
from sysid.store.staging import check_target
from sysid.sweep.inbox import JOURNAL, complete_summary
from sysid.sweep.plan import make_trial, sweep_trials
from sysid.sweep.results import SweepResults, collect_results, scanned_trials, write_results
from sysid.sweep.summary import SweepSummary
from sysid.sweep.runner import Outcomes, TuneStorage, make_scheduler, ray_session, run_optuna, run_trials
from sysid.sweep.runner import tune_storage as tune_storage_of
from sysid.sweep.spec import SweepSpec
from sysid.sweep.trial import TrialSpec, group_name, read_trial_data, seed_groups

MARKER = "sweep.toml"

SWEEP_KIND = "sweep"  # the kind in the sweep directory's manifest


def check_output(spec: SweepSpec, out: Path, resume: bool, overwrite: bool) -> None:
    """Refuse to mix sweeps (nothing written): an existing output is continued only with
    `resume` (and the same sweep file) or replaced with `overwrite` (only if sysid sealed it
    as a sweep, and it holds none of the sweep's inputs)."""
    marker = out / MARKER
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a directory; choose another output path")
    if resume:
        if not marker.is_file():
            raise OutputError(f"{out}: no sweep to resume here (no {MARKER}); start it without --resume")
        if marker.read_text() != spec.text:
            raise ConfigError(f"{spec.source}: differs from {marker}, the sweep file this sweep was started "
                              "with; resume with that file, or start a new sweep in another directory")
        return
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise OutputError(f"{out}: already exists; pass --resume to continue that sweep, --overwrite to "
                              "replace it, or choose another output path")
        check_target(out, overwrite, [spec.source, spec.base_path], SWEEP_KIND)


def write_output(spec: SweepSpec, out: Path, resume: bool) -> None:
    """Start the output directory (a replaced sweep's files go first)."""
    if resume:
        return
    if out.is_dir() and any(out.iterdir()):
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(spec.base.to_toml(), out / "base.toml")
    write_text(spec.text, out / MARKER)
    write_manifest(out, SWEEP_KIND)  # sealed as soon as it is made: sysid's from then on


def recorded_tune(storage: TuneStorage, out: Path) -> str:
    """Where Tune's experiment is, as sweep.json records it: relative to the sweep directory
    `out` when inside it (``tune``: found again after the sweep folder is moved), else its
    absolute path or URI."""
    experiment = Path(storage.experiment)
    if "://" in storage.storage_path or not experiment.resolve().is_relative_to(out.resolve()):
        return storage.experiment
    return experiment.resolve().relative_to(out.resolve()).as_posix()


def _remove_unstarted(out: Path, existed: bool) -> None:
    """After a failure before the first trial: remove what this sweep wrote."""
    if (out / JOURNAL).exists() or not out.is_dir():
        return
    shutil.rmtree(out, ignore_errors=True)
    if existed:
        out.mkdir(exist_ok=True)  # the empty folder the user gave


def optuna_history(spec: SweepSpec, out: Path) -> tuple[list[tuple[dict, float]], list[dict]]:
    """What an Optuna sweep finished, from sysid's verified run directories (Tune's pickled
    search state is never read): (Tune config, mean validation loss) of the configurations
    with every seed complete, and the configurations with seeds left."""
    from sysid.sweep.optuna_space import config_of

    by_point: dict[str, list[TrialSpec]] = {}
    for trial in scanned_trials(spec, out):
        by_point.setdefault(trial.point, []).append(trial)
    evaluated, pending = [], []
    for trials in by_point.values():
        config = config_of(spec, trials[0].values)
        if config is None:
            continue
        summaries = [complete_summary(out / t.path) for t in trials]
        losses = [s.objective if s is not None else math.nan for s in summaries]
        if set(spec.seeds) <= {t.seed for t in trials} and all(math.isfinite(v) for v in losses):
            evaluated.append((config, sum(losses) / len(losses)))
        else:
            pending.append(config)
    return evaluated, pending


def needs_paper_data(spec: SweepSpec, experiments) -> bool:
    """Whether the sweep names the paper's data set D1/D2 (``[experiment] dataset`` in the
    base, a planned trial, or an axis)."""
    if any(a.key == "experiment.dataset" for a in spec.axes):
        return True
    return any(e.experiment.dataset for e in experiments)


def sweep_inputs(spec: SweepSpec, experiments, root) -> list[Path]:
    """What a sweep reads: its sweep file, base config, every log of its configurations and
    the folders holding those logs (no output goes there)."""
    from sysid.data.splits import data_split

    paths = [Path(spec.source), spec.base_path]
    for exp in experiments:
        for files in data_split(exp, root).parts().values():
            paths += [Path(f) for f in files] + [Path(f).parent for f in files]
    return list(dict.fromkeys(paths))


def _seed_dirs(spec: SweepSpec, values: dict) -> dict[str, str]:
    return {f"seed{s}": make_trial(spec, values, s).path for s in spec.seeds}


def _experiments(spec: SweepSpec, trials: list[TrialSpec]):
    return [spec.base] + [parse_experiment(tomllib.loads(t.config), spec.source) for t in trials]


def run_sweep(spec: SweepSpec, out: str | os.PathLike, workers: int | None = None, address: str | None = None,
              resume: bool = False, overwrite: bool = False, data: str | os.PathLike | None = None,
              log: Callable[[str], None] = print, storage: str | None = None,
              mlflow: str | None = None) -> tuple[SweepResults, SweepSummary]:
    """Train every trial of `spec` (on Ray) into `out`; returns the results and summary.

    `address` joins a Ray cluster (default: ``RAY_ADDRESS``, else a local Ray of the
    sweep's own); `storage` puts Tune's experiment there (a path or URI) instead of
    ``{out}/tune``; `mlflow` (or the sweep file's ``[tracking] mlflow``) logs the sweep."""
    from sysid.data.datasets import data_root
    from sysid.sweep.optuna_space import point_of, values_of

    started = time.perf_counter()
    out = Path(out)
    check_output(spec, out, resume, overwrite)
    planned = sweep_trials(spec) if spec.search is not Search.OPTUNA else []
    experiments = _experiments(spec, planned)
    # the paper's data set only when a configuration names one (a clear error before Ray starts)
    root = data_root(data) if needs_paper_data(spec, experiments) else None
    trial_data = read_trial_data(experiments, root)
    tracker = None
    if mlflow or spec.mlflow:
        from sysid.experiment_tracking import Tracker
        tracker = Tracker(mlflow or spec.mlflow, spec.name)
    tune_storage = (tune_storage_of(storage, spec.name, out, sweep_inputs(spec, experiments, root)) if storage
                    else TuneStorage(str(out.resolve())))
    scheduler = make_scheduler(spec.scheduler, spec.most_epochs * (len(spec.seeds) if spec.search is Search.OPTUNA else 1))
    existed = out.is_dir()
    where = f" on {address}" if address else (f" on {os.environ['RAY_ADDRESS']}" if os.environ.get("RAY_ADDRESS") else "")
    evaluated, pending = optuna_history(spec, out) if spec.search is Search.OPTUNA and resume else ([], [])
    if spec.search is Search.OPTUNA and resume:
        log(f"sweep {spec.name}: optuna resumes from {len(evaluated)} finished configurations "
            f"({len(pending)} with seeds left) in {out / 'trials'}; Tune's saved search state is not read")
    parent, outcomes = None, Outcomes()

    def lost_note() -> str:
        if (out / JOURNAL).exists():
            return f"the trials finished so far are kept in {out / 'trials'}: rerun with --resume on a running cluster"
        return "nothing was written"

    def lost_cleanup() -> None:
        if not resume:
            _remove_unstarted(out, existed)
    try:
        if spec.search is Search.OPTUNA:
            log(f"sweep {spec.name}: optuna, {spec.samples} configurations x {len(spec.seeds)} seeds{where}")
            if len(evaluated) < spec.samples:
                with ray_session(out, workers, address, log, lost_note, lost_cleanup) as session:
                    write_output(spec, out, resume)
                    callbacks = []
                    if tracker is not None:
                        callbacks, parent = _tracking(tracker, spec, out, lambda c: point_of(spec, c),
                                                      lambda c: values_of(spec, c),
                                                      lambda c: _seed_dirs(spec, values_of(spec, c)), log)
                    outcomes = run_optuna(spec, out, trial_data, session, tune_storage, scheduler, callbacks,
                                          evaluated, pending, log)
            found = {t.path: t for t in scanned_trials(spec, out)}
            for config in outcomes.configs:  # trials Tune ended without a run (stopped, failed)
                for seed in spec.seeds:
                    trial = make_trial(spec, values_of(spec, config), seed)
                    found.setdefault(trial.path, trial)
            trials = sorted(found.values(), key=lambda t: t.path)
        else:
            trials = planned
            log(f"sweep {spec.name}: {spec.search}, {len(trials) // len(spec.seeds)} configurations x "
                f"{len(spec.seeds)} seeds = {len(trials)} trials{where}"
                + (f", scheduler {spec.scheduler.kind}" if spec.scheduler.kind != "none" else ""))
            # a scheduler compares trials epoch by epoch: seeds stay one trial each under one
            groups = seed_groups(trials, trial_data, log) if scheduler is None else None
            if scheduler is not None and len(spec.seeds) > 1:
                log(f"sweep {spec.name}: seeds one trial each (scheduler {spec.scheduler.kind} compares trials "
                    "epoch by epoch)")
            members = {g[0]: [trials[i] for i in g] for g in groups or [[i] for i in range(len(trials))]}
            with ray_session(out, workers, address, log, lost_note, lost_cleanup) as session:
                write_output(spec, out, resume)
                callbacks = []
                if tracker is not None:
                    callbacks, parent = _tracking(tracker, spec, out, lambda c: group_name(members[int(c["trial"])]),
                                                  lambda c: {**trials[int(c["trial"])].values,
                                                             "seed": ", ".join(str(t.seed)
                                                                               for t in members[int(c["trial"])])},
                                                  lambda c: {("run" if len(members[int(c["trial"])]) == 1
                                                              else f"seed{t.seed}"): t.path
                                                             for t in members[int(c["trial"])]}, log)
                outcomes = run_trials(trials, out, trial_data, session, spec.max_retries, tune_storage, scheduler,
                                      callbacks, log, groups=groups)
    except BaseException:
        if not resume:
            _remove_unstarted(out, existed)
        raise
    results = collect_results(spec, out, trials, outcomes)
    summary = write_results(spec, out, results, time.perf_counter() - started,
                            tune=recorded_tune(tune_storage, out), mlflow=tracker.uri if tracker else None)
    if tracker is not None and parent is not None:  # the sweep's own run: counts, best, the results table
        tracker.metrics(parent, {"complete": summary.complete, "failed": summary.failed,
                                 "stopped_early": summary.stopped_early}
                        | ({"best_val_loss": summary.best.val_loss_multistep_mean} if summary.best else {}))
        tracker.client.log_artifact(parent, str(out / "results.csv"))
        tracker.finish(parent)
    return results, summary


def _tracking(tracker, spec: SweepSpec, out: Path, names, params, run_dirs, log):
    """The sweep's MLflow run and the callback logging its trials as child runs."""
    from sysid.sweep.tracked import tracking_callback

    parent = tracker.start(spec.name, {"search": spec.search, "samples": spec.samples, "seeds": list(spec.seeds),
                                       "scheduler": spec.scheduler.kind, "base": str(spec.base_path),
                                       "output": str(out.resolve()), **spec.scheduler.as_dict()},
                           tags={"sysid.kind": "sweep"})
    return [tracking_callback(tracker, parent, out.resolve(), names, params, run_dirs, log)], parent
