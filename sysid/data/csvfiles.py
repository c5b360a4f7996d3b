"""Reading a CSV or Parquet file a user hands to sysid: one clear error naming the file when
it is empty, binary, not UTF-8 (a UTF-16 export), not parseable, or (Parquet) when pyarrow
is not installed."""
from __future__ import annotations

import codecs
import csv
import os
from pathlib import Path

import pandas as pd

from sysid.errors import DataError

_UTF16_MARKS = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE, codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE)


def not_a_file(path: str | os.PathLike) -> str:
    """Why `path`, which is no regular file, cannot be read: "file not found", or what it is
    instead (a directory, a named pipe, a socket, a device)."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except OSError:
        return "file not found"
    kinds = ((stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"))
    if stat.S_ISDIR(mode):
        return "is a directory, not a file"
    kind = next((name for test, name in kinds if test(mode)), None)
    if kind is None:
        return "file not found"
    return f"is {kind}, not a regular file; sysid reads a log more than once: save it to a file and give that"


def text_problem(path: Path) -> str | None:
    """Why the file is no UTF-8 text (None when it looks like text), from its first 64 KiB."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if not head:
        return "empty file"
    if head.startswith(_UTF16_MARKS):
        return "UTF-16/32 encoded; save it as UTF-8 CSV"
    if b"\x00" in head:
        return "binary, not a text CSV"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not just a character cut at the 64 KiB boundary
            return "not UTF-8 text (binary, or another encoding); save it as UTF-8 CSV"
    return None


def read_csv_table(path: str | os.PathLike, expect: str = "a CSV with a header row") -> pd.DataFrame:
    """A CSV file as a DataFrame, or `DataError` naming the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: {not_a_file(path)}")
    problem = text_problem(path)
    if problem:
        raise DataError(f"{path}: {problem} (expected {expect})")
    try:
        return pd.read_csv(path, encoding="utf-8")
    except pd.errors.EmptyDataError:
        raise DataError(f"{path}: no header row (expected {expect})") from None
    except UnicodeDecodeError:
        raise DataError(f"{path}: not UTF-8 text (binary, or another encoding); save it as UTF-8 CSV") from None
    except pd.errors.ParserError as exc:
        raise DataError(f"{path}: not a readable CSV ({str(exc).strip()})") from None


PARQUET_SUFFIXES = (".parquet", ".pq")
LOG_SUFFIXES = (".csv",) + PARQUET_SUFFIXES


def read_parquet_table(path: str | os.PathLike, expect: str = "a Parquet table") -> pd.DataFrame:
    """A Parquet file as a DataFrame (pandas with pyarrow), or `DataError` naming the file."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: {not_a_file(path)}")
    try:
        import pyarrow  # noqa: F401  (pandas reads Parquet through it)
    except ImportError:
        raise DataError(f"{path}: reading Parquet needs pyarrow: pip install 'sysid[parquet]' "
                        "(or save the log as CSV)") from None
    try:
        return pd.read_parquet(path)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several kinds for a bad file
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
        raise DataError(f"{path}: not a readable Parquet file ({reason}) (expected {expect})") from None


def record_lines(path: str | os.PathLike) -> list[int]:
    """The line (from 1, as a text editor numbers them) on which each record of a CSV file that
    `pd.read_csv` keeps begins, the header's first: a line holding nothing but spaces or tabs
    is skipped as pandas skips it, and a quoted cell over several lines counts them all."""
    lines: list[int] = []
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as fh:
        reader = csv.reader(fh)
        begins = 1
        for record in reader:
            if any(cell.strip(" \t") for cell in record) or len(record) > 1:
                lines.append(begins)
            begins = reader.line_num + 1
    return lines


def row_name(path: str | os.PathLike, index: int) -> str:
    """Where the data row at position `index` (from 0) of a table read by `read_table` is,
    for messages: "line N" of a CSV file, N the line a text editor shows (the file's header
    line counted, and every blank line pandas skipped before the row), "row N" of a Parquet
    table (N = index + 1)."""
    if Path(path).suffix.lower() in PARQUET_SUFFIXES:
        return f"row {int(index) + 1}"
    try:
        lines = record_lines(path)
    except (OSError, csv.Error):   # unreadable now: the position pandas counted
        lines = []
    if int(index) + 1 < len(lines):
        return f"line {lines[int(index) + 1]}"
    return f"line {int(index) + 2}"


def read_table(path: str | os.PathLike, expect: str = "a table with a header row") -> pd.DataFrame:
    """A log as a DataFrame: Parquet for ``.parquet``/``.pq`` files, CSV otherwise."""
    if Path(path).suffix.lower() in PARQUET_SUFFIXES:
        return read_parquet_table(path, expect)
    return read_csv_table(path, expect)
