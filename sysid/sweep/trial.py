"""One trial of a sweep: one configuration and seed trained into an ordinary run directory
(`sysid.runs.layout`; ``sysid evaluate`` and ``sysid report`` read it).

A trial may run on any node: it needs nothing but the network. Its data come with it
(`TrialData`, read once by the driver and shipped through Ray's object store); it trains in
a temporary directory of its node, sends its training checkpoint to the driver's
`RunInbox` after every epoch and, when done, its run directory, which the inbox verifies
and moves into place. A trial whose run is already complete is not trained again (its
epochs are reported from its history); one whose node was lost continues from the last
checkpoint the inbox holds, on whichever node Ray gives it.
"""
from __future__ import annotations

import dataclasses
import io
import math
import os
import socket
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Callable, Iterable, Sequence

import torch

from sysid.config.choices import Solver
from sysid.data.recordings import Run, read_runs
from sysid.data.datasets import test_files
from sysid.data.splits import file_sha256
from sysid.errors import DataError
from sysid.config.experiment import Experiment, parse_experiment
from sysid.identify.side_by_side import refusal
from sysid.runs.lifecycle import checkpoint_path, run_experiment, run_seeds, training_runs, validation_runs
from sysid.runs.summary import RunSummary
from sysid.sweep.inbox import COMPLETE, WAIT, complete_summary, pack_run  # noqa: F401 (complete_summary: API)
from sysid.identify.checkpoint import CheckpointState
from sysid.identify.trainer import EpochReport

OBJECTIVE = "val_loss_multistep"  # the metric trials report and sweeps rank by (`RunSummary.objective`)
CLAIM_POLL_S = 2.0   # how often a trial waiting for another training of its run asks again


@dataclass(frozen=True)
class TrialSpec:
    """What one trial trains: its run directory (relative to the sweep's output), the
    configuration's name and varied values, the seed, and the resolved experiment TOML."""

    path: str
    point: str
    seed: int
    config: str
    values: dict = field(default_factory=dict)
    label: str = ""          # reproduce: the protocol run's name


def data_key(exp: Experiment) -> tuple:
    """What decides an experiment's training data: data set, ``[data] train`` logs, their
    columns and rate (as `sysid.runs.lifecycle.cached_training_runs`)."""
    return (exp.experiment.dataset, tuple(exp.data.train), exp.data.columns, float(exp.data.rate))


def validation_key(exp: Experiment) -> tuple:
    """What decides an experiment's ``[data] validation`` logs: the files, their columns and rate."""
    return (tuple(exp.data.validation), exp.data.columns, float(exp.data.rate))


@dataclass(frozen=True)
class TrialData:
    """The data every trial needs, read once on the driver: the test runs (none for a sweep),
    the training runs of each `data_key` and the ``[data] validation`` runs of each
    `validation_key`. ``root`` is the driver's data root (a trial whose data were not
    shipped reads them there, which works only where that path exists; None: no paper
    data set is used)."""

    tests: tuple[Run, ...]
    training: dict = field(default_factory=dict)
    root: str | None = None
    validation: dict = field(default_factory=dict)

    def validation_runs(self, exp: Experiment) -> list[Run] | None:
        """The shipped ``[data] validation`` runs of `exp` (None: it lists none, or they were
        not shipped and are read where the trial runs)."""
        runs = self.validation.get(validation_key(exp))
        return list(runs) if runs is not None else None

    def training_runs(self, exp: Experiment) -> list[Run]:
        runs = self.training.get(data_key(exp))
        if runs is not None:
            return list(runs)
        try:
            return training_runs(exp, self.root)
        except DataError as exc:
            raise DataError(f"{exc} (on node {node_name()}: the sweep did not ship this configuration's "
                            "training data)") from None


def read_trial_data(experiments: Iterable[Experiment], root: str | os.PathLike | None,
                    tests: bool = False) -> TrialData:
    """The training runs of every distinct `data_key` among `experiments`, their ``[data]
    validation`` runs and, with `tests` (``sysid reproduce --seeds``: evaluation), the
    paper's test runs. A sweep reads no test file: its trials are trained, validated and
    ranked without one. `root` (the paper's data set) is needed only by an experiment that
    names one."""
    def hashed(runs) -> tuple[Run, ...]:  # the files' SHA-256 travel with them (the run's provenance)
        return tuple(dataclasses.replace(r, sha256=r.sha256 or file_sha256(r.path)) for r in runs)

    training, validation = {}, {}
    for exp in experiments:
        if exp.needs_training and data_key(exp) not in training:
            training[data_key(exp)] = hashed(training_runs(exp, root))
        if exp.needs_training and exp.data.validation and validation_key(exp) not in validation:
            validation[validation_key(exp)] = hashed(validation_runs(exp))
    test_runs = hashed(read_runs(test_files(root).values())) if tests else ()
    return TrialData(test_runs, training, str(root) if root is not None else None, validation)


def node_name() -> str:
    """This node: host name and, inside Ray, the first characters of its node id."""
    name = socket.gethostname()
    try:
        import ray
        if ray.is_initialized():
            name += ":" + ray.get_runtime_context().get_node_id()[:8]
    except ImportError:
        pass
    return name


_ACTORS: dict[str, Any] = {}


def call(inbox, method: str, *args, **kwargs):
    """Call `method` of the driver's inbox: the name of its Ray actor, or a `RunInbox`
    in-process."""
    if isinstance(inbox, str):
        import ray
        if inbox not in _ACTORS:
            _ACTORS[inbox] = ray.get_actor(inbox)
        inbox = _ACTORS[inbox]
    target = getattr(inbox, method)
    if hasattr(target, "remote"):
        import ray
        return ray.get(target.remote(*args, **kwargs))
    return target(*args, **kwargs)


def result_row(trial: TrialSpec, summary: RunSummary | None) -> dict:
    """The results-table row of a trial (status "missing" when it has no complete run)."""
    row = {"point": trial.point, "seed": trial.seed, "run": trial.path, **trial.values}
    if trial.label:
        row["name"] = trial.label
    if summary is None:
        return {**row, "status": "missing", OBJECTIVE: math.nan}
    return {**row, "status": summary.status, OBJECTIVE: summary.objective,
            "epochs": summary.epochs, "best_epoch": summary.best_epoch, "stopped": summary.stopped_text,
            "train_seconds": summary.train_seconds}


def epoch_metrics(stage: str, epoch: int, train_loss: float, val_loss: float) -> dict:
    """What a trial reports to Tune after every epoch (Tune counts ``training_iteration``):
    the epoch's early-stopping validation loss, also under the objective's name so that
    schedulers compare epochs on the one metric (the last report carries the run's
    ``val_loss_multistep``, `final_metrics`)."""
    return {OBJECTIVE: float(val_loss), "early_stopping_loss": float(val_loss), "train_loss": float(train_loss),
            "stage": stage, "epoch": int(epoch)}


def _history_metrics(rows: list[dict], summary: RunSummary | None = None) -> list[dict]:
    """The epochs of a history (`RunDir.read_history` rows or a checkpoint's) as reported metrics;
    Levenberg-Marquardt's one row is not an epoch and is left out."""
    solver = summary.identification.solver if summary is not None and summary.identification is not None else None
    return [epoch_metrics(r["stage"], r["epoch"], r["train_loss"], r["early_stopping_loss"]) for r in rows
            if not (r["stage"] == "identify" and solver == Solver.LEVENBERG_MARQUARDT)]


def _checkpoint_history(blob: bytes, source: str) -> list[dict]:
    state = CheckpointState.from_state_dict(torch.load(io.BytesIO(blob), map_location="cpu", weights_only=True), source)
    return list(state.history) + list(state.stage_history)


def _claimed(trial: TrialSpec, inbox, holder: str, report: Callable[[dict], None], node: str) -> dict | None:
    """Claim `trial` at the inbox (waiting while another Tune trial trains it): its
    results-table row when its run is complete (its epochs reported, journaled "reused"),
    else None (claimed: train it)."""
    while (state := call(inbox, "claim", trial.path, holder)) == WAIT:
        time.sleep(CLAIM_POLL_S)
    if state != COMPLETE:
        return None
    summary = call(inbox, "summary", trial.path)
    for metrics in _history_metrics(call(inbox, "history", trial.path), summary):
        report(metrics)
    call(inbox, "journal", "reused", trial.path, node=node)
    return result_row(trial, summary)


def _restored(trial: TrialSpec, inbox, run_dir: Path, report: Callable[[dict], None], node: str,
              **journal) -> bool:
    """The inbox's checkpoint of `trial` (if any) put beside `run_dir`, its epochs reported,
    the start journaled ("resumed" or "started", with `journal`); whether it resumes."""
    blob = call(inbox, "checkpoint", trial.path)
    done: list[dict] = []
    if blob is not None:
        checkpoint_path(run_dir).write_bytes(blob)
        done = _history_metrics(_checkpoint_history(blob, f"the checkpoint of trial {trial.path}"))
        for metrics in done:
            report(metrics)
    call(inbox, "journal", "resumed" if blob is not None else "started", trial.path, node=node, **journal,
         **({"after_epochs": len(done)} if blob is not None else {}))
    return blob is not None


def _epoch_sender(trial: TrialSpec, inbox, holder: str, report: Callable[[dict], None]) -> Callable[[EpochReport], None]:
    """``on_epoch`` of `trial`'s training: its checkpoint to the inbox, the epoch to Tune."""
    def on_epoch(epoch: EpochReport) -> None:
        if epoch.checkpoint is not None:
            call(inbox, "save_checkpoint", trial.path, holder, epoch.checkpoint.read_bytes())
        report(epoch_metrics(epoch.stage, epoch.epoch, epoch.train_loss, epoch.val_loss))
    return on_epoch


def run_trial(trial: TrialSpec, inbox, data: TrialData, holder: str = "local",
              report: Callable[[dict], None] | None = None, log: Callable[[str], None] = lambda m: None) -> dict:
    """Train `trial` unless its run is complete; its results-table row. Every epoch is
    reported (`epoch_metrics`) and checkpointed to the inbox; the run directory is
    delivered to the inbox when complete. `holder` names the Tune trial doing it."""
    report = report or (lambda metrics: None)
    node = node_name()
    if (row := _claimed(trial, inbox, holder, report, node)) is not None:
        return row
    exp = parse_experiment(tomllib.loads(trial.config), f"sweep trial {trial.path}")
    with tempfile.TemporaryDirectory(prefix="sysid-trial-") as scratch:
        run_dir = Path(scratch) / PurePosixPath(trial.path).name
        resume = _restored(trial, inbox, run_dir, report, node)
        runs = data.training_runs(exp) if exp.needs_training else None
        run_experiment(exp, run_dir, data.tests, runs, data.root, progress=False, log=log,
                       resume=resume, validation=data.validation_runs(exp),
                       on_epoch=_epoch_sender(trial, inbox, holder, report), home=call(inbox, "place", trial.path))
        summary = call(inbox, "deliver", trial.path, holder, pack_run(run_dir), trial.config, node)
    return result_row(trial, summary)


def side_by_side_refusal(trials: Sequence[TrialSpec], data: TrialData | None = None) -> str | None:
    """Why the seeds `trials` (one configuration) cannot train side by side in one trial
    (`sysid.identify.side_by_side.refusal`); None: they can."""
    if len(trials) < 2:
        return "a single seed"
    exp = parse_experiment(tomllib.loads(trials[0].config), f"sweep trial {trials[0].path}")
    shipped = data is not None and data.validation_runs(exp) is not None
    return refusal(exp, bool(exp.data.validation) or shipped)


def seed_groups(trials: Sequence[TrialSpec], data: TrialData | None = None,
                log: Callable[[str], None] = print) -> list[list[int]]:
    """The Tune trials of `trials` (indices into it): the seeds of each configuration (one
    ``label`` in a reproduction, one ``point`` in a sweep) side by side in one trial
    (`run_group`) where they can, else one trial per seed; one log line per configuration
    with more than one seed saying which."""
    groups: list[list[int]] = []
    by_key: dict[str, list[int]] = {}
    for i, t in enumerate(trials):
        by_key.setdefault(t.label or t.point, []).append(i)
    for key, members in by_key.items():
        why = side_by_side_refusal([trials[i] for i in members], data)
        if why is None:
            groups.append(members)
            log(f"{key}: {len(members)} seeds side by side in one trial")
        else:
            groups += [[i] for i in members]
            if len(members) > 1:
                log(f"{key}: {len(members)} seeds one trial each ({why})")
    return groups


def group_name(trials: Sequence[TrialSpec]) -> str:
    """A group's name in progress lines: the first seed's run directory and every seed."""
    if len(trials) == 1:
        return trials[0].path
    return f"{PurePosixPath(trials[0].path).parent}/seed{{{','.join(str(t.seed) for t in trials)}}}"


def run_group(trials: Sequence[TrialSpec], inbox, data: TrialData, holder: str = "local",
              report: Callable[[dict], None] | None = None, log: Callable[[str], None] = lambda m: None) -> list[dict]:
    """The seeds `trials` of one configuration trained side by side in this process
    (`sysid.runs.lifecycle.run_seeds`); their results-table rows in order. A seed whose run
    is complete is reused; every other one is claimed, continues from the checkpoint the
    inbox holds (a seed without one starts afresh: resuming a group resumes its unfinished
    seeds side by side), sends its checkpoint after each of its epochs, and is delivered
    as its own run directory, the layout of `run_trial`'s."""
    if len(trials) == 1:
        return [run_trial(trials[0], inbox, data, holder, report, log)]
    report = report or (lambda metrics: None)
    node = node_name()
    rows: dict[str, dict] = {}
    for trial in trials:
        if (row := _claimed(trial, inbox, holder, report, node)) is not None:
            rows[trial.path] = row
    todo = [t for t in trials if t.path not in rows]
    if len(todo) == 1:
        rows[todo[0].path] = run_trial(todo[0], inbox, data, holder, report, log)
    elif todo:
        experiments = [parse_experiment(tomllib.loads(t.config), f"sweep trial {t.path}") for t in todo]
        with tempfile.TemporaryDirectory(prefix="sysid-group-") as scratch:
            run_dirs = [Path(scratch) / str(i) / PurePosixPath(t.path).name for i, t in enumerate(todo)]
            for trial, run_dir in zip(todo, run_dirs):
                run_dir.parent.mkdir()
                _restored(trial, inbox, run_dir, report, node, side_by_side=len(todo))

            def seed_log(seed: int) -> Callable[[str], None]:
                return lambda m: log(f"seed {seed}: {m}")

            exp = experiments[0]
            run_seeds(experiments, run_dirs, data.tests, data.training_runs(exp), data.root, progress=True,
                      logs=[seed_log(t.seed) for t in todo], group_log=log, resume=True,
                      validation=data.validation_runs(exp),
                      on_epochs=[_epoch_sender(t, inbox, holder, report) for t in todo],
                      homes=[call(inbox, "place", t.path) for t in todo])
            for trial, run_dir in zip(todo, run_dirs):
                summary = call(inbox, "deliver", trial.path, holder, pack_run(run_dir), trial.config, node)
                rows[trial.path] = result_row(trial, summary)
    return [rows[t.path] for t in trials]


def final_metrics(rows: list[dict]) -> dict:
    """A Tune trial's last report: the mean validation loss of its run(s) (inf if any
    failed), the epochs, how many ``runs`` (seeds), and ``final`` (a trial without it was
    stopped early)."""
    values = [r[OBJECTIVE] for r in rows]
    ok = all(r["status"] == "complete" and math.isfinite(v) for r, v in zip(rows, values))
    return {OBJECTIVE: sum(values) / len(values) if ok else math.inf, "final": True, "failed": not ok,
            "epochs": int(sum(int(r.get("epochs") or 0) for r in rows)), "runs": len(rows)}


def tune_trainable(config: dict, trials: list[TrialSpec], inbox: Any, data: TrialData,
                   groups: dict[int, list[int]] | None = None) -> None:
    """Ray Tune's function trainable: the trial at index ``config["trial"]``, or with
    `groups` (first index -> the indices of the seeds of one configuration) that trial's
    group side by side (`run_group`)."""
    from ray import tune

    holder = tune.get_context().get_trial_id()
    first = int(config["trial"])
    members = [trials[i] for i in (groups or {}).get(first, [first])]
    rows = run_group(members, inbox, data, holder, tune.report, lambda m: print(f"[{group_name(members)}] {m}",
                                                                                flush=True))
    tune.report(final_metrics(rows))
