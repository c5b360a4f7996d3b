"""The driver's work after training (`sysid.protocol.reproduce` with seeds), overlapped with
the last trials: a protocol run's mean-of-seeds ensemble and the recorded maneuvers'
predictions of its models (`sysid.maneuvers.recorded`) start as soon as all its seeds are
complete, in worker processes, but only on the trial slots Ray no longer fills (no trial
left to start), so they take the cores the tail of the training leaves idle and never
compete with a trial for one.

Every piece is the same call, with the same settings (one torch thread, a worker process),
as when it runs after training: the tables and ``maneuver_indices.csv`` do not depend on
when it ran.
"""
from __future__ import annotations

import functools
import multiprocessing
from pathlib import Path
from typing import Any, Callable, Hashable, Mapping, Sequence, cast

from sysid.config.choices import ModelKind
from sysid.config.experiment import Experiment
from sysid.data.recordings import Run
from sysid.maneuvers.recorded import (Predictions, group_predictor, model_paths, record_predictor,
                                      recorded_test_runs)
from sysid.protocol.seed_runs import SeedGroup, ensemble_name, write_ensemble
from sysid.workers import Overlap


def _work(item: tuple, out: Path, tests: Sequence[Run], predict: Callable, predict_group: Callable):
    """One worker's item: ("ensemble", (name, experiment, seed group)) -> `write_ensemble`'s
    result; ("record", path) -> the predictions of the model at path; ("group", (paths of
    the seeds, the ensemble's path)) -> {path: predictions} of the seeds' models and their
    mean-of-seeds ensemble, one batched rollout (`sysid.maneuvers.recorded.group_predictor`)."""
    kind, payload = item
    if kind == "ensemble":
        name, exp, group = payload
        return write_ensemble(name, exp, group, out, tests, threads=1)
    if kind == "group":
        return predict_group(*payload)
    return predict(payload)[1]


class AfterTraining:
    """A `sysid.protocol.seed_runs.TrainingWatch` doing the after-training work of each
    protocol run that is `ready`, in up to `workers` processes as slots are `free`
    (`sysid.workers.Overlap`; use `pool` as a context manager around the training).
    ``ensembles``: run name -> (its seed group, `write_ensemble`'s result); ``predicted``:
    model path -> predictions (`sysid.maneuvers.recorded.write_record_comparison`'s
    `predicted`)."""

    def __init__(self, experiments: Mapping[str, Experiment], out: Path, tests: Sequence[Run], data, workers: int,
                 log: Callable[[str], None] = print):
        self.experiments, self.out, self.log = experiments, out, log
        runs = recorded_test_runs(data)
        self.pool = Overlap(functools.partial(_work, out=out, tests=tuple(tests), predict=record_predictor(runs),
                                              predict_group=group_predictor(runs)), workers,
                            multiprocessing.get_context("spawn"), self._done)
        self.groups: dict[str, SeedGroup] = {}
        self.ensembles: dict[str, tuple[SeedGroup, tuple]] = {}
        self.predicted: dict[Path, Predictions] = {}
        self.early = 0    # pieces done before `finish`: while trials ran

    def free(self, slots: int) -> None:
        self.pool.allow(slots)

    def poll(self) -> None:
        self.pool.poll()

    def ready(self, name: str, group: SeedGroup | None = None) -> None:
        """Run `name` is complete (`group`: its seeds; None: a run without seeds): its
        ensemble (a learned run) and its models' predictions queued."""
        exp = self.experiments[name]
        paths = model_paths(self.out / "runs" / name)
        if group is not None and exp.experiment.model is not ModelKind.MMG and group.seeds:
            self.groups[name] = group
            self.pool.add(("ensemble", name), ("ensemble", (name, exp, group)), first=True)
            # the seeds' and the ensemble's maneuvers, one batched rollout: the longest pieces, first
            ensemble = self.out / "runs" / ensemble_name(name, exp.experiment.dataset)
            self.pool.add(("group", name), ("group", (paths, ensemble)), first=True)
            return
        for path in paths:
            self.pool.add(("record", path), ("record", path))

    def finish(self) -> None:
        """Every queued piece done (all slots now free); one line of how many were done
        while trials ran."""
        self.pool.poll()
        self.early = len(self.pool.results)
        self.pool.finish()
        self.log(f"after training: {self.early} of {len(self.pool.results)} pieces (mean-of-seeds ensembles, models' "
                 "recorded maneuvers) were done while the last trials ran")

    def _done(self, key: Hashable, result: Any) -> None:
        kind, subject = cast(tuple, key)
        if kind == "ensemble":
            group = self.groups[subject]
            self.ensembles[subject] = (group, result)
            self.log(f"[{result[0]}] mean of {len(group.seeds)} seeds' networks evaluated")
        elif kind == "group":
            self.predicted.update(cast(dict, result))
        else:
            self.predicted[subject] = result
