"""Where a command writes: one `OutputTarget`, made at the command line from ``-o``, the
command's inputs, the kind of output and ``--overwrite``, checked before any work and held
(locked) while the command writes.

Refused (`OutputError`: exit 2, one line naming the output and the path at fault):

- an output that is one of the command's inputs (the same file under any name), holds one,
  or lies inside one (a data directory, a run directory read);
- an output that is a symbolic link (the name ``-o`` gives, or a file written into a
  report's folder): writing through it would replace the file it points to, or leave the
  folder named for wherever it leads. Links in the folders above are the user's layout:
  followed, and every check here sees where they lead;
- a path inside a directory sysid sealed with a manifest (a run, a preprocessing output, a
  reproduction, a sweep): its files are listed and checked, nothing else writes there.
  A report is the one addition a command owns: ``report.html`` and ``report.pdf`` inside
  the directory it reports on (`OutputTarget.adds_to`);
- an existing directory, unless ``--overwrite`` and it is a complete sysid output of the
  same kind (`sysid.store.staging.check_replaceable`: sysid's manifest format, the same kind,
  every listed file intact); a file sysid did not name itself (a truth file, a report)
  unless it is sysid's own or ``--overwrite`` says so;
- an output another sysid process is writing: the first holds a lock file beside the
  output (``.NAME.lock``, removed when it is done), the second stops at once.
"""
from __future__ import annotations

import errno
import os
import re
import stat
from contextlib import contextmanager
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Iterable, Iterator

from sysid.errors import IncompleteOutputError, OutputError
from sysid.store.manifest import MANIFEST, read_manifest
from sysid.store.staging import check_parent, check_target, staged_directory

try:
    import fcntl
except ImportError:  # not POSIX: outputs are not locked
    fcntl = None


class OutputKind(str, Enum):
    """What a command writes: one file, a sealed directory of a kind, or a report's two
    files in a folder."""

    FILE = "file"
    RUN = "run"
    PREPROCESSING = "preprocessing"
    REPRODUCTION = "reproduction"
    SWEEP = "sweep"
    MANEUVERS = "maneuvers"
    COMPARISON = "comparison"
    REPORT = "report"

    @property
    def sealed(self) -> bool:
        """A directory written whole and sealed with a manifest of this kind."""
        return self not in (OutputKind.FILE, OutputKind.REPORT)


REPORT_FILES = ("report.html", "report.pdf")

# the JSON record that says what a sealed directory of a kind holds: one name per kind (a
# run's is its summary). Directories written before the kinds had their own names hold theirs
# as LEGACY_RECORD; readers take it there (`record_file`).
RECORD_FILES = {OutputKind.RUN: "summary.json", OutputKind.REPRODUCTION: "reproduction.json",
                OutputKind.SWEEP: "sweep.json", OutputKind.MANEUVERS: "maneuvers.json",
                OutputKind.COMPARISON: "comparison.json"}
LEGACY_RECORD = "summary.json"


def record_file(directory: str | os.PathLike, kind: OutputKind) -> Path:
    """The record file of a `kind` directory: its own name (`RECORD_FILES`), or summary.json
    in a directory written before that name (when only that one is there)."""
    path = Path(directory) / RECORD_FILES[kind]
    legacy = Path(directory) / LEGACY_RECORD
    return legacy if not path.exists() and legacy.exists() else path


def real_path(path: str | os.PathLike) -> Path:
    """Absolute `path` with every link resolved except its last component (the name that
    is written: a link there is refused, not followed)."""
    path = Path(path)
    if path.name in ("", "..") or str(path) == ".":
        return path.resolve()
    return path.absolute().parent.resolve() / path.name


def _within(path: Path, directory: Path) -> bool:
    return path != directory and path.is_relative_to(directory)


def sealed_by(directory: Path) -> str | None:
    """The kind of output sysid sealed `directory` as, or None (no manifest, or another
    program's ``manifest.json``)."""
    if not (directory / MANIFEST).is_file():
        return None
    try:
        return str(read_manifest(directory).get("kind"))
    except (IncompleteOutputError, OSError):
        return None


def is_sysid_report(path: Path) -> bool:
    """Whether `path` is a report.html or report.pdf `sysid report` wrote (its title or
    the PDF's creator say so)."""
    markers = (b"<title>sysid accuracy report", b"<title>sysid maneuvers report") if path.suffix == ".html" \
        else (b"sysid report",)
    try:
        with open(path, "rb") as fh:
            head = fh.read()
            return any(marker in head for marker in markers)
    except OSError:
        return False


@dataclass(frozen=True)
class OutputTarget:
    """One command's output and what it must not touch.

    path : ``-o`` as given (a file, a directory of `kind`, or the folder of a report).
    inputs : every file and directory the command reads (data, configs, ship files, the
        sweep file, the run directory read).
    overwrite : ``--overwrite``: replace a complete sysid output of the same kind (and, for
        a file output, a companion file sysid did not name itself).
    resume : continue an existing output of the same kind (a sweep).
    adds_to : a sealed input directory this command may add its own files to (a report of
        a run or reproduction, written into it).
    companion : the output the user named, when this file is written beside it (synth-raw's
        truth file): an existing file here is replaced only with `overwrite`.
    """

    path: Path
    kind: OutputKind
    inputs: tuple[Path, ...] = ()
    overwrite: bool = False
    resume: bool = False
    adds_to: Path | None = None
    companion: Path | None = None

    @classmethod
    def checked(cls, path: str | os.PathLike, kind: OutputKind | str,
                inputs: Iterable[str | os.PathLike | None] = (), overwrite: bool = False, **options
                ) -> "OutputTarget":
        """The target, checked (`OutputError` on any refusal)."""
        target = cls(Path(path), OutputKind(kind), tuple(Path(p) for p in inputs if p is not None),
                     overwrite, **options)
        target.check()
        return target

    def written(self) -> list[Path]:
        """The paths this command writes or replaces."""
        if self.kind is OutputKind.REPORT:
            return [self.path / name for name in REPORT_FILES]
        return [self.path]

    def check(self) -> None:
        """Refuse this target if it is an input, holds one, lies in one or in a sealed
        directory, is a link, or exists and may not be replaced; create its parent."""
        self.check_place()
        if self.kind is OutputKind.SWEEP:
            self._check_sweep()
        elif self.kind.sealed:
            check_target(self.path, self.overwrite, self.inputs, self.kind.value)
        elif self.kind is OutputKind.REPORT:
            if self.path.exists() and not self.path.is_dir():
                raise OutputError(f"{self.path}: exists and is not a directory; choose another output folder")
            for file in self.written():
                if self._check_existing_file(file) and not is_sysid_report(file):
                    raise OutputError(f"{file}: already exists and is not a report sysid wrote; the report goes "
                                      f"into {self.path}: move that file away or choose another output folder")
            check_parent(self.written()[0])
        else:
            if self._check_existing_file(self.path) and self.companion is not None and not self.overwrite:
                raise OutputError(f"{self.path}: already exists; it is written beside {self.companion}: pass "
                                  "--overwrite to replace it, or choose another output path")
            check_parent(self.path)

    def check_place(self, sealed: bool = True) -> None:
        """The rules for where any output may go, whatever is there: not a link, not one of
        the inputs, holding none and inside none, and (with `sealed`) not inside a
        directory sysid sealed."""
        for path in dict.fromkeys([self.path, *self.written()]):
            self._check_link(path)
        for path in self.written():
            self._check_inputs(path, same=True)
            if sealed:
                self._check_sealed(path)
            self._check_inputs(path, same=False)

    def _check_link(self, path: Path) -> None:
        if path.is_symlink():
            raise OutputError(f"{path}: is a symbolic link to {os.readlink(path)}; writing it would replace "
                              "the file it points to: give the path of a new file instead")

    def _owned(self, path: Path, directory: Path) -> bool:
        """`path` is a report file this command adds to `directory` (its own source)."""
        return (self.kind is OutputKind.REPORT and self.adds_to is not None
                and self.adds_to.resolve() == directory and path.parent == directory)

    def _check_inputs(self, path: Path, same: bool) -> None:
        """`same`: refuse `path` if it is an input; else if it holds or lies inside one."""
        real = real_path(path)
        for given in self.inputs:
            source = given.resolve()
            if same:
                if real == source or (real.exists() and source.exists() and os.path.samefile(real, source)):
                    raise OutputError(f"{path}: is {given}, an input of this command; writing it would destroy "
                                      "that input: choose another output path")
            elif _within(source, real):
                raise OutputError(f"{path}: holds {given}, an input of this command; choose an output path "
                                  "that holds none of its inputs")
            elif _within(real, source) and not self._owned(real, source):
                raise OutputError(f"{path}: lies inside {given}, an input of this command; choose an output "
                                  "path outside it")

    def _check_sealed(self, path: Path) -> None:
        real = real_path(path)
        for directory in real.parents:
            kind = sealed_by(directory)
            if kind is not None and not self._owned(real, directory):
                raise OutputError(f"{path}: lies inside {directory}, a {kind} directory sysid sealed ({MANIFEST}); "
                                  "nothing else is written there: choose a path outside it")

    def _check_sweep(self) -> None:
        """A sweep directory: new or empty; continued with `resume` (the sweep checks its
        sweep file); replaced with `overwrite` only if it is a complete sysid sweep."""
        path = self.path
        if path.is_dir() and any(path.iterdir()) and not self.resume:
            if not self.overwrite:
                raise OutputError(f"{path}: already exists; pass --resume to continue that sweep, --overwrite to "
                                  "replace it, or choose another output path")
            check_target(path, True, self.inputs, self.kind.value)
        elif path.is_symlink() or (path.exists() and not path.is_dir()):
            raise OutputError(f"{path}: exists and is not a directory; choose another output path")
        else:
            check_parent(path)

    def _check_existing_file(self, path: Path) -> bool:
        """Whether `path` exists; refused if it is not a regular file."""
        if not path.exists():
            return False
        if path.is_dir():
            raise OutputError(f"{path}: is a directory; give the path of a file")
        if not path.is_file():
            raise OutputError(f"{path}: exists and is not a regular file; give the path of a new file")
        return True

    # -- writing ---------------------------------------------------------------------------
    def lock_path(self) -> Path:
        """The lock file beside the output: ``.NAME.lock``."""
        real = real_path(self.path)
        return real.parent / f".{real.name}.lock"

    @contextmanager
    def lock(self) -> Iterator["OutputTarget"]:
        """Hold the output's lock while the command writes: a second sysid process on the
        same output is refused at once (`OutputError`); the target is checked again under
        the lock (the first may have finished meanwhile). The lock file is removed at the end."""
        with exclusive_lock(self.lock_path(), self.path):
            self.check()
            yield self

    @contextmanager
    def staged(self) -> Iterator[Path]:
        """A staging directory moved into place, sealed as `kind`, when the block ends
        without an error (`sysid.store.staging.staged_directory`)."""
        with staged_directory(self.path, self.kind.value, self.overwrite, keep=self.inputs) as staging:
            yield staging


_PID_LINE = re.compile(rb"\d{0,10}\n?")  # what sysid writes into its lock files: its process id


def _refuse_lock(target: Path, lock: Path, why: str) -> OutputError:
    return OutputError(f"{target}: its lock file {lock} {why}; sysid creates that file itself and never writes "
                       "through it: move it away, or choose another output path")


def _open_lock(lock: Path, target: Path) -> tuple[int, bool]:
    """The lock file's descriptor, and whether this process created it. A new lock file is
    created exclusively (``O_EXCL``, never through a link); an existing one is opened only if
    it is itself a plain file (``O_NOFOLLOW``, one link)."""
    flags = os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        return os.open(lock, flags | os.O_CREAT | os.O_EXCL, 0o644), True
    except FileExistsError:
        pass
    except OSError as exc:
        raise OutputError(f"{target}: cannot create its lock file {lock} ({exc.strerror})") from None
    if os.path.islink(lock):  # a symbolic link, dangling or not: never followed
        raise _refuse_lock(target, lock, f"is a symbolic link to {os.readlink(lock)}")
    try:
        return os.open(lock, flags), False
    except FileNotFoundError:
        return -1, False  # its holder removed it meanwhile
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise _refuse_lock(target, lock, "is a symbolic link") from None
        raise OutputError(f"{target}: cannot open its lock file {lock} ({exc.strerror})") from None


@contextmanager
def exclusive_lock(lock: Path, target: Path) -> Iterator[None]:
    """An exclusive ``flock`` on the file `lock`, created by this process (``O_EXCL``, never
    through a link) and holding its id, or `OutputError` naming `target` and `lock` if
    another process holds it. The file is removed when the block ends.

    A lock file found in place is one sysid left only if it is a plain file with one link,
    owned by this user, holding nothing but a process id; anything else (a symbolic link,
    dangling or not, a hard link to another file, a file of other content) is refused and
    left untouched. A holder that was killed leaves its file unlocked (the kernel releases
    the lock): the next command removes it and creates its own."""
    if fcntl is None:
        yield
        return
    while True:
        fd, created = _open_lock(lock, target)
        if fd < 0:
            continue
        try:
            found = os.fstat(fd)
            if not stat.S_ISREG(found.st_mode):
                raise _refuse_lock(target, lock, "is not a regular file")
            if found.st_nlink != 1:
                raise _refuse_lock(target, lock, f"is a hard link ({found.st_nlink} names for one file)")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
                raise OutputError(f"{target}: another sysid process (pid {holder}) is writing it (lock {lock}); "
                                  "wait for it to finish or choose another output path") from None
            try:
                still_there = os.lstat(lock).st_ino == found.st_ino
            except FileNotFoundError:
                still_there = False
            if still_there and not created:  # a lock left by a killed sysid: checked, removed, made anew
                if found.st_uid != os.geteuid():
                    raise _refuse_lock(target, lock, f"belongs to another user (uid {found.st_uid})")
                if not _PID_LINE.fullmatch(os.read(fd, 64)):
                    raise _refuse_lock(target, lock, "holds something other than a sysid process id")
                os.unlink(lock)
                still_there = False
        except BaseException:
            os.close(fd)
            raise
        if still_there:
            break  # created here, locked, and still at `lock`: ours
        os.close(fd)
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        try:
            if os.lstat(lock).st_ino == os.fstat(fd).st_ino:
                os.unlink(lock)
        except FileNotFoundError:
            pass
        os.close(fd)
