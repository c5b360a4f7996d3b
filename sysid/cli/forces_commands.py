"""``sysid forces``: the MMG's force components and state derivatives for rows of states."""
from __future__ import annotations

import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid import logs
from sysid.channel_names import FORCE, INPUTS, STATE, force_column
from sysid.cli.app import app
from sysid.cli.mmg_options import MMG_COMPONENTS, QuadratureOption, SetOption, ShipOption, mmg_of
from sysid.cli.outputs import claim, ship_file
from sysid.errors import DataError
from sysid.store.target import OutputKind

FORCE_INPUTS = [*STATE, *INPUTS]
DERIVATIVES = [f"{c}_dot" for c in STATE]


def force_columns(model, frame):
    """Force components, totals and state derivatives (SI) for rows of `FORCE_INPUTS`."""
    import pandas as pd
    import torch
    from sysid.dynamics.equations import state_derivative

    values = torch.tensor(frame[FORCE_INPUTS].to_numpy(dtype=float), dtype=torch.float64)
    state, inputs = values[:, :6], values[:, 6:]
    with torch.no_grad():
        forces = model(state, inputs)
        deriv = state_derivative(state, forces.total, model.coefficients)
    out = {}
    for comp in MMG_COMPONENTS:
        arr = getattr(forces, comp).numpy()
        for j, axis in enumerate(FORCE):
            out[force_column(comp, axis)] = arr[:, j]
    total = forces.total.numpy()
    for j, axis in enumerate(FORCE):
        out[axis] = total[:, j]
    for j, name in enumerate(DERIVATIVES):
        out[name] = deriv.numpy()[:, j]
    return pd.DataFrame(out, index=frame.index)


def _read_force_inputs(path: Path):
    """The `FORCE_INPUTS` columns of a CSV as floats; one clear error for an empty, binary,
    non-UTF-8 or non-numeric file."""
    import numpy as np
    import pandas as pd
    from sysid.data.csvfiles import read_csv_table

    frame = read_csv_table(path, f"a CSV with the header {' '.join(FORCE_INPUTS)}")
    missing = [c for c in FORCE_INPUTS if c not in frame.columns]
    if missing:
        raise DataError(f"{path}: missing column(s) {missing} (header: {', '.join(map(str, frame.columns[:12]))})")
    if not len(frame):
        raise DataError(f"{path}: no data rows under the header")
    numeric = frame[FORCE_INPUTS].apply(pd.to_numeric, errors="coerce")
    bad = ~np.isfinite(numeric.to_numpy(dtype=float))
    if bad.any():
        row, col = np.argwhere(bad)[0]
        cell = frame[FORCE_INPUTS[col]].iloc[row]
        raise DataError(f"{path}: column {FORCE_INPUTS[col]!r} is not a finite number at line {row + 2} "
                        f"({'empty' if pd.isna(cell) else f'found {cell}'})")
    return numeric.astype(float)


# beyond these a state is not a ship model's: the forces are computed but flagged
PLAUSIBLE = {"u": 20.0, "v": 20.0, "r": 3.0, "n_prop": 200.0, "wind_velo_true": 60.0,
             "delta_rudder": 1.0}   # rad: no rudder turns 57 deg; 35 is a hard-over angle in degrees
_UNIT_HINT = {"delta_rudder": " (degrees? the column is in rad)", "r": " (deg/s? the column is in rad/s)",
              "n_prop": " (rpm? the column is in rps)"}


@app.command()
def forces(
    input_csv: Path = typer.Argument(..., help="CSV with columns x u y v psi r n_prop delta_rudder wind_velo_true wind_dir_true (SI: m, m/s, rad, rad/s, rps)."),
    output: Path = typer.Option(..., "-o", "--output", help="Output CSV."),
    ship: str = ShipOption,
    set_: Optional[List[str]] = SetOption,
    quadrature: str = QuadratureOption,
    chunk: int = typer.Option(65536, help="Rows per batch."),
) -> None:
    """MMG force components (hull, propeller, rudder, wind; X, Y, N) and state derivatives per row."""
    import numpy as np
    import pandas as pd
    from sysid.store.files import write_float_csv
    from sysid.config import checks
    from sysid.progress import progress

    start = time.perf_counter()
    checks.POSITIVE_COUNT.check("--chunk", chunk)
    model = mmg_of(ship, set_, quadrature)
    claim(output, OutputKind.FILE, [input_csv, ship_file(ship)])
    numeric = _read_force_inputs(input_csv)
    parts = []
    bounds = range(0, len(numeric), chunk)
    bar = progress(bounds, desc="forces", unit="batches", quiet=len(bounds) < 4)
    for lo in bar:
        parts.append(force_columns(model, numeric.iloc[lo:lo + chunk]))
    result = pd.concat([numeric] + [pd.concat(parts)], axis=1)
    computed = result.columns[len(FORCE_INPUTS):]
    values = result[computed].to_numpy()
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        state = ", ".join(f"{c} = {numeric[c].iloc[row]:g}" for c in ("u", "v", "r", "n_prop"))
        raise DataError(f"{input_csv}: line {row + 2}: {computed[col]} is {values[row, col]} ({state}): "
                        f"the state is beyond the model's range ({int(bad.any(axis=1).sum())} row(s)); nothing written")
    for name, limit in PLAUSIBLE.items():
        beyond = np.abs(numeric[name].to_numpy()) > limit
        if beyond.any():
            typer.secho(f"warning: {input_csv}: column {name!r} beyond {limit:g} on {int(beyond.sum())} row(s) "
                        f"(first at line {int(np.argmax(beyond)) + 2}): not a ship model's state"
                        f"{_UNIT_HINT.get(name, '')}; forces computed but implausible", fg=typer.colors.YELLOW,
                        err=True)
    writing = progress(total=len(result), desc="writing", unit="rows", quiet=len(result) < 100_000)
    write_float_csv(result, output, on_block=writing.update)
    writing.close()
    if not logs.is_quiet():  # -q: warnings and errors only
        typer.echo(f"forces: {len(result)} rows, ship {model.ship.name}, {quadrature} cross-flow -> {output} "
                   f"({time.perf_counter() - start:.2f} s)")

