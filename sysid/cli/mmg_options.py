"""Options shared by the commands that run a ship's MMG (``sysid forces``, ``sysid simulate``,
``sysid evaluate --model mmg``), parsed here once."""
from __future__ import annotations

from typing import List, Optional

import typer

from sysid.errors import DataError
from sysid.fast.payoff import PREDICTION_REPAY_STEPS

MMG_COMPONENTS = ("hull", "propeller", "rudder", "wind")

ShipOption = typer.Option("esso_osaka", "--ship", help="Ship name (configs/ships/NAME.toml) or path to a ship TOML.")
SetOption = typer.Option(None, "--set", help="Override a ship parameter, e.g. --set Xvr=0.4535 (repeatable).")
QuadratureOption = typer.Option("exact", "--quadrature",
                                help="Cross-flow integrals: exact (closed form) or simpson (the lab simulator's).")
CompiledOption = typer.Option(None, "--compiled/--eager", show_default=False,
                              help="Force the compiled step (native code, cached on disk; first use compiles, a minute "
                                   "or more) or the eager one. Default: compiled when its package is in the cache, or "
                                   f"when the eager steps reach {PREDICTION_REPAY_STEPS} per package not yet cached; "
                                   "else eager (decided from the step count and the cache alone).")


def prediction_path(command: str, asked: Optional[bool], models, work, method, dt: float):
    """The `sysid.fast.payoff.PathChoice` for predicting `work` ((ships, steps) of each
    batched prediction) with each of `models` by rule `method` at step `dt` [s]; echoed in
    one line."""
    from sysid.fast.payoff import choose_path
    from sysid.fast.compiled import enabled, prediction_package

    packages, label = set(), None
    if asked is None and enabled():
        for model in models:
            for ships, _ in work:
                label, path = prediction_package(model, method, dt, ships)
                packages.add(path)
    steps = len(models) * sum(steps for _, steps in work)
    cold = sum(not path.is_file() for path in packages)
    choice = choose_path("prediction", steps, cold, len(packages), PREDICTION_REPAY_STEPS, asked, label)
    typer.echo(f"{command}: {choice.reason}")
    return choice


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

