"""``sysid forces``, ``sysid simulate``, ``sysid evaluate --model mmg``."""
from __future__ import annotations

import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid import logs
from sysid.cli.app import app
from sysid.cli.outputs import claim, ship_file
from sysid.store.target import OutputKind
from sysid.errors import DataError
from sysid.fast.payoff import PREDICTION_REPAY_STEPS
from sysid.state import FORCE, INPUTS, STATE, force_column

FORCE_INPUTS = [*STATE, *INPUTS]
MMG_COMPONENTS = ("hull", "propeller", "rudder", "wind")
DERIVATIVES = [f"{c}_dot" for c in STATE]

ShipOption = typer.Option("esso_osaka", "--ship", help="Ship name (configs/ships/NAME.toml) or path to a ship TOML.")
SetOption = typer.Option(None, "--set", help="Override a ship parameter, e.g. --set Xvr=0.4535 (repeatable).")
QuadratureOption = typer.Option("exact", "--quadrature",
                                help="Cross-flow integrals: exact (closed form) or simpson (the lab simulator's).")
CompiledOption = typer.Option(None, "--compiled/--eager", show_default=False,
                              help="Force the compiled step (native code, cached on disk; first use compiles, a minute "
                                   "or more) or the eager one. Default: compiled when its package is in the cache, or "
                                   f"when the eager steps reach {PREDICTION_REPAY_STEPS} per package not yet cached; "
                                   "else eager (decided from the step count and the cache alone).")


def _prediction_path(command: str, asked: Optional[bool], models, work, method, dt: float):
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


def _integrator(name: str, compiled: bool):
    """The `Integrator` an ``--integrator`` (and ``--compiled``) option names; exit 2 otherwise."""
    from sysid.config.choices import Method
    from sysid.dynamics.integrators import Integrator

    try:
        return Integrator(Method.parse(name, "--integrator", offered_only=True), compiled)
    except ValueError as exc:
        raise DataError(str(exc)) from None


def _model(ship: str, overrides: Optional[List[str]], quadrature: str):
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship, parse_overrides

    if quadrature not in ("exact", "simpson"):
        raise DataError(f"--quadrature {quadrature!r}: choose exact or simpson")
    return MMG(load_ship(ship, parse_overrides(overrides)), quadrature=quadrature)


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
        raise DataError(f"{path}: column {FORCE_INPUTS[col]!r} is not a finite number at data row {row + 2} "
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
    model = _model(ship, set_, quadrature)
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
        raise DataError(f"{input_csv}: data row {row + 2}: {computed[col]} is {values[row, col]} ({state}): "
                        f"the state is beyond the model's range ({int(bad.any(axis=1).sum())} row(s)); nothing written")
    for name, limit in PLAUSIBLE.items():
        beyond = np.abs(numeric[name].to_numpy()) > limit
        if beyond.any():
            typer.secho(f"warning: {input_csv}: column {name!r} beyond {limit:g} on {int(beyond.sum())} row(s) "
                        f"(first at data row {int(np.argmax(beyond)) + 2}): not a ship model's state"
                        f"{_UNIT_HINT.get(name, '')}; forces computed but implausible", fg=typer.colors.YELLOW,
                        err=True)
    writing = progress(total=len(result), desc="writing", unit="rows", quiet=len(result) < 100_000)
    write_float_csv(result, output, on_block=writing.update)
    writing.close()
    if not logs.is_quiet():  # -q: warnings and errors only
        typer.echo(f"forces: {len(result)} rows, ship {model.ship.name}, {quadrature} cross-flow -> {output} "
                   f"({time.perf_counter() - start:.2f} s)")


@app.command()
def simulate(
    log: Path = typer.Option(..., "--log", help="Processed run (public schema, 10 Hz or 1 Hz)."),
    start: float = typer.Option(..., "--start", help="Start time T [s] (recorded state at T)."),
    horizon: float = typer.Option(..., "--horizon", help="Prediction horizon H [s]."),
    output: Path = typer.Option(..., "-o", "--output", help="Output CSV."),
    integrator: str = typer.Option("euler", "--integrator", help="euler (the paper's) or rk4 (classical)."),
    rate: float = typer.Option(1.0, "--rate", help="Step rate [Hz]: 1 = the protocol's 1 Hz grid."),
    ship: str = ShipOption,
    set_: Optional[List[str]] = SetOption,
    quadrature: str = QuadratureOption,
    compiled: Optional[bool] = CompiledOption,
) -> None:
    """Predict from the recorded state at T with the recorded inputs (zero-order hold)."""
    import numpy as np
    import pandas as pd
    import torch
    from sysid.fast.compiled import predict
    from sysid.data.recordings import read_run
    from sysid.store.files import write_csv
    from sysid.config import checks

    chosen = _integrator(integrator, False)
    checks.RATE.check("--rate", rate)
    checks.DURATION.check("--horizon", horizon)
    checks.TIME.check("--start", start)
    model = _model(ship, set_, quadrature)
    claim(output, OutputKind.FILE, [log, ship_file(ship)])
    run = read_run(log, rate)
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
    x0 = torch.as_tensor(run.states[i0], dtype=torch.float64)
    inputs = torch.as_tensor(run.inputs[sl], dtype=torch.float64)
    path = _prediction_path("simulate", compiled, [model], [(1, steps)], chosen.method, run.dt)
    chosen = _integrator(integrator, path.compiled)
    with torch.no_grad():
        pred = predict(model, x0, inputs, run.dt, chosen)
        forces = model(pred, inputs)
    out = pd.DataFrame({"t": run.t[sl], "t_rel": run.t[sl] - run.t[i0]})
    for j, name in enumerate(STATE):
        out[name] = pred[:, j].numpy()
    for j, name in enumerate(INPUTS):
        out[name] = run.inputs[sl, j]
    for comp in MMG_COMPONENTS:
        arr = getattr(forces, comp).numpy()
        for j, axis in enumerate(FORCE):
            out[force_column(comp, axis)] = arr[:, j]
    for j, name in enumerate(STATE):
        out[f"obs_{name}"] = run.states[sl, j]
    write_csv(out, output, float_format="%.17g")
    err = np.sqrt(((out[["u", "v", "r"]].to_numpy() - out[["obs_u", "obs_v", "obs_r"]].to_numpy()) ** 2).mean(0))
    typer.echo(f"simulate: {run.name} from t = {run.t[i0]:.1f} s, {steps} {chosen.method} steps of {run.dt:g} s -> {output}\n"
               f"  RMSE vs record: u {err[0]:.4f} m/s, v_m {err[1]:.4f} m/s, r {err[2]:.4f} rad/s")


@app.command()
def evaluate(
    run_dir: Optional[Path] = typer.Argument(None, help="A run directory (sysid train); omit with --model mmg."),
    data: Optional[List[Path]] = typer.Option(None, "--data", help="Processed files or directories (repeatable; several may follow one --data; default: the [data] test logs of --config, else of the run)."),
    horizon: Optional[List[float]] = typer.Option(None, "--horizon", help="Horizon [s] (repeatable; default: the config's [evaluation] horizons, else 30 and 100)."),
    output: Path = typer.Option(..., "-o", "--output", help="Metrics CSV."),
    model_kind: str = typer.Option("mmg", "--model", help="mmg (the physical model alone)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment config: its [data.columns] and [data] rate read the logs, its [data] test logs, [evaluation] horizons and integrator are the defaults; with --model mmg its ship and [mmg] overrides are the MMG's."),
    integrator: Optional[str] = typer.Option(None, "--integrator", help="euler (the protocol's) or rk4 (default: the config's, else euler)."),
    ship: Optional[str] = typer.Option(None, "--ship", help="Ship name (configs/ships/NAME.toml) or path to a ship TOML (default: the config's, else esso_osaka)."),
    set_: Optional[List[str]] = SetOption,
    quadrature: str = QuadratureOption,
    compiled: Optional[bool] = CompiledOption,
) -> None:
    """The protocol's windowed RMSE of u, v_m, r per file and horizon (MMG or a trained run).

    A trained run is shown beside its physics baselines (the ship file's MMG with the run's
    [mmg] overrides; the identified MMG under a hybrid's FNN) on the same windows, with its
    verdict (docs: How sysid judges a model)."""
    import pandas as pd
    from sysid.config.experiment import load_experiment
    from sysid.data.recordings import expand_paths, read_runs
    from sysid.data.datasets import test_files
    from sysid.data.splits import config_paths
    from sysid.evaluation.evaluate import evaluate_model, short_runs
    from sysid.store.files import write_csv
    from sysid.config import checks
    from sysid.progress import progress

    for h in horizon or ():
        checks.DURATION.check("--horizon", h)
    start = time.perf_counter()
    exp = load_experiment(config) if config is not None else None
    if run_dir is not None:
        from sysid.runs.rundir import load_model
        run_exp, model = load_model(run_dir)
        label = f"{run_exp.experiment.model} run {run_dir}"
    else:
        if model_kind != "mmg":
            raise DataError(f"--model {model_kind!r}: give a run directory for trained models, or --model mmg")
        run_exp = None
        ship_name = ship or (exp.experiment.ship if exp is not None else "esso_osaka")
        overrides = [f"{k}={v!r}" for k, v in (exp.mmg.overrides.items() if exp is not None and not ship else ())]
        model = _model(ship_name, overrides + list(set_ or []), quadrature)
        shown = ", ".join(f"{k}={v:g}" for k, v in model.ship.overrides.items()) or "none"
        label = f"MMG ({model.ship.name}, overrides: {shown})"
    source = exp if exp is not None else run_exp   # where the logs, horizons and integrator come from
    if data:
        files, columns = expand_paths(data), source.data.columns if source is not None else None
    elif source is not None and source.data.test:   # only the test logs need to exist here
        files, columns = list(config_paths(source.data.test, "test", source.source)), source.data.columns
    elif source is not None and source.experiment.dataset:
        files, columns = list(test_files().values()), None   # the paper's six, in the processed schema
    else:
        raise DataError("evaluate: no logs: name them with --data, or give --config EXP (or a run) whose "
                        "[data] test lists them")
    horizons = list(horizon) if horizon else list(source.evaluation.horizons if source is not None else (30.0, 100.0))
    chosen = _integrator(integrator or (str(source.evaluation.integrator) if source is not None else "euler"), False)
    ship_input = None if run_dir is not None else ship_file(ship or (exp.experiment.ship if exp is not None
                                                                     else "esso_osaka"))
    claim(output, OutputKind.FILE, [run_dir, config, *(data or []), *files, ship_input])  # --data folders too
    rate = source.data.rate if source is not None else 1.0
    runs = read_runs(progress(files, desc="reading", unit="files", quiet=len(files) < 4), rate, columns)
    short = short_runs(runs, horizons)
    for h in horizons:
        if sum(s == h for _, s in short) == len(runs):
            longest = max(r.duration for r in runs)
            raise DataError(f"--horizon {h:g} s: no file is long enough for one window "
                            f"(the longest lasts {longest:.0f} s); nothing written")
    for run, h in short:
        typer.secho(f"warning: {run.path}: {len(run)} samples ({run.duration:.0f} s), fewer than one {h:g}-s "
                    "window: its metrics row is empty (n_windows 0)", fg=typer.colors.YELLOW, err=True)
    limits = None
    if run_dir is not None:
        from sysid.evaluation.divergence import PhysicalRange
        from sysid.runs.directory import RunDir
        limits = PhysicalRange.of_summary(RunDir(run_dir).read_summary())
    typer.echo(f"divergence: a non-finite state, or speed or |r| beyond {limits.factor:g} x the run's training range "
               f"({limits.speed:.3g} m/s, {limits.yaw_rate:.3g} rad/s, widened to each window's record)"
               if limits is not None else "divergence: a non-finite state only (no training range recorded)")
    baselines = _baselines(run_exp, model)
    path = _prediction_path("evaluate", compiled, [model, *baselines.values()], _window_work(runs, horizons),
                            chosen.method, runs[0].dt)
    chosen = _integrator(str(chosen.method), path.compiled)
    evaluation = evaluate_model(model, runs, horizons, chosen, traces=False, limits=limits)
    for divergence in evaluation.divergences:
        typer.secho(f"WARNING: the prediction diverged on {divergence.text()}", fg=typer.colors.YELLOW, err=True)
    table = evaluation.metrics
    write_csv(table, output, float_format="%.6g")
    with pd.option_context("display.width", 120, "display.float_format", "{:.5f}".format):
        typer.echo(table.to_string(index=False))
    typer.echo(f"evaluate: {len(runs)} file(s), horizons {', '.join(f'{h:g}' for h in horizons)} s, "
               f"{label} -> {output} ({time.perf_counter() - start:.1f} s)")
    if run_exp is not None:
        _beside_baselines(run_exp, model, baselines, runs, horizons, chosen)


def _baselines(exp, model) -> dict:
    """The run's physics baselines (`sysid.runs.lifecycle.physics_baselines`); {} for the MMG alone."""
    if exp is None:
        return {}
    import torch
    from sysid.runs.lifecycle import physics_baselines
    return physics_baselines(exp, model, torch.float64)


def _window_work(runs, horizons) -> list[tuple[int, int]]:
    """(windows, steps) of each horizon's one batched prediction of every run's windows."""
    from sysid.data.recordings import protocol_windows
    from sysid.evaluation.evaluate import window_samples

    work = []
    for h in horizons:
        samples = {window_samples("--horizon", h, run.dt) for run in runs}
        windows = sum(len(protocol_windows(len(run), window_samples("--horizon", h, run.dt))) for run in runs)
        if windows:
            work.append((windows, max(samples) - 1))
    return work


def _beside_baselines(exp, model, baselines, runs, horizons, method) -> None:
    """The run's physics baselines on the same windows, their RMSE printed beside the
    model's, and the model's verdict against each (last line; stderr when not beaten)."""
    import pandas as pd
    from sysid.evaluation.comparison import Contender, judge_against_baselines, metrics_of
    from sysid.evaluation.verdict import MODEL_NAMES

    if not baselines:
        typer.echo("verdict: none: an MMG used as defined is itself the physics baseline")
        return
    name = f"The {MODEL_NAMES.get(str(exp.experiment.model), str(exp.experiment.model))}"
    errors, verdicts = judge_against_baselines(Contender(name, (model,)),
                                               [Contender(k, (m,)) for k, m in baselines.items()],
                                               runs, horizons, method)
    rows = [metrics_of(errors, name).assign(model=name[4:])]
    rows += [metrics_of(errors, label).assign(model=label) for label in baselines]
    side = pd.concat(rows, ignore_index=True)[["file", "horizon_s", "n_windows", "model", "rmse_u", "rmse_v", "rmse_r"]]
    with pd.option_context("display.width", 140, "display.float_format", "{:.5f}".format):
        order = {(e.log, e.horizon_s): i for i, e in enumerate(errors)}   # horizon, then the logs' order
        side = side.iloc[sorted(range(len(side)), key=lambda i: order[(side.file[i], side.horizon_s[i])])]
        typer.echo("beside its physics baseline(s), on the same windows:\n" + side.to_string(index=False))
    for judgement in verdicts.values():
        if judgement.beats:
            typer.echo("verdict: " + judgement.sentence)
        else:
            typer.secho("WARNING: " + judgement.sentence, fg=typer.colors.YELLOW, err=True)

