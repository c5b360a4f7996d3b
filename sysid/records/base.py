"""JSON objects of a run or reproduction directory mirrored by frozen dataclasses.

A `JsonRecord` is parsed once, where the file is read (`from_json`), with one error line
naming the file and the field (`sysid.errors.RecordError`); `to_json` gives back the object key for key, in the order of
the dataclass fields, so that ``json.dumps(record.to_json(), indent=2)`` writes the bytes
sysid has always written. The field types drive both directions: a field typed as another
record (or a tuple of them) nests, ``tuple[...]`` is a JSON array, ``dict[str, ...]`` an
object with free keys (file names, coefficient names), ``X | None`` may be null, and a closed
choice (`sysid.config.choices.Choice`) is its enum, written as the same word it was read from.

Unknown keys are kept, not refused: they are written by a newer sysid (a block added to a
summary) and a reader must still open such a run. They live in `extra` and are written after
the known keys, in their order.
"""
from __future__ import annotations

import dataclasses
import enum
import json
import os
import types
import typing
from pathlib import Path
from typing import Any, ClassVar, Union

from sysid.config.choices import plain_data
from sysid.errors import RecordError

FIX = "the file was changed or comes from another program; write it again with sysid"


def read_json_object(path: Path) -> dict:
    """The JSON object in `path`, or `RecordError` naming the file."""
    if not path.is_file():
        raise RecordError(f"{path}: file not found")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise RecordError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise RecordError(f"{path}: expected a JSON object")
    return data


class JsonRecord:
    """Base of a frozen dataclass mirroring one JSON object (see the module docstring).

    Subclasses declare their fields in the JSON's key order and end with
    ``extra: dict[str, Any] = field(default_factory=dict)``. A field without a default is
    required. ``SPARSE = True``: a None field is left out when written and an absent key
    reads as None (objects whose writer leaves out what it does not know).
    """

    SPARSE: ClassVar[bool] = False
    __dataclass_fields__: ClassVar[dict[str, Any]]  # every subclass is a dataclass
    extra: dict[str, Any]

    @classmethod
    def from_json(cls, data: Any, source: str = "", at: str = "") -> typing.Self:
        """Parse `data` (a JSON object) read from the file `source`; `at` is its key path
        in that file ("gate"), both named in errors."""
        if not isinstance(data, dict):
            raise RecordError(f"{source}: {at or 'the file'}: expected an object, got {_kind(data)}; {FIX}")
        hints = _hints(cls)
        known, values = set(), {}
        for f in dataclasses.fields(cls):
            if f.name == "extra":
                continue
            known.add(f.name)
            key = f"{at}.{f.name}" if at else f.name
            if f.name in data:
                values[f.name] = _parse(data[f.name], hints[f.name], source, key)
            elif not _has_default(f) and not cls.SPARSE:
                raise RecordError(f"{source}: key {key!r} is missing; {FIX}")
            elif not _has_default(f):
                values[f.name] = None
        return cls(**values, extra={k: v for k, v in data.items() if k not in known})  # type: ignore[call-arg]

    @classmethod
    def read(cls, path: str | os.PathLike) -> typing.Self:
        """The record in the JSON file at `path`; `RecordError` naming the file and key."""
        return cls.from_json(read_json_object(Path(path)), str(path))

    def to_text(self) -> str:
        """The JSON file's text, as sysid writes it (indent 2, no final newline)."""
        return json.dumps(self.to_json(), indent=2, default=str)

    def to_json(self) -> dict:
        """The JSON object: known keys in field order (None left out when `SPARSE`), then `extra`."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "extra" or (value is None and self.SPARSE):
                continue
            out[f.name] = _plain(value)
        out.update(self.extra)
        return out


def _has_default(f: dataclasses.Field) -> bool:
    return f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING


_HINTS: dict[type, dict] = {}


def _hints(cls: type) -> dict:
    if cls not in _HINTS:
        _HINTS[cls] = typing.get_type_hints(cls)
    return _HINTS[cls]


def _kind(value: Any) -> str:
    """What a JSON value is, in words."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return "a number"
    return {dict: "an object", list: "an array", str: "a string", bool: "true/false",
            type(None): "null"}.get(type(value), type(value).__name__)


_SCALARS = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}


def _parse(value: Any, hint: Any, source: str, at: str) -> Any:
    """`value` (key path `at` in the file `source`) checked against the type `hint`;
    arrays become tuples, objects of a record type records."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return value
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _parse(value, inner, source, at)
    if isinstance(hint, type) and issubclass(hint, JsonRecord):
        return hint.from_json(value, source, at)
    if isinstance(hint, type) and issubclass(hint, enum.StrEnum):
        words = [m.value for m in hint]
        if not isinstance(value, str) or value not in words:
            raise RecordError(f"{source}: {at}: expected one of {', '.join(words)}, got {_kind(value)} "
                                  f"{value!r:.40}; {FIX}")
        return hint(value)
    if origin is tuple:
        if not isinstance(value, list):
            raise RecordError(f"{source}: {at}: expected an array, got {_kind(value)}; {FIX}")
        return tuple(_parse(v, args[0], source, f"{at}[{i}]") for i, v in enumerate(value))
    if origin is dict:
        if not isinstance(value, dict):
            raise RecordError(f"{source}: {at}: expected an object, got {_kind(value)}; {FIX}")
        return {k: _parse(v, args[1], source, f"{at}.{k}") for k, v in value.items()}
    fits = {bool: lambda v: isinstance(v, bool),
            int: lambda v: isinstance(v, int) and not isinstance(v, bool),
            float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
            str: lambda v: isinstance(v, str)}[hint]
    if not fits(value):
        raise RecordError(f"{source}: {at}: expected {_SCALARS[hint]}, got {_kind(value)} {value!r:.40}; {FIX}")
    return value  # as read (an integral float stays 1.0, an int 1): written back the same


def _plain(value: Any) -> Any:
    """A field value as JSON data (records to objects, choices to their words, tuples to arrays)."""
    return plain_data(value, ((JsonRecord, JsonRecord.to_json),))
