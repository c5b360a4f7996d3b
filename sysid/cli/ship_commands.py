"""``sysid ship check FILE``: validate a ship file and print what it implies."""
from __future__ import annotations

import typer

from sysid.cli.app import app

ship_app = typer.Typer(no_args_is_help=True, help="Ship definitions: check a ship file.")
app.add_typer(ship_app, name="ship")


@ship_app.command("check")
def check(ship: str = typer.Argument(..., help="Ship TOML file or bundled ship name.")) -> None:
    """Validate FILE and print derived quantities (non-dimensional masses, course stability,
    propeller and rudder geometry) and warnings; exit code 2 with one line on bad input."""
    from sysid.mmg.ship import load_ship  # with the force models, torch: only when the command runs
    from sysid.mmg.ship_check import check_ship

    typer.echo(check_ship(load_ship(ship)).text())
