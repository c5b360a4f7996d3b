"""Training checkpoints: the whole training state at the end of an epoch, so that an
interrupted training continues to the same final model as an uninterrupted one.

Written atomically (temporary file, then rename) with plain tensors, numbers and strings
only, so that ``torch.load(..., weights_only=True)`` reads it. Each of its tensor tables (the
model's state, the best state, Adam's moments) is stored packed: one flat tensor per dtype
and one layout string (`pack`), so that a save pickles a handful of tensors, not about two
hundred (the MMG's coefficients are scalars of their own in a state dict). Version 1 files
(every tensor on its own) still read.

A checkpoint belongs to the resolved experiment TOML it was made with (``config``). Its logs
and ship file are named there by absolute path, so it also keeps their SHA-256 (``files``,
`files_of`): after the project folder is moved, the checkpoint still belongs to a config with
the same options whose files hold the same bytes at their new paths (`TrainingCheckpoint.load`).
"""
from __future__ import annotations

import enum
import io
import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import torch

try:  # torch's flatten of a tensor list (one C++ call, its DDP buckets'): torch.cat of the flattened tensors
    from torch._utils import _flatten_dense_tensors as _flatten  # in about a third of the time for many small ones
except ImportError:  # a private name: where a torch has it no more, the same values by torch.cat
    def _flatten(tensors):
        return torch.cat([t.reshape(-1) for t in tensors])

from sysid.errors import CheckpointError
from sysid.store.files import atomic_path

FILE_KEYS = ("train", "validation", "test")   # the [data] lists a checkpoint keeps the bytes of

VERSION = 2
VERSIONS = (1, 2)   # the layouts `TrainingCheckpoint.load` reads: 1 tensor by tensor, 2 packed


def plain(value):
    """`value` with numpy scalars turned into Python numbers and enum members into their
    values (weights_only-safe)."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, torch.Tensor):
        return value.item()
    return value


def pack(tensors: dict) -> dict:
    """The tensors of `tensors` (name -> tensor) as ``{"layout": str, "values": {dtype:
    1-D tensor}}``: each dtype's tensors flattened one after another in the dict's order, and
    a layout line "name<TAB>dtype<TAB>shape" per tensor (shape "64,9"; "" for a scalar).
    `unpack` gives back equal tensors (contiguous, each its own storage)."""
    lines, parts = [], {}
    for name, t in tensors.items():
        dtype = str(t.dtype)[6:]   # "torch.float32" -> "float32"
        lines.append(f"{name}\t{dtype}\t{','.join(map(str, t.shape))}")
        parts.setdefault(dtype, []).append(t)
    with torch.no_grad():
        values = {d: _flatten(ts) for d, ts in parts.items()}
    return {"layout": "\n".join(lines), "values": values}


def unpack(packed, source: str | os.PathLike, key: str) -> dict:
    """The tensors (name -> tensor) of `pack`'s `packed`; one `CheckpointError` line naming the
    file and `key` when it is not such a table."""
    bad = CheckpointError(f"{source}: training checkpoint's {key!r} is not a packed tensor table; "
                          "delete it to start afresh")
    if not (isinstance(packed, dict) and isinstance(packed.get("layout"), str)
            and isinstance(packed.get("values"), dict)):
        raise bad
    offsets = dict.fromkeys(packed["values"], 0)
    tensors = {}
    try:
        for line in packed["layout"].split("\n") if packed["layout"] else ():
            name, dtype, dims = line.split("\t")
            shape = [int(n) for n in dims.split(",")] if dims else []
            size = math.prod(shape)
            flat, at = packed["values"][dtype], offsets[dtype]
            if (not isinstance(flat, torch.Tensor) or flat.dim() != 1 or str(flat.dtype)[6:] != dtype
                    or size < 0 or at + size > flat.numel()):
                raise bad
            tensors[name] = flat[at:at + size].reshape(shape).clone()
            offsets[dtype] = at + size
    except (ValueError, KeyError, RuntimeError):
        raise bad from None
    if any(not isinstance(packed["values"][d], torch.Tensor) or packed["values"][d].numel() != n
           for d, n in offsets.items()):
        raise bad
    return tensors


STAGES = ("identify", "train")


@dataclass(frozen=True)
class CheckpointState:
    """The state of a training stage at the end of an epoch, all that a resumed stage needs
    to continue to the model an uninterrupted one gives.

    stage : "identify" | "train"; epoch : the last finished one (from 1);
    model, optimizer : state dicts; scheduler : the learning-rate schedule's ({} without);
    generator : the minibatch order's random state (uint8 tensor);
    best_loss, best_epoch, best_state : the best validation loss so far, its epoch and its
    weights (None before the first epoch improved on inf);
    stage_history : this stage's history rows; history : the rows of earlier stages;
    summary : the trainer's `TrainingSummary.to_dict()` so far.
    """

    stage: str
    epoch: int
    model: dict
    optimizer: dict
    scheduler: dict
    generator: torch.Tensor
    best_loss: float
    best_epoch: int
    best_state: dict | None
    stage_history: list
    history: list
    summary: dict

    def to_state_dict(self) -> dict:
        """The checkpoint's keys after ``version`` and ``config``, in this order."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def to_packed(self) -> dict:
        """`to_state_dict` as a version-2 file holds it: the model's state, the best state
        and the optimizer's per-parameter state `pack`ed, the rest `plain`."""
        opt = self.optimizer
        return {"stage": self.stage, "epoch": self.epoch, "model": pack(self.model),
                "optimizer": {"state": pack({f"{i}/{k}": t for i, s in opt["state"].items() for k, t in s.items()}),
                              "param_groups": plain(opt["param_groups"])} if opt else {},
                "scheduler": plain(self.scheduler), "generator": self.generator, "best_loss": plain(self.best_loss),
                "best_epoch": plain(self.best_epoch),
                "best_state": pack(self.best_state) if self.best_state is not None else None,
                "stage_history": plain(self.stage_history), "history": plain(self.history),
                "summary": plain(self.summary)}

    @classmethod
    def from_state_dict(cls, state: dict, source: str | os.PathLike) -> "CheckpointState":
        """The state in `state` (read from the file `source`; a version-2 file's tables
        unpacked); one `CheckpointError` line naming the file and the key when one is missing
        or of the wrong kind."""
        if state.get("version") == 2:
            state = _unpacked(state, source)
        kinds = {"stage": str, "epoch": int, "model": dict, "optimizer": dict, "scheduler": dict,
                 "generator": torch.Tensor, "best_loss": (int, float), "best_epoch": int,
                 "best_state": (dict, type(None)), "stage_history": list, "history": list, "summary": dict}
        for f in fields(cls):
            if f.name not in state:
                raise CheckpointError(f"{source}: training checkpoint has no {f.name!r}; delete it to start afresh")
            if not isinstance(state[f.name], kinds[f.name]) or isinstance(state[f.name], bool):
                raise CheckpointError(f"{source}: training checkpoint's {f.name!r} is a "
                                      f"{type(state[f.name]).__name__}; delete it to start afresh")
        if state["stage"] not in STAGES:
            raise CheckpointError(f"{source}: training checkpoint of unknown stage {state['stage']!r} "
                                  f"(expected one of {', '.join(STAGES)}); delete it to start afresh")
        return cls(**{f.name: state[f.name] for f in fields(cls)})


def _unpacked(state: dict, source: str | os.PathLike) -> dict:
    """A version-2 file's `state` with its packed tables as state dicts (version 1's layout)."""
    state = dict(state)
    for key in ("model", "best_state"):
        if isinstance(state.get(key), dict):
            state[key] = unpack(state[key], source, key)
    opt = state.get("optimizer")
    if isinstance(opt, dict) and "state" in opt:
        per_param: dict = {}
        for name, t in unpack(opt["state"], source, "optimizer").items():
            index, _, key = name.partition("/")
            if not index.isdigit():
                raise CheckpointError(f"{source}: training checkpoint's 'optimizer' names a state {name!r}; "
                                      "delete it to start afresh")
            per_param.setdefault(int(index), {})[key] = t
        state["optimizer"] = {"state": per_param, "param_groups": opt.get("param_groups")}
    return state


class TrainingCheckpoint:
    """One file holding the `CheckpointState` of the running training stage, with
    ``version``, ``config`` (the resolved experiment TOML it belongs to) and ``files`` (the
    SHA-256 of the files the config names, `files_of`; None: not known) before it."""

    def __init__(self, path: str | os.PathLike, config: str, files: dict[str, list[str]] | None = None):
        self.path = Path(path)
        self.config = config
        self.files = files

    def save(self, state: CheckpointState) -> None:
        # serialized in memory, then one write: torch's zip writer on a path writes record by
        # record (about a fifth slower for a ~300 kB checkpoint)
        buffer = io.BytesIO()
        files = {"files": self.files} if self.files is not None else {}
        torch.save({"version": VERSION, "config": self.config, **files, **state.to_packed()}, buffer)
        with atomic_path(self.path, ".pt") as tmp:
            tmp.write_bytes(buffer.getbuffer())

    def load(self) -> CheckpointState | None:
        """The saved state, None when there is none; refuses another config's checkpoint."""
        if not self.path.is_file():
            return None
        try:
            state = torch.load(self.path, map_location="cpu", weights_only=True)
        except Exception as exc:  # truncated or not a checkpoint
            raise CheckpointError(f"{self.path}: not a readable training checkpoint "
                                  f"({type(exc).__name__}); delete it to start afresh") from None
        if not isinstance(state, dict) or state.get("version") not in VERSIONS:
            raise CheckpointError(f"{self.path}: not a sysid training checkpoint (version "
                                  f"{state.get('version') if isinstance(state, dict) else '?'})")
        if not self.belongs(state.get("config"), state.get("files")):
            raise CheckpointError(f"{self.path}: made with another config; delete it or train without --resume")
        return CheckpointState.from_state_dict(state, self.path)

    def belongs(self, config, files) -> bool:
        """Whether a checkpoint saved with `config` and `files` is this config's: the same
        TOML, or (a project moved since) the same options but for the paths of its ship file
        and logs, whose bytes are those `files` recorded."""
        if config == self.config:
            return True
        if not isinstance(config, str) or files is None or files != self.files:
            return False
        placeless = _without_paths(self.config)
        return placeless is not None and _without_paths(config) == placeless

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


def _without_paths(config: str) -> dict | None:
    """A resolved experiment TOML without the paths `files_of` stands for (a ship file's,
    the [data] lists); None when it is not TOML."""
    import tomllib

    from sysid.config.experiment import is_ship_path

    try:
        doc = tomllib.loads(config)
    except tomllib.TOMLDecodeError:
        return None
    experiment = dict(doc.get("experiment", {}))
    if is_ship_path(str(experiment.get("ship", ""))):
        experiment.pop("ship")
    data = {k: v for k, v in doc.get("data", {}).items() if k not in FILE_KEYS}
    return {**doc, "experiment": experiment, "data": data}


def files_of(exp) -> dict[str, list[str]] | None:
    """The SHA-256 of the files the `Experiment` `exp` names by path: its ship file
    (``"ship"``: a bundled ship's too) and each [data] list's logs (patterns and folders
    expanded, in order); None when one of them cannot be read."""
    from sysid.data.recordings import expand_paths
    from sysid.errors import DataError, ShipDefinitionError
    from sysid.mmg.ship import resolve_ship_path
    from sysid.store.manifest import sha256_of

    try:
        out = {"ship": [sha256_of(resolve_ship_path(exp.experiment.ship))]}
        for key in FILE_KEYS:
            out[key] = [sha256_of(p) for p in expand_paths(list(getattr(exp.data, key)))]
    except (DataError, ShipDefinitionError, OSError):
        return None
    return out


class Checkpointing:
    """The checkpointing part of training: the state a fit resumes from (read once by
    `start`) and the `CheckpointState` written after every epoch; none of either without
    a file."""

    def __init__(self, path: str | os.PathLike | None, config: str, resume: bool = False,
                 files: dict[str, list[str]] | None = None):
        self.file = TrainingCheckpoint(path, config, files) if path else None
        self.resume = resume
        self.resumed: CheckpointState | None = None

    @property
    def path(self) -> Path | None:
        return self.file.path if self.file is not None else None

    def start(self) -> CheckpointState | None:
        """The saved state to resume from (None: none, or not resuming)."""
        self.resumed = self.file.load() if self.file is not None and self.resume else None
        return self.resumed

    def stage(self, label: str) -> CheckpointState | None:
        """The saved state of stage `label`, when the fit resumes inside it."""
        return self.resumed if self.resumed is not None and self.resumed.stage == label else None

    def save(self, state: CheckpointState) -> None:
        if self.file is not None:
            self.file.save(state)
