"""Protocol runs trained with N seeds on Ray (``sysid reproduce --seeds N``): the seeds of
a learned run train side by side in one trial where they can (`seed_groups`); each learned
run becomes ``runs/{name}/seed{k}/`` (ordinary run directories), its metrics the mean over
the seeds with their spread (`sysid.protocol.seeds`), and the networks' mean-of-seeds ensemble a run
of its own, ``runs/{variant}_ensemble_{dataset}/`` (`sysid.hybrid.ensemble`)."""
from __future__ import annotations

import functools
import multiprocessing
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Protocol, Sequence

import pandas as pd

from sysid.data.recordings import Run
from sysid.dynamics.integrators import Integrator
from sysid.device import compute_threads
from sysid.evaluation.divergence import PhysicalRange
from sysid.evaluation.evaluate import Evaluation, evaluate_model
from sysid.evaluation.verdict import BaselineVerdict, baseline_verdict
from sysid.config.experiment import Experiment
from sysid.protocol.paper import run_variant
from sysid.runs.rundir import RunDir
from sysid.runs.layout import load_model, write_run
from sysid.runs.lifecycle import scores_on_tests
from sysid.protocol.seeds import seed_metrics
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.sweep.inbox import complete_summary
from sysid.sweep.connect import import_ray
from sysid.sweep.runner import TuneStorage, ray_session, run_trials
from sysid.sweep.trial import TrialSpec, group_name, read_trial_data, seed_groups
from sysid.workers import in_workers


@dataclass
class SeedGroup:
    """One protocol run's seeds: seed-mean metrics, mean gate-off shares, failures, and
    ``seconds``: the sum of its seed runs' own times (trials run side by side, so this is
    the compute time of the group, not a share of the wall clock)."""

    name: str
    seeds: list[int]
    metrics: pd.DataFrame
    gate_off_share: dict
    failure: str | None
    seconds: float


def seed_trials(experiments: dict[str, Experiment], seeds: int) -> list[TrialSpec]:
    """Every learned run x seed (the config's seed, +1, ...), one torch thread each."""
    trials = []
    for name, exp in experiments.items():
        for k in range(seeds):
            seed = exp.experiment.seed + k
            config = exp.replace(experiment={"seed": seed}, training={"threads": 1}).to_toml()
            trials.append(TrialSpec(f"runs/{name}/seed{seed}", name, seed, config, label=name))
    return trials


SIDE_BY_SIDE_COST = 0.4   # a seed's share of its group's time (benchmarks/speed_results.md: 0.31-0.37x)


def train_seeds(experiments: dict[str, Experiment], seeds: int, out: Path, data: str, workers: int | None,
                address: str | None = None, log: Callable[[str], None] = print, storage: str | None = None,
                mlflow: str | None = None, cost: Callable[[str], float] | None = None,
                watch: TrainingWatch | None = None) -> dict[str, SeedGroup]:
    """Train the learned runs with `seeds` seeds each on Ray (locally with `workers` side
    by side, or on the cluster at `address`; `sysid.sweep.runner`); their `SeedGroup`s.
    The data are read here once and shipped to the trials; Tune's experiment goes to
    ``{out}/tune`` or `storage`; `mlflow` logs every seed run; `cost` (run name -> relative
    training cost of one seed) orders the trials longest first (None: as given); `watch`
    hears of the trials as they end (on a local Ray only)."""
    trials = seed_trials(experiments, seeds)
    trial_data = read_trial_data(experiments.values(), data, tests=True)  # the protocol evaluates
    together = seed_groups(trials, trial_data, log)   # a protocol run's seeds share its label
    if cost is not None:  # the longest trials first; a group of seeds costs about SIDE_BY_SIDE_COST a seed
        together.sort(key=lambda g: -cost(trials[g[0]].label) * (SIDE_BY_SIDE_COST * len(g) if len(g) > 1 else 1))
    callbacks = []
    with ray_session(out, workers, address, log) as session:
        tracker = parent = None
        if mlflow:
            from sysid.sweep.tracked import tracking_callback
            from sysid.experiment_tracking import Tracker
            tracker = Tracker(mlflow, "sysid-reproduce")
            parent = tracker.start("reproduce --seeds", {"seeds": seeds, "runs": ", ".join(experiments)},
                                   tags={"sysid.kind": "reproduce"})
            by_first = {g[0]: [trials[i] for i in g] for g in together}
            callbacks = [tracking_callback(tracker, parent, out.resolve(), lambda c: group_name(by_first[int(c["trial"])]),
                                           lambda c: {"run": trials[int(c["trial"])].label,
                                                      "seed": ", ".join(str(t.seed) for t in by_first[int(c["trial"])])},
                                           lambda c: {f"seed{t.seed}": t.path for t in by_first[int(c["trial"])]},
                                           log)]
        if watch is not None and address is None and session.concurrency:
            callbacks.append(_watch_callback(watch, trials, together, out, session.concurrency))
        outcomes = run_trials(trials, out, trial_data, session, max_retries=1,
                              storage=TuneStorage(storage, "reproduce") if storage else None,
                              callbacks=callbacks, log=log, prefix="seeds", groups=together,
                              rank_trials=False)  # D1 and D2, NN and hybrid: their losses do not compare
        if tracker is not None:
            tracker.finish(parent)
    return {name: seed_group(name, trials, out, outcomes.errors) for name in experiments}


def seed_group(name: str, trials: Sequence[TrialSpec], out: Path, errors: dict[str, str]) -> SeedGroup:
    """The `SeedGroup` of the protocol run `name` from its seeds' run directories in `out`
    (`errors`: trial path -> what Tune said of a trial without a complete run)."""
    frames, shares, failures, used, seconds = [], [], [], [], 0.0
    for trial in (t for t in trials if t.label == name):
        summary = complete_summary(out / trial.path)
        if summary is None:
            failures.append(f"seed {trial.seed}: {errors.get(trial.path, 'no complete run')}")
            continue
        if summary.status != "complete":
            failures.append(f"seed {trial.seed}: {summary.status}")
        frames.append(RunDir(out / trial.path).read_metrics())
        shares.append(summary.gate.off_share or {})
        used.append(trial.seed)
        seconds += float(summary.seconds or 0.0)
    metrics = seed_metrics(frames) if frames else pd.DataFrame()
    mean_share = {k: sum(s.get(k, 0.0) for s in shares) / len(shares) for k in (shares[0] if shares else {})}
    return SeedGroup(name, used, metrics, mean_share, "; ".join(failures) or None, seconds)


class TrainingWatch(Protocol):
    """What `train_seeds` tells while its trials run (in the driver's thread): `free`
    trial slots no trial will take again (the queue is empty), a protocol run `ready` (all
    its seeds complete), and `poll` on every step of Tune's loop."""

    def free(self, slots: int) -> None: ...

    def ready(self, name: str, group: SeedGroup) -> None: ...

    def poll(self) -> None: ...


def _watch_callback(watch: TrainingWatch, specs: Sequence[TrialSpec], groups: Sequence[Sequence[int]], out: Path,
                    slots: int):
    """A Tune callback feeding `watch`: `specs` trained in Tune trials of `groups` (indices
    into `specs`, ``config["trial"]`` the first), `slots` of them at once."""
    _, tune = import_ray()
    seeds_of: dict[str, int] = {}
    for t in specs:
        seeds_of[t.label] = seeds_of.get(t.label, 0) + 1

    class Watch(tune.Callback):  # type: ignore[name-defined]
        def __init__(self):
            self.ended, self.announced = 0, set()

        def on_step_end(self, iteration, trials, **info):
            watch.poll()

        def _ended(self, trial) -> None:
            self.ended += 1
            watch.free(slots - (len(groups) - self.ended))
            name = specs[int(trial.config["trial"])].label
            if name not in self.announced:
                group = seed_group(name, specs, out, {})
                if group.failure is None and len(group.seeds) == seeds_of[name]:
                    self.announced.add(name)
                    watch.ready(name, group)

        def on_trial_complete(self, iteration, trials, trial, **info):
            self._ended(trial)

        def on_trial_error(self, iteration, trials, trial, **info):
            self._ended(trial)

    return Watch()


def ensemble_name(name: str, dataset: str) -> str:
    """hybrid_D1 -> hybrid_ensemble_D1."""
    return f"{run_variant(name, dataset)}_ensemble_{dataset}"


def write_ensemble(name: str, exp: Experiment, group: SeedGroup, out: Path, tests: Sequence[Run],
                   threads: int | None = None):
    """The mean-of-seeds ensemble of a learned run, evaluated (with `threads` torch threads;
    None: as set) and written as a run directory whose ``[ensemble] members`` point at the
    seeds' run directories: (its name, `Evaluation`, its path). Its verdict (summary.json
    ``verdict``) is the one rule's on the test logs' per-log cells against its physics
    baseline, the ship file's MMG with the run's ``[mmg] overrides`` (the MMG the hybrids
    correct; `ensemble_verdict`), as ``sysid compare RUN --against baseline`` judges it."""
    if threads is not None:
        with compute_threads(threads):
            return write_ensemble(name, exp, group, out, tests)
    started = time.perf_counter()
    seed_dirs = [out / "runs" / name / f"seed{seed}" for seed in group.seeds]
    members = [load_model(p)[1] for p in seed_dirs]
    model = SeedEnsemble(members)
    # the seeds' widest training range: beyond it a prediction diverged, as in each seed's run
    limits = PhysicalRange.widest([PhysicalRange.of_summary(RunDir(p).read_summary()) for p in seed_dirs])
    evaluation = evaluate_model(model, tests, exp.evaluation.horizons, Integrator(exp.evaluation.integrator),
                                limits=limits)
    verdict, baseline_metrics = ensemble_verdict(exp, model, evaluation, tests, limits)
    target = ensemble_name(name, exp.experiment.dataset)
    ens = exp.replace(experiment={"name": target},
                      ensemble={"members": tuple(f"../{name}/seed{seed}" for seed in group.seeds)})
    path = write_run(out / "runs" / target, ens, model, evaluation, seconds=time.perf_counter() - started,
                     verdict=verdict, baseline_metrics=baseline_metrics, limits=limits)
    return target, evaluation, path


def ensemble_verdict(exp: Experiment, model: SeedEnsemble, evaluation: Evaluation, tests: Sequence[Run],
                     limits: PhysicalRange | None = None) -> tuple[BaselineVerdict | None, pd.DataFrame | None]:
    """(the verdict of a mean-of-seeds ensemble, its baseline's metrics on the test logs), or
    (None, None) without test logs: the ensemble's `evaluation` (its test predictions, made
    once) paired window by window with its physics baseline's on the same test logs, the
    ship file's MMG with ``[mmg] overrides`` (`physics_baselines`; one MMG rollout per
    window, float64), judged by the one rule (`baseline_verdict`). The ensemble is one
    model (no spread); its `evaluation` and its baseline's mark a prediction diverged by the
    one rule (`sysid.evaluation.divergence`) against `limits`, the seeds' widest training
    range, as ``sysid train`` and ``sysid compare RUN --against baseline`` do."""
    scores = scores_on_tests(exp, model, evaluation, tests, limits)
    if not scores:
        return None, None
    verdict = baseline_verdict(str(exp.experiment.model), None, scores, ensemble_of=len(model.members))
    metrics = pd.concat([e.metrics.assign(baseline=label) for label, e in scores.items() if label != "model"],
                        ignore_index=True)
    return verdict, metrics



def write_ensembles(groups: Sequence[tuple[str, Experiment, SeedGroup]], out: Path, tests: Sequence[Run],
                    workers: int = 1, threads: int = 1, on_result: Callable | None = None) -> dict[str, tuple]:
    """`write_ensemble` of each (name, experiment, seed group), in up to `workers` worker
    processes side by side (`sysid.workers`, `threads` torch threads each): name ->
    its result in the order of `groups`, each also passed to `on_result` as it is written."""
    if workers <= 1 or len(groups) <= 1:
        done = {}
        for name, exp, group in groups:
            done[name] = write_ensemble(name, exp, group, out, tests, threads if workers > 1 else None)
            if on_result is not None:
                on_result(done[name])
        return done
    work = functools.partial(_ensemble_work, out=out, tests=tests, threads=threads)
    results = in_workers(work, list(groups), workers, multiprocessing.get_context("spawn"),
                         on_result=None if on_result is None else lambda r: on_result(r[1]))
    written = dict(results)
    return {name: written[name] for name, _, _ in groups}  # in the order of `groups`


def _ensemble_work(item: tuple[str, Experiment, SeedGroup], out: Path, tests: Sequence[Run],
                   threads: int) -> tuple[str, tuple]:
    """One worker's item of `write_ensembles`: (name, `write_ensemble`'s result)."""
    name, exp, group = item
    return name, write_ensemble(name, exp, group, out, tests, threads)
