"""Errors a user sees: each names the file (or config) and the field at fault."""
from __future__ import annotations


class SysidError(Exception):
    """Base class of every error `sysid` raises on bad input."""


class ShipDefinitionError(SysidError):
    """A ship TOML is missing a key, has an out-of-range value, or an override is unknown."""


class DataError(SysidError):
    """A data file is missing, misnamed, or holds NaN, wrong units or non-monotonic time."""


class ConfigError(SysidError):
    """An experiment config is malformed."""


class OptionError(SysidError):
    """A command-line option is not a finite number, or lies outside its range."""


class CheckpointError(SysidError):
    """A run directory or checkpoint is missing or corrupt."""


class IncompleteOutputError(SysidError):
    """An output directory (run, preprocessing, reproduction) is incomplete or was changed
    after it was written: no manifest, a listed file missing, or a checksum mismatch."""


class OutputError(SysidError):
    """An output cannot or must not be written where asked (`sysid.store.target`): it exists
    (without ``--overwrite``, or is not a complete sysid output of its kind), is an input or
    holds or lies in one, is a link, lies in a sealed directory, another sysid is writing
    it, or its directory cannot be created or written."""


class TrainingError(SysidError):
    """Training cannot produce a model: a non-finite loss (too high a learning rate, bad data)."""


class ClusterLostError(SysidError):
    """The Ray cluster a sweep joined went away while it ran (its head stopped answering)."""
