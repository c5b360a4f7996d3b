"""``sysid simulate``: one prediction of the MMG, or of a trained run beside its physics
baseline, from a recorded state with the recorded inputs."""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import List, Optional

import typer

from sysid.channel_names import FORCE, INPUTS, STATE, force_column
from sysid.cli.app import app
from sysid.cli.mmg_options import (MMG_COMPONENTS, CompiledOption, QuadratureOption, SetOption, integrator_of,
                                   mmg_of, prediction_path)
from sysid.cli.outputs import claim, ship_file
from sysid.errors import DataError
from sysid.store.target import OutputKind


@app.command()
def simulate(
    log: Path = typer.Option(..., "--log", help="Processed run (the processed columns, or yours with --config; "
                                                "10 Hz or 1 Hz)."),
    start: float = typer.Option(..., "--start", help="Start time T [s] (recorded state at T)."),
    horizon: float = typer.Option(..., "--horizon", help="Prediction horizon H [s]."),
    output: Path = typer.Option(..., "-o", "--output", help="Output CSV."),
    integrator: str = typer.Option("euler", "--integrator", help="euler (the paper's) or rk4 (classical)."),
    rate: float = typer.Option(1.0, "--rate", help="Step rate [Hz]: 1 = the protocol's 1 Hz grid."),
    ship: Optional[str] = typer.Option(None, "--ship", help="Ship name (configs/ships/NAME.toml) or path to a ship "
                                                            "TOML (default: the config's, else esso_osaka)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment config: its [data.columns] read the log "
                                                                 "(your column names and units); its ship and [mmg] "
                                                                 "overrides are the MMG's unless --ship is given."),
    set_: Optional[List[str]] = SetOption,
    quadrature: str = QuadratureOption,
    compiled: Optional[bool] = CompiledOption,
    run_dir: Optional[Path] = typer.Option(None, "--run", help="A run directory (sysid train): predict with its model "
                                                               "(MMG, NN-only, hybrid with its kNN gate) beside its "
                                                               "physics baseline; --ship FILE loads it with FILE."),
) -> None:
    """Predict from the recorded state at T with the recorded inputs (zero-order hold).

    Forces [N] and moments [N m] per component; with --run, the FNN's correction, the kNN
    gate's distance and decision at every step, and the physics baseline's prediction
    (``mmg_`` columns) from the same state with the same inputs."""
    import torch
    from sysid.fast.compiled import predict
    from sysid.data.recordings import read_run
    from sysid.store.files import write_csv
    from sysid.config import checks
    from sysid.config.experiment import load_experiment

    chosen = integrator_of(integrator, False)
    checks.RATE.check("--rate", rate)
    checks.DURATION.check("--horizon", horizon)
    checks.TIME.check("--start", start)
    exp = load_experiment(config) if config is not None else None
    baseline = None
    if run_dir is not None:
        from sysid.runs.layout import load_model
        from sysid.runs.lifecycle import physics_baselines
        if set_ or quadrature != "exact":
            raise DataError("--run: the run's model is its own (its ship file and [mmg] overrides); "
                            "--set and --quadrature apply to a ship file's MMG without --run")
        run_exp, model = load_model(run_dir, ship=ship)
        baseline = next(iter(physics_baselines(run_exp, model, torch.float64).items()), None)
        columns = exp.data.columns if exp is not None else run_exp.data.columns
        checked = (exp if exp is not None else run_exp).data.rudder_sign_checked
        claim(output, OutputKind.FILE, [log, config, run_dir, ship_file(ship) if ship else None])
    else:
        ship_name = ship or (exp.experiment.ship if exp is not None else "esso_osaka")
        overrides = [f"{k}={v!r}" for k, v in (exp.mmg.overrides.items() if exp is not None and not ship else ())]
        model = mmg_of(ship_name, overrides + list(set_ or []), quadrature)
        columns = exp.data.columns if exp is not None else None
        checked = exp.data.rudder_sign_checked if exp is not None else ()
        claim(output, OutputKind.FILE, [log, config, ship_file(ship_name)])
    run = read_run(log, rate, columns, rudder_sign_checked=checked)
    i0, steps = _window(run, log, start, horizon, rate)
    sl = slice(i0, i0 + steps + 1)
    x0 = torch.as_tensor(run.states[i0], dtype=torch.float64)
    inputs = torch.as_tensor(run.inputs[sl], dtype=torch.float64)
    models = [model] if baseline is None else [model, baseline[1]]
    path = prediction_path("simulate", compiled, models, [(1, steps)], chosen.method, run.dt)
    chosen = dataclasses.replace(chosen, compiled=path.compiled)  # the method parsed once, above
    with torch.no_grad():
        pred = predict(model, x0, inputs, run.dt, chosen)
        forces = model(pred, inputs)
        beside = None if baseline is None else predict(baseline[1], x0, inputs, run.dt, chosen).numpy()
    out = _prediction_frame(run, sl, i0, pred.numpy(), forces, beside)
    write_csv(out, output, float_format="%.17g")
    typer.echo(f"simulate: {run.name} from t = {run.t[i0]:.1f} s, {steps} {chosen.method} steps of {run.dt:g} s -> {output}")
    typer.echo(f"  RMSE vs record: {_rmse(out, '')}" + ("" if run_dir is None else f" ({run_exp.experiment.model} run)"))
    if baseline is not None:
        typer.echo(f"  RMSE vs record: {_rmse(out, 'mmg_')} ({baseline[0]}, the physics baseline: mmg_ columns)")
    if forces.gate_on is not None:
        from sysid.hybrid.force_models import gate_off_meaning
        off = 1.0 - float(forces.gate_on[:-1].double().mean()) if steps else 0.0
        gate = getattr(model, "gate", None)
        shown = f", threshold {float(gate.threshold):.4g}" if gate is not None else ""
        typer.echo(f"  kNN gate{shown}: off on {100 * off:.1f} % of the steps (largest knn_distance "
                   f"{float(forces.ood_distance.max()):.4g}); where off, {gate_off_meaning(model)}"
                   + (": mostly outside the training data" if off > 0.5 else ""))


def _rmse(out, prefix: str) -> str:
    """RMSE of the prediction (columns `prefix` u, v, r) against the record, in words."""
    import numpy as np
    predicted = out[[f"{prefix}{c}" for c in ("u", "v", "r")]].to_numpy()
    err = np.sqrt(((predicted - out[["obs_u", "obs_v", "obs_r"]].to_numpy()) ** 2).mean(0))
    return f"u {err[0]:.4f} m/s, v_m {err[1]:.4f} m/s, r {err[2]:.4f} rad/s"


def _window(run, log: Path, start: float, horizon: float, rate: float) -> tuple[int, int]:
    """The sample index of ``--start`` in `run` and the steps of ``--horizon``; exit 2 for a
    start outside the run, a horizon past its end or samples not ``1 / --rate`` apart."""
    import numpy as np
    from sysid.config import checks

    i0 = int(np.argmin(np.abs(run.t - start)))
    if abs(run.t[i0] - start) > 0.5 * run.dt:
        raise DataError(f"{log}: --start {start} s is outside the run ({run.t[0]:.1f}..{run.t[-1]:.1f} s)")
    steps = checks.whole_samples("--horizon", horizon, run.dt)
    if i0 + steps >= len(run):
        raise DataError(f"{log}: --horizon {horizon} s from {run.t[i0]:.1f} s runs past the end "
                        f"({run.t[-1]:.1f} s)")
    sl = slice(i0, i0 + steps + 1)
    uneven = np.abs(np.diff(run.t[sl]) - run.dt) > 1e-3 * run.dt
    if uneven.any():  # the model steps by dt on the recorded inputs: they must be dt apart
        k = i0 + int(np.argmax(uneven))
        raise DataError(f"{log}: samples at t = {run.t[k]:.6g} and {run.t[k + 1]:.6g} s are "
                        f"{run.t[k + 1] - run.t[k]:.6g} s apart, not the {run.dt:g} s of --rate {rate:g} Hz "
                        f"({int(uneven.sum())} uneven step(s) in the {horizon:g}-s horizon); choose a --start "
                        "and --horizon inside an evenly sampled stretch, or resample the log")
    return i0, steps


def _prediction_frame(run, sl: slice, i0: int, pred, forces, beside=None):
    """The simulate CSV: time, the predicted state `pred` (K+1, 6), the recorded inputs, the
    force components (N, N m; the FNN's XNN, YNN, NNN of a learned model), the kNN gate's
    ``knn_distance`` and ``gate_on`` (1: the FNN acts) of a gated model, the physics
    baseline's predicted state `beside` (K+1, 6) as ``mmg_`` columns, and the recorded
    state (``obs_``), one row per step of `sl`."""
    import pandas as pd

    out = pd.DataFrame({"t": run.t[sl], "t_rel": run.t[sl] - run.t[i0]})
    for j, name in enumerate(STATE):
        out[name] = pred[:, j]
    for j, name in enumerate(INPUTS):
        out[name] = run.inputs[sl, j]
    learned = beside is not None or forces.gate_on is not None   # a trained run: its FNN's columns too
    for comp in (*MMG_COMPONENTS, "correction") if learned else MMG_COMPONENTS:
        arr = getattr(forces, comp).numpy()
        for j, axis in enumerate(FORCE):
            out[force_column(comp, axis)] = arr[:, j]
    if forces.gate_on is not None:
        out["knn_distance"] = forces.ood_distance.numpy()
        out["gate_on"] = forces.gate_on.numpy().astype(int)
    if beside is not None:
        for j, name in enumerate(STATE):
            out[f"mmg_{name}"] = beside[:, j]
    for j, name in enumerate(STATE):
        out[f"obs_{name}"] = run.states[sl, j]
    return out
