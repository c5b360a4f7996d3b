"""Options shared by the commands that run a ship's MMG (``sysid forces``, ``sysid simulate``,
``sysid evaluate --model mmg``), parsed here once."""
from __future__ import annotations

from typing import List, Optional

import typer

from sysid.errors import DataError

MMG_COMPONENTS = ("hull", "propeller", "rudder", "wind")

ShipOption = typer.Option("esso_osaka", "--ship", help="Ship name (configs/ships/NAME.toml) or path to a ship TOML.")
SetOption = typer.Option(None, "--set", help="Override a ship parameter, e.g. --set Xvr=0.4535 (repeatable).")
QuadratureOption = typer.Option("exact", "--quadrature",
                                help="Cross-flow integrals: exact (closed form) or simpson (the lab simulator's).")
CompiledOption = typer.Option(False, "--compiled",
                              help="Compiled step (native code, cached on disk; first use compiles, about a minute).")


def integrator_of(name: str, compiled: bool):
    """The `Integrator` an ``--integrator`` (and ``--compiled``) option names; exit 2 otherwise."""
    from sysid.config.choices import Method
    from sysid.dynamics.integrators import Integrator

    try:
        return Integrator(Method.parse(name, "--integrator", offered_only=True), compiled)
    except ValueError as exc:
        raise DataError(str(exc)) from None


def mmg_of(ship: str, overrides: Optional[List[str]], quadrature: str):
    """The MMG of a ``--ship`` with its ``--set`` overrides and ``--quadrature``."""
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship, parse_overrides

    if quadrature not in ("exact", "simpson"):
        raise DataError(f"--quadrature {quadrature!r}: choose exact or simpson")
    return MMG(load_ship(ship, parse_overrides(overrides)), quadrature=quadrature)

