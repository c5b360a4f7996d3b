"""The driver's end of a sweep: the only place that reads or writes the sweep's output.

Trials run on any node of a Ray cluster and share nothing with the driver but the network.
A trial trains into a directory of its own node and hands its results to the driver's
`RunInbox` (a Ray actor placed on the driver's node, so it sees ``-o``):

- ``claim``: one training per trial at a time (Optuna may propose a configuration twice
  while the first still trains); a claim belongs to a Tune trial, whose retries take it over.
- ``save_checkpoint`` / ``checkpoint``: the training checkpoint after every epoch, kept
  beside the run directory it belongs to (`sysid.runs.lifecycle.checkpoint_path`), so that a
  trial whose node is lost resumes on another node, and ``--resume`` after a driver kill.
- ``deliver``: the finished run directory as bytes (`pack_run`); unpacked beside its place,
  its manifest verified (every file's SHA-256) and its config compared with the trial's,
  then moved into place complete. The first complete delivery wins.
- ``journal``: one JSON line per trial event in ``trials.log`` (started, resumed, trained,
  reused), with the node that did it.

The class is plain Python (tests use it in-process); `inbox_actor` makes the Ray actor.
"""
from __future__ import annotations

import io
import json
import os
import shutil
import tarfile
import tempfile
import time
import tomllib
from pathlib import Path, PurePosixPath


from sysid.config.experiment import is_ship_path
from sysid.errors import IncompleteOutputError
from sysid.store.files import atomic_path, directory_mode
from sysid.errors import CheckpointError
from sysid.runs.rundir import RunDir
from sysid.runs.lifecycle import checkpoint_path
from sysid.runs.summary import RunSummary

JOURNAL = "trials.log"

# claim answers
TRAIN, WAIT, COMPLETE = "train", "wait", "complete"


def pack_run(run_dir: str | os.PathLike) -> bytes:
    """A run directory as gzip'd tar bytes (regular files and folders only)."""
    run_dir = Path(run_dir)
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz", compresslevel=1) as tar:
        for path in sorted(run_dir.rglob("*")):
            if path.is_file() and not path.is_symlink():
                tar.add(path, arcname=path.relative_to(run_dir).as_posix(), recursive=False)
    return buffer.getvalue()


def unpack_run(blob: bytes, directory: Path) -> None:
    """Write the files of `pack_run` bytes below `directory`, refusing anything but regular
    files at relative paths inside it (no links, devices, absolute or ``..`` paths)."""
    with tarfile.open(fileobj=io.BytesIO(blob), mode="r:gz") as tar:
        for member in tar.getmembers():
            name = PurePosixPath(member.name)
            if not member.isfile() or name.is_absolute() or ".." in name.parts or not name.parts:
                raise IncompleteOutputError(f"a delivered run holds {member.name!r}, which is not a plain file "
                                            "inside the run directory")
            target = directory.joinpath(*name.parts)
            target.parent.mkdir(parents=True, exist_ok=True)
            source = tar.extractfile(member)
            with open(target, "wb") as fh:  # mode from the user's umask, not from the archive
                shutil.copyfileobj(source, fh)


def complete_summary(run_dir: Path) -> RunSummary | None:
    """summary.json of a complete run directory (manifest verified), else None."""
    run = RunDir.complete(run_dir)
    try:
        return run.read_summary() if run is not None else None
    except (CheckpointError, OSError):
        return None


def journal_line(out: str | os.PathLike, event: str, trial_path: str, **extra) -> None:
    """Append one event line to the sweep's journal (one write on an O_APPEND file)."""
    line = json.dumps({"event": event, "trial": trial_path, "time": time.time(), **extra})
    Path(out).mkdir(parents=True, exist_ok=True)
    fd = os.open(Path(out) / JOURNAL, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        os.write(fd, (line + "\n").encode())
    finally:
        os.close(fd)


def read_journal(out: str | os.PathLike) -> list[dict]:
    """Every event of the journal (a torn last line, from a kill mid-write, is skipped)."""
    path = Path(out) / JOURNAL
    events = []
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                events.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return events


USED_FILES = ("train", "validation", "test")  # [data] keys a run's config.toml lists as the files used


def same_trial(written: dict, trial: dict, home: Path | None = None) -> bool:
    """Whether a run's config.toml (`written`) is its trial's resolved config (`trial`),
    both as TOML tables: every option alike except the ``[data]`` file lists, which the run
    writes as the files it used (globs expanded, the test logs named); its ship file,
    named relative to the run directory `home` (`sysid.runs.log_paths`), is compared
    where it points."""
    def options(doc: dict, anchor: Path | None) -> dict:
        experiment = dict(doc.get("experiment", {}))
        ship = experiment.get("ship")
        if anchor is not None and isinstance(ship, str) and is_ship_path(ship) and not os.path.isabs(ship):
            experiment["ship"] = os.path.normpath(os.path.join(Path(anchor).resolve(), ship))   # as load_experiment
        return {**doc, "experiment": experiment,
                "data": {k: v for k, v in doc.get("data", {}).items() if k not in USED_FILES}}
    return options(written, home) == options(trial, None)


class RunInbox:
    """Receives what trials make and keeps the sweep's output directory `out` (an absolute
    path on the driver's node). Every method is called one at a time (a Ray actor)."""

    def __init__(self, out: str):
        self.out = Path(out)
        self.claims: dict[str, str] = {}   # trial path -> holder (a Tune trial id)

    def _run_dir(self, path: str) -> Path:
        parts = PurePosixPath(path).parts
        if not parts or PurePosixPath(path).is_absolute() or ".." in parts:
            raise ValueError(f"trial path {path!r} is not inside the sweep's output")
        return self.out.joinpath(*parts)

    def place(self, path: str) -> str:
        """Where the run of trial `path` will live (the home its logs are recorded relative
        to while it is written in a trial's scratch directory)."""
        return str(self._run_dir(path))

    # -- one training per trial ------------------------------------------------------
    def claim(self, path: str, holder: str) -> str:
        """COMPLETE if the run is there; TRAIN (claimed for `holder`) if nobody else trains
        it; WAIT if another Tune trial does (ask again later)."""
        if complete_summary(self._run_dir(path)) is not None:
            return COMPLETE
        owner = self.claims.get(path)
        if owner is not None and owner != holder:
            return WAIT
        self.claims[path] = holder
        return TRAIN

    def release(self, holder: str) -> None:
        """Drop every claim of a Tune trial that has ended (done, stopped or failed)."""
        self.claims = {p: h for p, h in self.claims.items() if h != holder}

    # -- what a finished or interrupted trial left ---------------------------------------
    def summary(self, path: str) -> RunSummary | None:
        return complete_summary(self._run_dir(path))

    def history(self, path: str) -> list[dict]:
        """The epochs of a complete run (history.csv rows; none for an untrained run)."""
        history = RunDir(self._run_dir(path)).read_history()
        return history.to_dict("records") if history is not None else []

    def checkpoint(self, path: str) -> bytes | None:
        """The training checkpoint of an interrupted trial, as bytes (None: none)."""
        file = checkpoint_path(self._run_dir(path))
        return file.read_bytes() if file.is_file() else None

    def save_checkpoint(self, path: str, holder: str, blob: bytes) -> bool:
        """Keep a trial's latest training checkpoint (only from the trial that claims it)."""
        if self.claims.get(path) != holder:
            return False
        with atomic_path(checkpoint_path(self._run_dir(path)), ".pt") as tmp:
            tmp.write_bytes(blob)
        return True

    # -- the finished run ----------------------------------------------------------------
    def deliver(self, path: str, holder: str, blob: bytes, config: str, node: str = "") -> RunSummary:
        """Unpack a finished run next to its place, verify it, move it into place; its
        summary. A run already complete there is kept (the first delivery wins)."""
        target = self._run_dir(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        arriving = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.arriving-"))
        try:
            os.chmod(arriving, directory_mode())
            unpack_run(blob, arriving)
            run = RunDir.open(arriving)
            if not same_trial(run.read_config(), tomllib.loads(config), target):
                raise IncompleteOutputError(f"{target}: the delivered run was trained with another config "
                                            "than its trial's; not kept")
            summary = run.read_summary()
            if complete_summary(target) is None:
                if target.exists():  # an incomplete leftover (not sysid's move): set aside, never mixed in
                    os.rename(target, target.with_name(f".{target.name}.incomplete-{os.getpid()}-{time.time_ns()}"))
                os.rename(arriving, target)
                journal_line(self.out, "trained", path, node=node, val_loss_multistep=summary.val_loss_multistep)
            else:
                summary = complete_summary(target)
        finally:
            if arriving.exists():
                shutil.rmtree(arriving, ignore_errors=True)
        checkpoint_path(target).unlink(missing_ok=True)
        if self.claims.get(path) == holder:
            del self.claims[path]
        return summary

    def journal(self, event: str, path: str, **extra) -> None:
        journal_line(self.out, event, path, **extra)

    def ready(self) -> bool:
        return True


def inbox_actor(out: str | os.PathLike):
    """A `RunInbox` as a named Ray actor on this (the driver's) node, using no CPU; its
    handle and name (trials find it by name, so nothing Tune saves holds a live handle)."""
    import uuid

    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    here = ray.get_runtime_context().get_node_id()
    name = f"sysid-inbox-{uuid.uuid4().hex[:12]}"
    actor = ray.remote(RunInbox).options(
        name=name, num_cpus=0, max_restarts=0,
        scheduling_strategy=NodeAffinitySchedulingStrategy(node_id=here, soft=False)).remote(str(out))
    ray.get(actor.ready.remote())  # type: ignore[attr-defined]
    return actor, name
