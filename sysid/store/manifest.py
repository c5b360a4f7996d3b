"""Completeness manifests: the last file written into a run, preprocessing or reproduction
directory, listing every other file with its size and SHA-256.

A directory without a manifest was interrupted while being written (or comes from an older
sysid); a file that is missing or differs from its checksum was lost or changed afterwards.
Readers call `verify_manifest` and refuse such a directory with one line naming it and the
file at fault. Files added after the manifest (the report ``sysid reproduce`` writes beside
its finished reproduction, and may write again) are not listed and not checked.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path
from typing import Iterable

from sysid.errors import IncompleteOutputError
from sysid.store.files import write_text

MANIFEST = "manifest.json"
FORMAT = "sysid-manifest/1"


def sha256_of(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _entry(path: Path) -> dict:
    return {"bytes": path.stat().st_size, "sha256": sha256_of(path)}


def _listed_files(directory: Path) -> list[Path]:
    """Every regular file below `directory` except this manifest and hidden temporaries."""
    found = []
    for path in directory.rglob("*"):
        rel = path.relative_to(directory)
        if path.is_file() and rel.as_posix() != MANIFEST and not any(p.startswith(".") for p in rel.parts):
            found.append(path)
    return sorted(found)


def write_manifest(directory: str | os.PathLike, kind: str) -> Path:
    """List every file of `directory` (relative path, bytes, SHA-256) in ``manifest.json``.

    `kind` names what the directory is ("run", "preprocessing", "reproduction", "sweep") so a
    reader can refuse the wrong one; the version of sysid that wrote it is recorded beside.
    """
    from sysid import __version__

    directory = Path(directory)
    files = {p.relative_to(directory).as_posix(): _entry(p) for p in _listed_files(directory)}
    doc = {"format": FORMAT, "kind": kind, "sysid": __version__, "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
           "files": files}
    return write_text(json.dumps(doc, indent=1), directory / MANIFEST)


def seed_order(name: str) -> tuple[int, str]:
    """Sort key of seed folder names: seed2 before seed10 (``sysid reproduce --seeds N``'s
    ``seed0``, ``seed1``, ...)."""
    return len(name), name


def seed_run_dirs(directory: str | os.PathLike) -> list[Path]:
    """The seed run directories of a folder of seed runs (``seed*/`` with a manifest), in
    seed order; empty when there are none."""
    return sorted((p for p in Path(directory).glob("seed*") if (p / MANIFEST).is_file()), key=lambda p: seed_order(p.name))


def seed_folder(directory: str | os.PathLike) -> str | None:
    """What to give instead when `directory` is a folder of seed runs (``runs/NAME/seed0``, ...
    of ``sysid reproduce --seeds N``) rather than one run; None otherwise."""
    directory = Path(directory)
    seeds = [p.name for p in seed_run_dirs(directory)]
    if (directory / MANIFEST).exists() or not seeds:
        return None
    return (f"{directory}: a folder of {len(seeds)} seed runs ({', '.join(seeds)}), not one run: give one seed "
            f"({directory / seeds[0]}); sysid compare and sysid maneuver take the folder, its seeds as members of one model")


def read_manifest(directory: str | os.PathLike, what: str = "output") -> dict:
    """The manifest of `directory`, or `IncompleteOutputError` naming what is wrong."""
    directory = Path(directory)
    path = directory / MANIFEST
    if not directory.is_dir():
        raise IncompleteOutputError(f"{directory}: no such directory")
    if not path.is_file() and seed_folder(directory):
        raise IncompleteOutputError(str(seed_folder(directory)))
    if not path.is_file():
        raise IncompleteOutputError(
            f"{directory}: incomplete {what} directory: no {MANIFEST} (it was interrupted while "
            "being written, or written by an older sysid); write it again")
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise IncompleteOutputError(f"{path}: corrupt manifest ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("files"), dict):
        raise IncompleteOutputError(f"{path}: not a sysid manifest (expected format {FORMAT!r})")
    return doc


def verify_manifest(directory: str | os.PathLike, kind: str | None = None,
                    required: Iterable[str] = ()) -> dict:
    """Check that `directory` is complete and unchanged since it was written.

    Refuses (`IncompleteOutputError`, one line naming the directory and the file): no
    manifest, a manifest of another kind, a listed file missing or differing in size or
    SHA-256, or a `required` file not listed. Returns the manifest.
    """
    directory = Path(directory)
    what = kind or "output"
    doc = read_manifest(directory, what)
    if kind is not None and doc.get("kind") != kind:
        raise IncompleteOutputError(f"{directory}: a {doc.get('kind')!r} directory, not a {kind} directory "
                                    f"({MANIFEST} says so)")
    for name in required:
        if name not in doc["files"]:
            raise IncompleteOutputError(f"{directory}: incomplete {what} directory: {name} is missing "
                                        f"(not listed in {MANIFEST})")
    for name, entry in doc["files"].items():
        path = directory / name
        if not path.is_file():
            raise IncompleteOutputError(f"{directory}: incomplete {what} directory: {name} is missing "
                                        f"(listed in {MANIFEST})")
        if not isinstance(entry, dict) or path.stat().st_size != entry.get("bytes") \
                or sha256_of(path) != entry.get("sha256"):
            raise IncompleteOutputError(f"{directory}: {name} does not match its checksum in {MANIFEST} "
                                        "(changed or corrupted after it was written)")
    return doc


def has_manifest(directory: str | os.PathLike) -> bool:
    """Whether `directory` carries a manifest (sysid wrote it completely)."""
    return (Path(directory) / MANIFEST).is_file()
