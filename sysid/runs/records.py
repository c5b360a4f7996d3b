"""JSON objects mirrored by frozen dataclasses: `JsonRecord` lives in `sysid.records.base`;
its names stay importable here."""
from sysid.records.base import FIX, JsonRecord, read_json_object  # noqa: F401
