"""Reading a TOML file (experiment configs, ship files, sweep files): one reader, one clear
line for a missing, non-UTF-8 or malformed file, naming the file."""
from __future__ import annotations

import os
import tomllib
from pathlib import Path

from sysid.errors import ConfigError, SysidError


def read_toml(path: str | os.PathLike, what: str = "config file",
              error: type[SysidError] = ConfigError) -> tuple[dict, str]:
    """The parsed document of the TOML file `path` and its text.

    what : the kind of file, for messages ("config file", "ship file", "sweep file").
    error : the `SysidError` raised, with one line naming the file and the fault.
    """
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: {what} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: not UTF-8 text (binary, or another encoding such as UTF-16); "
                    f"a {what} is a UTF-8 TOML file") from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({exc})") from None
