"""Writing the files of a new project (`sysid init`): all of them or none, never over a file
that exists."""
from __future__ import annotations

from pathlib import Path

from sysid.errors import OutputError
from sysid.store.files import write_text

SUBFOLDERS = ("logs", "test")  # where the next steps ask for the training and test logs


def write_project(project) -> list[Path]:
    """Write `project.files` (name -> text) into `project.folder` and create its log folders;
    `OutputError` naming the first file that exists (or is not a regular path) before anything
    is written. Returns the files written."""
    folder = Path(project.folder)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"{folder}: exists and is not a folder; give a new or existing folder for the project")
    targets = [folder / name for name in project.files]
    for path in targets:
        if path.exists() or path.is_symlink():
            raise OutputError(f"{path}: already exists; sysid init never overwrites a file: move it away or "
                              "choose another folder")
    folder.mkdir(parents=True, exist_ok=True)
    for sub in SUBFOLDERS:
        if not (folder / sub).exists():
            (folder / sub).mkdir()
    written: list[Path] = []
    try:
        for path, text in zip(targets, project.files.values()):
            written.append(write_text(text, path))
    except BaseException:
        for path in written:  # all or none
            path.unlink(missing_ok=True)
        raise
    return targets
