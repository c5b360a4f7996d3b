"""Trials on Ray Tune: on a local Ray of the sweep's own or on a cluster (`sysid.sweep.connect`),
one CPU and one torch thread per trial, retries of crashed trials and of trials whose node
was lost, an optional scheduler that stops poor trials early, and a progress line per
event (done / running / failed / stopped early, best validation loss so far).

Every trial reports its validation loss after every epoch and a last result marked
``final`` (the run's objective). Tune's experiment state is kept where Ray users look for
it (``{out}/tune`` or ``--storage``): ``tune.ExperimentAnalysis`` and
``Tuner.restore(...).get_results()`` read every trial's per-epoch validation loss there.
sysid itself never reads it back: a resumed sweep starts a new Tune experiment and learns
what is done from its own verified run directories.
"""
from __future__ import annotations

import math
import os
import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

from sysid.errors import ConfigError
from sysid.sweep.connect import import_ray, start_ray
from sysid.sweep.inbox import inbox_actor
from sysid.sweep.spec import SchedulerSpec
from sysid.sweep.trial import OBJECTIVE, TrialData, TrialSpec, group_name, tune_trainable

TUNE_DIR = "tune"   # Tune's experiment, inside the output directory unless --storage is given


@dataclass(frozen=True)
class TuneStorage:
    """Where Tune keeps its experiment: ``storage_path`` (a directory or a URI pyarrow
    reads, e.g. s3://bucket/sweeps) and the experiment's ``name`` below it."""

    storage_path: str
    name: str = TUNE_DIR

    @property
    def experiment(self) -> str:
        return f"{self.storage_path.rstrip('/')}/{self.name}"


# URI schemes pyarrow's FileSystem.from_uri opens (Tune writes its experiment through it)
STORAGE_SCHEMES = ("file", "s3", "gs", "gcs", "hdfs", "viewfs", "abfs", "abfss", "mock")


def tune_storage(storage: str, name: str, out: Path, inputs: Iterable[str | os.PathLike] = ()) -> TuneStorage:
    """``--storage`` checked as an output before Ray starts: a URI of a scheme pyarrow opens,
    or a folder where Tune's experiment ``{storage}/{name}`` follows the rules of ``-o``
    (`sysid.store.target.OutputTarget.check_place`): not a link, not one of the sweep's
    `inputs` or the folder of one of its logs, holding none and inside none, not inside a
    directory sysid sealed other than the sweep's own output `out`."""
    from sysid.errors import OutputError
    from sysid.store.target import OutputKind, OutputTarget

    scheme, sep, rest = storage.partition("://")
    if sep and scheme.lower() != "file":
        if scheme.lower() not in STORAGE_SCHEMES or not rest:
            raise ConfigError(f"--storage {storage!r}: not a folder or a storage URI Tune can write to (schemes: "
                              f"{', '.join(STORAGE_SCHEMES[1:])}, or file://); give a folder or e.g. s3://bucket/dir")
        return TuneStorage(storage, name)
    folder = Path(rest if sep else storage).expanduser()
    if not str(folder).strip():
        raise OutputError("--storage: empty; give a folder or a storage URI")
    experiment = folder / name
    own = experiment.absolute().resolve().is_relative_to(out.absolute().resolve())
    try:
        OutputTarget(experiment, OutputKind.SWEEP, tuple(Path(p) for p in inputs)).check_place(sealed=not own)
    except OutputError as exc:
        raise OutputError(f"--storage {storage}: {exc}") from None
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"--storage {storage}: exists and is not a folder; give a folder for Tune's experiment")
    return TuneStorage(str(folder.absolute()), name)


@dataclass
class Outcomes:
    """What Tune says of the trials it ended without a complete run: errors, and trials a
    scheduler stopped early (with the epochs they reported), keyed by trial path or point."""

    errors: dict[str, str] = field(default_factory=dict)
    stopped: dict[str, int] = field(default_factory=dict)
    configs: list[dict] = field(default_factory=list)   # every Tune trial's config


def progress_callback(total: int, names: Callable[[dict], str], log: Callable[[str], None],
                      inbox: str | None = None, prefix: str = "sweep", rank_trials: bool = True):
    """A Tune callback printing one line per trial event with the counts (done, running,
    failed, stopped early) and, with `rank_trials` (trials of one experiment, a sweep), the
    best validation loss so far; it also releases the claims of every Tune trial that ends in
    the inbox named `inbox`."""
    _, tune = import_ray()

    class SweepProgress(tune.Callback):  # type: ignore[name-defined]
        def __init__(self):
            self.running, self.done, self.failed, self.stopped, self.retried = set(), 0, 0, 0, 0
            self.best = (math.inf, "")

        def _line(self, event: str) -> None:
            best = (f"; best val_loss_multistep {self.best[0]:.5f} ({self.best[1]})"
                    if rank_trials and math.isfinite(self.best[0]) else "")
            log(f"{prefix}: {event} | {self.done}/{total} done, {len(self.running)} running, {self.failed} failed, "
                f"{self.stopped} stopped early{f', {self.retried} retried' if self.retried else ''}{best}")

        def _ended(self, trial) -> None:
            self.running.discard(trial.trial_id)
            if inbox is not None:
                import ray
                ray.get_actor(inbox).release.remote(trial.trial_id)

        def on_trial_start(self, iteration, trials, trial, **info):
            self.running.add(trial.trial_id)
            self._line(f"started {names(trial.config)}")

        def on_trial_complete(self, iteration, trials, trial, **info):
            self._ended(trial)
            result = trial.last_result or {}
            if not result.get("final"):
                self.stopped += 1
                self._line(f"stopped early {names(trial.config)} after {result.get('training_iteration', 0)} "
                           f"epochs (val_loss_multistep {result.get(OBJECTIVE, math.nan):.5f})")
                return
            self.done += 1
            value = result.get(OBJECTIVE, math.inf)
            if value < self.best[0]:
                self.best = (value, names(trial.config))
            runs = int(result.get("runs", 1))
            self._line(f"done {names(trial.config)} (val_loss_multistep {value:.5f}"
                       + (f", the mean of its {runs} seeds)" if runs > 1 else ")"))

        def on_trial_recover(self, iteration, trials, trial, **info):
            self.retried += 1
            cause = failure_cause(_trial_error(trial))
            self._line(f"retrying {names(trial.config)} after a failure: {cause}" if cause
                       else f"retrying {names(trial.config)} after a failure (a lost node or a crash)")

        def on_trial_error(self, iteration, trials, trial, **info):
            self._ended(trial)
            self.failed += 1
            self._line(f"FAILED {names(trial.config)}")

    return SweepProgress()


def _trial_error(trial) -> BaseException | None:
    """The exception Tune recorded for `trial`'s last failure (its pickled copy), None when
    there is none or it cannot be read back."""
    try:
        return trial.get_pickled_error()
    except Exception:   # no error file, a storage that does not answer, a class that does not unpickle
        return None


def failure_cause(error: BaseException | None) -> str | None:
    """The first line of the failure's own message: through Ray's wrappers (a trial's
    exception, or an actor's it called, as `RayTaskError.cause`) to the exception raised;
    None without one."""
    seen = 0
    while isinstance(getattr(error, "cause", None), BaseException) and seen < 8:
        error, seen = error.cause, seen + 1   # type: ignore[union-attr]
    if error is None:
        return None
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return lines[0] if lines else type(error).__name__


def make_scheduler(spec: SchedulerSpec, horizon: int):
    """Tune's scheduler for `spec` over trials of at most `horizon` epoch reports (None: none).

    Time is Tune's ``training_iteration`` (one report per epoch); ``max_t`` lies one past
    the horizon, so only a trial's last report (its final result) can reach it."""
    if spec.kind == "none":
        return None
    from ray.tune.schedulers import ASHAScheduler, MedianStoppingRule

    s = spec.as_dict()
    if spec.kind == "asha":
        max_t = max(horizon + 1, int(s["grace_period"]) + 1)
        return ASHAScheduler(time_attr="training_iteration", metric=OBJECTIVE, mode="min", max_t=max_t,
                             grace_period=int(s["grace_period"]), reduction_factor=float(s["reduction_factor"]),
                             brackets=int(s["brackets"]))
    return MedianStoppingRule(time_attr="training_iteration", metric=OBJECTIVE, mode="min",
                              grace_period=float(s["grace_period"]),
                              min_samples_required=int(s["min_samples_required"]))


def _run_config(tune, storage: TuneStorage, max_retries: int, callbacks: list):
    return tune.RunConfig(name=storage.name, storage_path=storage.storage_path, verbose=0, callbacks=callbacks,
                          failure_config=tune.FailureConfig(max_failures=max_retries))


@dataclass(frozen=True)
class Session:
    """A sweep's Ray: its inbox (actor handle, and the name trials find it by) and how
    many trials run side by side (None: as many as the cluster has CPUs)."""

    inbox: object
    inbox_name: str
    concurrency: int | None


@contextmanager
def ray_session(out: Path, workers: int | None, address: str | None, log: Callable[[str], None],
                lost_note: Callable[[], str] = lambda: "nothing was kept",
                lost_cleanup: Callable[[], None] = lambda: None) -> Iterator[Session]:
    """Ray started or joined for the sweep, and the sweep's inbox on this node; Ray is shut
    down afterwards if this session started it. A joined cluster whose head stops
    answering ends the sweep with one line (`sysid.sweep.connect.watch_head`: `lost_cleanup`
    first, `lost_note` says what was kept), or a `ClusterLostError` when Ray's calls fail first."""
    from sysid.errors import ClusterLostError
    from sysid.sweep.connect import head_answers, lost_line, ray_target, resolved, watch_head

    ray, _ = import_ray()
    local = ray_target(address).address is None
    started = start_ray(workers or default_workers(), address, log)
    try:
        try:
            inbox, name = inbox_actor(out.resolve())
        except ray.exceptions.RayError as exc:  # e.g. this node's Ray workers run another sysid
            reason = next((line.strip() for line in reversed(str(exc).splitlines()) if line.strip()), "")
            raise ConfigError(f"{ray_target(address).describe()}: cannot run sysid's code on this node "
                              f"({reason[:200]}); every node of the cluster needs the same sysid installed") from None
        if not local and not ray.cluster_resources().get("CPU"):
            log(f"note: {ray_target(address).describe()} has no CPU for trials yet; the trials wait for nodes "
                "to join (Ctrl-C stops)")
        target = resolved(ray_target(address))
        try:
            with watch_head(target, lost_note, lost_cleanup):
                yield Session(inbox, name, (workers or default_workers()) if local else workers)
        except Exception as exc:
            if not local and target.address and not head_answers(target.address):
                raise ClusterLostError(lost_line(target, lost_note())) from exc
            raise
    finally:
        if started:
            ray.shutdown()


def run_trials(trials: list[TrialSpec], out: Path, data: TrialData, session: Session, max_retries: int = 2,
               storage: TuneStorage | None = None, scheduler=None, callbacks: Sequence = (),
               log: Callable[[str], None] = print, prefix: str = "sweep",
               groups: Sequence[Sequence[int]] | None = None, rank_trials: bool = True) -> Outcomes:
    """Run `trials` (one Tune trial each, one CPU each) in a `ray_session`; trials already
    complete in `out` are reused. Returns what Tune ended without a complete run.

    `groups` (indices into `trials`, each index in one group; None: each trial alone):
    one Tune trial per group, its seeds side by side (`sysid.sweep.trial.run_group`);
    ``config["trial"]`` is the group's first index. `rank_trials` false: the progress lines
    name no "best" trial (trials of different experiments, whose losses do not compare)."""
    _, tune = import_ray()
    storage = storage or TuneStorage(str(out.resolve()))
    groups = [list(g) for g in groups] if groups is not None else [[i] for i in range(len(trials))]
    by_first = {g[0]: g for g in groups}
    trainable = tune.with_resources(tune.with_parameters(tune_trainable, trials=trials, inbox=session.inbox_name,
                                                         data=data, groups=by_first), {"cpu": 1})
    progress = progress_callback(len(groups), lambda c: group_name([trials[i] for i in by_first[int(c["trial"])]]),
                                 log, session.inbox_name, prefix, rank_trials)
    tuner = tune.Tuner(
        trainable, param_space=trial_space(tune, trials, [g[0] for g in groups]),
        tune_config=tune.TuneConfig(max_concurrent_trials=session.concurrency, reuse_actors=True,
                                    scheduler=scheduler),
        run_config=_run_config(tune, storage, max_retries, [progress, *callbacks]))
    with _ctrl_c_ends_tune():
        grid = tuner.fit()
    outcomes = _outcomes(grid, lambda c: trials[int(c["trial"])].path)
    for group in groups:  # what Tune says of a group's trial holds for each of its seeds
        first = trials[group[0]].path
        for i in group[1:]:
            if first in outcomes.errors:
                outcomes.errors[trials[i].path] = outcomes.errors[first]
            if first in outcomes.stopped:
                outcomes.stopped[trials[i].path] = outcomes.stopped[first]
    return outcomes


def _plain(value):
    return list(value) if isinstance(value, tuple) else value


def trial_space(tune, trials: list[TrialSpec], firsts: Sequence[int] | None = None) -> dict:
    """Tune's parameter space of a trial list: the trial's index (a grid over all of them,
    or over `firsts`, the first trial of each group) and, filled in from it, its seed, run
    name and varied values (``section__option``), so that Tune's tables and
    ``get_best_config`` show what a trial is."""
    space = {"trial": tune.grid_search(list(firsts) if firsts is not None else list(range(len(trials)))),
             "seed": tune.sample_from(lambda s: trials[s.config["trial"]].seed)}
    if any(t.label for t in trials):
        space["run"] = tune.sample_from(lambda s: trials[s.config["trial"]].label)
    for key in trials[0].values if trials else ():
        space[key.replace(".", "__")] = tune.sample_from(lambda s, k=key: _plain(trials[s.config["trial"]].values[k]))
    return space


def run_optuna(spec, out: Path, data: TrialData, session: Session, storage: TuneStorage | None = None, scheduler=None,
               callbacks: Sequence = (), evaluated: Sequence[tuple[dict, float]] = (), pending: Sequence[dict] = (),
               log: Callable[[str], None] = print) -> Outcomes:
    """Optuna's search (through Ray Tune): ``samples`` configurations, each trial training
    every seed of the sweep and reporting their mean validation loss. A resumed search
    starts from sysid's own record: `evaluated` (Tune config, mean validation loss) are
    told to Optuna as done, `pending` (configurations with seeds left) are run first."""
    _, tune = import_ray()
    try:
        from ray.tune.search.optuna import OptunaSearch
    except ImportError:
        raise ConfigError(f"{spec.source}: search = \"optuna\" needs optuna: pip install \"sysid[sweep]\"") from None
    from sysid.sweep.optuna_space import optuna_space, optuna_trainable, point_of

    storage = storage or TuneStorage(str(out.resolve()))
    remaining = spec.samples - len(evaluated)
    if remaining <= 0:
        return Outcomes()
    import optuna
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # a resumed search draws from a stream of its own: the sampler's first draws would
    # otherwise repeat the configurations it is told are done
    search = OptunaSearch(space=optuna_space(spec), metric=OBJECTIVE, mode="min",
                          seed=spec.search_seed + len(evaluated) + len(pending),
                          points_to_evaluate=list(pending) or None)
    for config, value in evaluated:
        search.add_evaluated_point(config, value)
    trainable = tune.with_resources(tune.with_parameters(optuna_trainable, spec=spec, inbox=session.inbox_name,
                                                         data=data), {"cpu": 1})
    progress = progress_callback(remaining, lambda c: point_of(spec, c), log, session.inbox_name)
    tuner = tune.Tuner(
        trainable,
        tune_config=tune.TuneConfig(search_alg=search, num_samples=remaining,
                                    max_concurrent_trials=session.concurrency,
                                    reuse_actors=True, scheduler=scheduler),
        run_config=_run_config(tune, storage, spec.max_retries, [progress, *callbacks]))
    with _ctrl_c_ends_tune():
        grid = tuner.fit()
    return _outcomes(grid, lambda c: point_of(spec, c))


@contextmanager
def _ctrl_c_ends_tune() -> Iterator[None]:
    """Ctrl-C (SIGINT) during ``Tuner.fit`` stops Tune gracefully and then raises
    `KeyboardInterrupt`, so that nothing takes an interrupted sweep or reproduction for a
    finished one (Tune's own SIGINT handler returns as if the trials had ended). Tune's
    graceful stop is its SIGUSR1; a second Ctrl-C interrupts at once."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    interrupted = threading.Event()
    previous = signal.getsignal(signal.SIGINT)

    def stop_tune(signum, frame):
        interrupted.set()
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if signal.getsignal(signal.SIGUSR1) in (signal.SIG_DFL, signal.SIG_IGN, None):
            raise KeyboardInterrupt  # Tune's loop has not started: nothing to stop gracefully
        os.kill(os.getpid(), signal.SIGUSR1)

    tune_setting = os.environ.get("TUNE_DISABLE_SIGINT_HANDLER")
    os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"
    signal.signal(signal.SIGINT, stop_tune)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if tune_setting is None:
            os.environ.pop("TUNE_DISABLE_SIGINT_HANDLER", None)
        else:
            os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = tune_setting
    if interrupted.is_set():
        raise KeyboardInterrupt


def _outcomes(grid, key: Callable[[dict], str]) -> Outcomes:
    """What Tune ended without a complete run."""
    outcomes = Outcomes()
    for result in grid:
        outcomes.configs.append(dict(result.config))
        if result.error is not None:
            outcomes.errors[key(result.config)] = _error_text(result.error)
        elif not (result.metrics or {}).get("final"):
            outcomes.stopped[key(result.config)] = int((result.metrics or {}).get("training_iteration", 0))
    return outcomes


def _error_text(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return (text[-1] if text else type(error).__name__)[:300]


def default_workers() -> int:
    from sysid.device import cpu_cores
    return max(1, cpu_cores())
