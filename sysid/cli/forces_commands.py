"""``sysid forces``: the force components (the MMG's, and a trained run's FNN correction with
its kNN gate) and state derivatives for rows of states."""
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


def force_columns(model, frame, learned: bool = False):
    """Force components (X, Y [N], N [N m]), totals and state derivatives (SI) for rows of
    `FORCE_INPUTS`; of a `learned` model the FNN's correction (XNN, YNN, NNN) too and, with
    a kNN gate, its distance ``knn_distance`` and decision ``gate_on`` (1: the FNN acts, 0:
    outside the training data, the MMG alone)."""
    import pandas as pd
    import torch
    from sysid.dynamics.equations import state_derivative

    values = torch.tensor(frame[FORCE_INPUTS].to_numpy(dtype=float), dtype=torch.float64)
    state, inputs = values[:, :6], values[:, 6:]
    with torch.no_grad():
        forces = model(state, inputs)
        deriv = state_derivative(state, forces.total, model.coefficients)
    out = {}
    for comp in (*MMG_COMPONENTS, "correction") if learned else MMG_COMPONENTS:
        arr = getattr(forces, comp).numpy()
        for j, axis in enumerate(FORCE):
            out[force_column(comp, axis)] = arr[:, j]
    total = forces.total.numpy()
    for j, axis in enumerate(FORCE):
        out[axis] = total[:, j]
    for j, name in enumerate(DERIVATIVES):
        out[name] = deriv.numpy()[:, j]
    if forces.gate_on is not None:
        out["knn_distance"] = forces.ood_distance.numpy()
        out["gate_on"] = forces.gate_on.numpy().astype(int)
    return pd.DataFrame(out, index=frame.index)


def _read_force_inputs(path: Path):
    """The `FORCE_INPUTS` columns of a CSV as floats; one clear error for an empty, binary,
    non-UTF-8 or non-numeric file."""
    import numpy as np
    import pandas as pd
    from sysid.data.csvfiles import read_csv_table, row_name

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
        raise DataError(f"{path}: column {FORCE_INPUTS[col]!r} is not a finite number at {row_name(path, row)} "
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
    run_dir: Optional[Path] = typer.Option(None, "--run", help="A run directory (sysid train): its model's forces "
                                                               "(its MMG's components, the FNN's XNN, YNN, NNN, the "
                                                               "kNN gate's knn_distance and gate_on)."),
) -> None:
    """MMG force components (hull, propeller, rudder, wind; X, Y [N], N [N m]) and state derivatives per row.

    With --run, a trained model's: its MMG's components beside the FNN's correction, their
    total, and the kNN gate's distance and decision per row (gate_on 0: outside the
    training data, the FNN switched off)."""
    import numpy as np
    import pandas as pd
    from sysid.data.csvfiles import row_name
    from sysid.store.files import write_float_csv
    from sysid.config import checks
    from sysid.progress import progress

    start = time.perf_counter()
    checks.POSITIVE_COUNT.check("--chunk", chunk)
    if run_dir is not None:
        from sysid.runs.layout import load_model
        if set_ or quadrature != "exact" or ship != ShipOption.default:
            raise DataError("--run: the run's model is its own (its ship file and [mmg] overrides); "
                            "--ship, --set and --quadrature apply to a ship file's MMG without --run")
        run_exp, model = load_model(run_dir)
        learned = run_exp.needs_training
        claim(output, OutputKind.FILE, [input_csv, run_dir])
    else:
        model, learned = mmg_of(ship, set_, quadrature), False
        claim(output, OutputKind.FILE, [input_csv, ship_file(ship)])
    numeric = _read_force_inputs(input_csv)
    parts = []
    bounds = range(0, len(numeric), chunk)
    bar = progress(bounds, desc="forces", unit="batches", quiet=len(bounds) < 4)
    for lo in bar:
        parts.append(force_columns(model, numeric.iloc[lo:lo + chunk], learned))
    result = pd.concat([numeric] + [pd.concat(parts)], axis=1)
    computed = result.columns[len(FORCE_INPUTS):]
    values = result[computed].to_numpy()
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        state = ", ".join(f"{c} = {numeric[c].iloc[row]:g}" for c in ("u", "v", "r", "n_prop"))
        raise DataError(f"{input_csv}: {row_name(input_csv, row)}: {computed[col]} is {values[row, col]} ({state}): "
                        f"the state is beyond the model's range ({int(bad.any(axis=1).sum())} row(s)); nothing written")
    for name, limit in PLAUSIBLE.items():
        beyond = np.abs(numeric[name].to_numpy()) > limit
        if beyond.any():
            typer.secho(f"warning: {input_csv}: column {name!r} beyond {limit:g} on {int(beyond.sum())} row(s) "
                        f"(first at {row_name(input_csv, int(np.argmax(beyond)))}): not a ship model's state"
                        f"{_UNIT_HINT.get(name, '')}; forces computed but implausible", fg=typer.colors.YELLOW,
                        err=True)
    writing = progress(total=len(result), desc="writing", unit="rows", quiet=len(result) < 100_000)
    write_float_csv(result, output, on_block=writing.update)
    writing.close()
    if not logs.is_quiet():  # -q: warnings and errors only
        source = f"run {run_dir}" if run_dir is not None else f"ship {model.ship.name}, {quadrature} cross-flow"
        typer.echo(f"forces: {len(result)} rows, {source} -> {output} ({time.perf_counter() - start:.2f} s); "
                   "forces X, Y [N], moments N [N m]")
        if "gate_on" in result:
            from sysid.hybrid.force_models import gate_off_meaning
            off = 1.0 - float(result["gate_on"].mean())
            typer.echo(f"  kNN gate: off on {100 * off:.1f} % of the rows (gate_on 0: outside the training data; "
                       f"{gate_off_meaning(model)})")

