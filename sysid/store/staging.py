"""Output directories written all-or-nothing: a fresh hidden staging directory beside the
target, filled, sealed with a manifest (`sysid.store.manifest`), then moved into place.

An interrupted or failed job leaves nothing where the output belongs (the staging
directory is removed). An existing target is refused unless the caller allows
``overwrite``; then the whole old directory is replaced, so no file of an earlier job
survives beside the new ones. `check_target` answers the same questions before a long job
starts, so a bad ``-o`` fails in a second, not after training. `sysid.store.target` adds
what a command knows beyond the directory itself (its inputs, sealed directories, links,
other processes).
"""
from __future__ import annotations

import os
import shutil
import tempfile
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Iterator

from sysid.errors import IncompleteOutputError, OutputError
from sysid.store.files import directory_mode
from sysid.store.manifest import FORMAT, MANIFEST, read_manifest, verify_manifest, write_manifest


def _inside(path: Path, directory: Path) -> bool:
    try:
        path.resolve().relative_to(directory.resolve())
    except ValueError:
        return False
    return True


def check_target(target: str | os.PathLike, overwrite: bool = False, keep: Iterable[str | os.PathLike] = (),
                 kind: str | None = None) -> Path:
    """Refuse an output directory that cannot or must not be written (`OutputError`, one line).

    Refused: a target that is a file or a link; an existing directory without `overwrite`;
    with `overwrite`, a non-empty directory that is not a complete sysid output of `kind`
    (`check_replaceable`), or one holding the working directory or any path in `keep` (the
    job's inputs); a parent that cannot be created or written.
    """
    target = Path(target)
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise OutputError(f"{target}: exists and is not a directory; choose another output path")
    if target.is_dir():
        if not overwrite:
            raise OutputError(f"{target}: already exists; pass --overwrite to replace the whole directory, "
                              "or choose another output path")
        if any(target.iterdir()):
            check_replaceable(target, kind)
        for inner in [Path.cwd(), *map(Path, keep)]:
            if _inside(inner, target):
                raise OutputError(f"{target}: --overwrite would delete {inner}, which this job needs; "
                                  "choose another output path")
    check_parent(target)
    return target


def check_replaceable(target: Path, kind: str | None) -> dict:
    """Refuse (`OutputError`) to replace `target` unless it is a complete sysid output of
    `kind` (any kind if None): its manifest is sysid's format, says `kind`, and every file it
    lists is intact. Returns the manifest."""
    manifest = target / MANIFEST
    refusal = "--overwrite only replaces complete sysid outputs: remove it yourself or choose another path"
    if not manifest.is_file():
        raise OutputError(f"{target}: exists and was not written by sysid (no {MANIFEST}); {refusal}")
    try:
        doc = read_manifest(target)
    except IncompleteOutputError:
        raise OutputError(f"{target}: exists and was not written by sysid ({manifest} is not a sysid "
                          f"manifest: no format {FORMAT!r}); {refusal}") from None
    if kind is not None and doc.get("kind") != kind:
        raise OutputError(f"{target}: a {doc.get('kind')!r} output ({manifest} says so), not a {kind} "
                          f"directory; {refusal}")
    try:
        return verify_manifest(target, kind)
    except IncompleteOutputError as exc:
        detail = str(exc).removeprefix(f"{target}: ")
        raise OutputError(f"{target}: not a complete sysid output ({detail}); {refusal}") from None


def check_parent(target: str | os.PathLike) -> Path:
    """Create the parent directory of `target` and check that it can be written in
    (`OutputError` naming both when not)."""
    target = Path(target)
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{target}: cannot create the directory {parent}: a file of that name exists") from None
    except OSError as exc:
        raise OutputError(f"{target}: cannot create the directory {parent} ({exc.strerror})") from None
    try:  # the real test (permissions, read-only file systems, /proc): make and remove a directory
        os.rmdir(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.probe-"))
    except OSError as exc:
        raise OutputError(f"{target}: cannot write in {parent} ({exc.strerror})") from None
    return target


def _move_into_place(staging: Path, target: Path, overwrite: bool, kind: str) -> None:
    old = None
    if target.exists() or target.is_symlink():
        check_target(target, overwrite, kind=kind)  # something appeared while the job ran
        old = target.with_name(f".{target.name}.replaced-{uuid.uuid4().hex[:8]}")
        os.rename(target, old)
    try:
        os.rename(staging, target)
    except OSError:
        if old is not None:
            os.rename(old, target)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextmanager
def staged_directory(target: str | os.PathLike, kind: str, overwrite: bool = False,
                     keep: Iterable[str | os.PathLike] = ()) -> Iterator[Path]:
    """Yield a fresh staging directory for `target`; on success seal it with a manifest of
    `kind` and move it into place (replacing `target` if `overwrite`); on any exception or
    interruption remove it and leave `target` as it was."""
    target = check_target(target, overwrite, keep, kind)
    try:
        staging = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.staging-"))
    except OSError as exc:
        raise OutputError(f"{target}: cannot write in {target.parent} ({exc.strerror})") from None
    try:
        os.chmod(staging, directory_mode())  # mkdtemp's 0700 is for the staging phase only
        yield staging
        write_manifest(staging, kind)
        try:
            _move_into_place(staging, target, overwrite, kind)
        except OSError as exc:
            raise OutputError(f"{target}: cannot move the finished output into place ({exc.strerror})") from None
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
