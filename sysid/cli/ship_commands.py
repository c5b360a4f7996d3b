"""``sysid ship check FILE``: validate a ship file and print what it implies."""
from __future__ import annotations

import typer

from sysid.cli.app import app
from sysid.ship import load_ship
from sysid.ship_check import check_ship

ship_app = typer.Typer(no_args_is_help=True, help="Ship definitions: check a ship file.")
app.add_typer(ship_app, name="ship")


@ship_app.command("check")
def check(ship: str = typer.Argument(..., help="Ship TOML file or bundled ship name.")) -> None:
    """Validate FILE and print derived quantities (non-dimensional masses, course stability,
    propeller and rudder geometry) and warnings; exit code 2 with one line on bad input."""
    typer.echo(check_ship(load_ship(ship)).text())
