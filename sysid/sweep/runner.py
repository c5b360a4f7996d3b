"""Trials on Ray Tune: locally (Ray started in-process, one trial per core, one torch thread
per trial) or on an existing cluster (``address``), with retries of crashed or killed trials
and a progress line per event (done / running / failed, best validation loss so far).

Resuming needs nothing from Ray's own state for grid and random sweeps: a trial whose run
directory is complete is not trained again, an interrupted one continues from its
checkpoint (`sysid.sweep.trial`). Optuna's search state is restored from Ray's.
"""
from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Callable

from sysid.errors import ConfigError
from sysid.sweep.trial import TrialContext, TrialSpec, tune_trainable
from sysid.sweep.trial_lock import remove_locks

RAY_DIR = ".ray"   # Ray Tune's experiment state, inside the sweep's output directory
INSTALL_HINT = "Ray is needed for sweeps and seed studies: pip install \"sysid[sweep]\" (ray[tune], optuna)"


def import_ray():
    """Ray and Ray Tune, quiet, or a clear error when they are not installed."""
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    os.environ.setdefault("TUNE_DISABLE_AUTO_CALLBACK_LOGGERS", "1")
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    os.environ.setdefault("TUNE_WARN_EXCESSIVE_EXPERIMENT_CHECKPOINT_SYNC_THRESHOLD_S", "600")
    try:
        import ray
        from ray import tune
    except ImportError:
        raise ConfigError(INSTALL_HINT) from None
    return ray, tune


def start_ray(workers: int, address: str | None) -> bool:
    """Connect to `address` or start a local Ray with `workers` CPUs; True if started here."""
    ray, _ = import_ray()
    # trial failures are reported by the progress lines and the results table, not tracebacks
    for name in ("ray.tune", "ray.air", "ray.train"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if ray.is_initialized():
        return False
    if address:
        ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR)
    else:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR,
                 object_store_memory=200 * 1024**2, configure_logging=True)
    return True


def progress_callback(total: int, names: Callable[[dict], str], log: Callable[[str], None], prefix: str = "sweep"):
    """A Tune callback printing one line per trial event: counts and the best so far."""
    _, tune = import_ray()

    class SweepProgress(tune.Callback):
        def __init__(self):
            self.running, self.done, self.failed, self.retried = set(), 0, 0, 0
            self.best = (math.inf, "")

        def _line(self, event: str) -> None:
            best = f"; best val_loss_multistep {self.best[0]:.5f} ({self.best[1]})" if math.isfinite(self.best[0]) else ""
            log(f"{prefix}: {event} | {self.done}/{total} done, {len(self.running)} running, "
                f"{self.failed} failed{f', {self.retried} retried' if self.retried else ''}{best}")

        def on_trial_start(self, iteration, trials, trial, **info):
            self.running.add(trial.trial_id)
            self._line(f"started {names(trial.config)}")

        def on_trial_complete(self, iteration, trials, trial, **info):
            self.running.discard(trial.trial_id)
            self.done += 1
            value = (trial.last_result or {}).get("val_loss_multistep", math.inf)
            if value < self.best[0]:
                self.best = (value, names(trial.config))
            self._line(f"done {names(trial.config)} (val_loss_multistep {value:.5f})")

        def on_trial_recover(self, iteration, trials, trial, **info):
            self.retried += 1
            self._line(f"retrying {names(trial.config)} after a failure")

        def on_trial_error(self, iteration, trials, trial, **info):
            self.running.discard(trial.trial_id)
            self.failed += 1
            self._line(f"FAILED {names(trial.config)}")

    return SweepProgress()


def _run_config(tune, storage: Path, max_retries: int, callback):
    return tune.RunConfig(name="tune", storage_path=str(storage.resolve()), verbose=0, callbacks=[callback],
                          failure_config=tune.FailureConfig(max_failures=max_retries),
                          checkpoint_config=tune.CheckpointConfig(num_to_keep=1))


def run_trials(trials: list[TrialSpec], context: TrialContext, workers: int, address: str | None = None,
               max_retries: int = 2, storage: Path | None = None,
               log: Callable[[str], None] = print, prefix: str = "sweep") -> dict[str, str]:
    """Run `trials` (one Tune trial each, one CPU each); trials already complete are reused.
    Ray reuses a worker process for the next trial (data read once per process); results
    do not depend on it (every trial seeds itself).

    Returns {trial path: error} for trials that failed after their retries.
    """
    ray, tune = import_ray()
    started = start_ray(workers, address)
    try:
        storage = storage or Path(context.out) / RAY_DIR
        trainable = tune.with_resources(tune.with_parameters(tune_trainable, trials=trials, context=context),
                                        {"cpu": 1})
        callback = progress_callback(len(trials), lambda c: trials[int(c["trial"])].path, log, prefix)
        tuner = tune.Tuner(
            trainable, param_space={"trial": tune.grid_search(list(range(len(trials))))},
            tune_config=tune.TuneConfig(max_concurrent_trials=workers, reuse_actors=True),
            run_config=_run_config(tune, storage, max_retries, callback))
        grid = tuner.fit()
        remove_locks(context.out)  # every trial is over
        return {trials[int(r.config["trial"])].path: _error_text(r.error) for r in grid if r.error is not None}
    finally:
        if started:
            ray.shutdown()


def run_optuna(spec, context: TrialContext, workers: int, address: str | None = None,
               storage: Path | None = None, resume: bool = False,
               log: Callable[[str], None] = print) -> dict[str, str]:
    """Optuna's search (through Ray Tune): ``samples`` configurations, each trial training
    every seed of the sweep and reporting their mean validation loss."""
    ray, tune = import_ray()
    try:
        from ray.tune.search.optuna import OptunaSearch
        import optuna  # noqa: F401
    except ImportError:
        raise ConfigError(f"{spec.source}: search = \"optuna\" needs optuna: {INSTALL_HINT}") from None
    from sysid.sweep.optuna_space import optuna_space, optuna_trainable, point_of

    started = start_ray(workers, address)
    try:
        storage = storage or Path(context.out) / RAY_DIR
        path = (storage / "tune").resolve()
        trainable = tune.with_resources(tune.with_parameters(optuna_trainable, spec=spec, context=context), {"cpu": 1})
        callback = progress_callback(spec.samples, lambda c: point_of(spec, c), log)
        if resume and tune.Tuner.can_restore(str(path)):
            tuner = tune.Tuner.restore(str(path), trainable, resume_errored=True)
        else:
            search = OptunaSearch(metric="val_loss_multistep", mode="min", seed=spec.search_seed)
            tuner = tune.Tuner(
                trainable, param_space=optuna_space(spec),
                tune_config=tune.TuneConfig(search_alg=search, num_samples=spec.samples,
                                            max_concurrent_trials=workers, reuse_actors=True),
                run_config=_run_config(tune, storage, spec.max_retries, callback))
        grid = tuner.fit()
        remove_locks(context.out)  # every trial is over
        return {point_of(spec, r.config): _error_text(r.error) for r in grid if r.error is not None}
    finally:
        if started:
            ray.shutdown()


def _error_text(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return (text[-1] if text else type(error).__name__)[:300]


def default_workers() -> int:
    from sysid.device import cpu_cores
    return max(1, cpu_cores())

