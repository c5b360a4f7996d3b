"""The `sysid` typer application; each ``*_commands`` module registers its commands on it."""
from __future__ import annotations

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode=None,
                  pretty_exceptions_enable=False,
                  help="Ship maneuvering system identification: MMG, hybrid MMG+FNN, reports.")
