"""Each command's output target (`sysid.store.target.OutputTarget`): what the command
reads, collected from its options (the output must be none of these paths, hold none, lie
in none), and the target's lock, held until the command ends (`hold`, released by
`sysid.cli.run` whatever the outcome)."""
from __future__ import annotations

import glob
import os
from contextlib import ExitStack
from pathlib import Path

_held = ExitStack()
_made: list[Path] = []   # folders the command's outputs created, deepest first: removed if it fails


def hold(target):
    """Lock `target` (`OutputTarget.lock`: a second sysid on it is refused) until the
    running command ends; returns it."""
    _held.enter_context(target.lock())
    return target


def claim(path: str | os.PathLike, kind, inputs=(), overwrite: bool = False, **options):
    """The command's output target (`OutputTarget.checked`: `kind` an `OutputKind`), checked
    and held (`hold`)."""
    from sysid.store.target import OutputKind, OutputTarget

    folder = Path(path) if OutputKind(kind) is OutputKind.REPORT else Path(path).parent
    missing = [p for p in [folder.absolute(), *folder.absolute().parents] if not p.exists()]
    _made.extend(missing)  # before the check, which creates them
    return hold(OutputTarget.checked(path, kind, inputs, overwrite, **options))


def release(failed: bool = False) -> None:
    """Release every lock the command took (its lock files removed); `failed`: also remove
    the folders its outputs created, if still empty (a refused command leaves no folder)."""
    _held.close()
    if failed:
        for folder in _made:
            try:
                os.rmdir(folder)
            except OSError:  # not empty, or gone: left as it is
                pass
    _made.clear()


def ship_file(name_or_path: str | os.PathLike) -> Path | None:
    """The ship TOML a ``--ship`` option reads, or None when it names no ship (loading the
    ship says why)."""
    from sysid.errors import ShipDefinitionError
    from sysid.mmg.ship import resolve_ship_path

    try:
        return resolve_ship_path(name_or_path)
    except ShipDefinitionError:
        return None


def experiment_inputs(exp, data: str | os.PathLike | None = None) -> list[Path]:
    """The files an experiment reads: its config, its ship, its logs (``[data] train``,
    ``validation`` and ``test``, patterns expanded), or the dataset's data directory (a paper
    data set, `sysid.data.splits`)."""
    from sysid.data.datasets import data_dir
    from sysid.data.recordings import expand_paths

    paths = [Path(exp.source)] if exp.source and Path(exp.source).is_file() else []
    paths.append(ship_file(exp.experiment.ship))
    listed = exp.data.train + exp.data.validation + exp.data.test
    paths += [p for f in listed for p in (expand_paths([f]) if glob.has_magic(f) else [Path(f)])]
    if exp.experiment.dataset or (exp.needs_training and not exp.data.train):
        paths.append(data_dir(data))
    return [p for p in paths if p is not None]
