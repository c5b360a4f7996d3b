"""``sysid evaluate``: the protocol's windowed RMSE of the MMG or of a trained run, a run
beside its physics baselines with its verdict."""
from __future__ import annotations

import dataclasses
import glob
import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid.cli.app import app
from sysid.cli.mmg_options import CompiledOption, QuadratureOption, SetOption, integrator_of, mmg_of, prediction_path
from sysid.cli.outputs import claim, ship_file
from sysid.errors import DataError
from sysid.records.columns import RMSE_UNITS
from sysid.store.target import OutputKind



@app.command()
def evaluate(
    run_dir: Optional[Path] = typer.Argument(None, help="A run directory (sysid train); omit with --model mmg."),
    data: Optional[List[Path]] = typer.Option(None, "--data", help="Processed files or directories (repeatable; several may follow one --data; default: the [data] test logs of --config, else of the run)."),
    horizon: Optional[List[float]] = typer.Option(None, "--horizon", help="Horizon [s] (repeatable; default: the config's [evaluation] horizons, else 30 and 100)."),
    output: Path = typer.Option(..., "-o", "--output", help="Metrics CSV."),
    model_kind: str = typer.Option("mmg", "--model", help="mmg (the physical model alone)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment config: its [data.columns] and [data] rate read the logs, its [data] test logs, [evaluation] horizons and integrator are the defaults; with --model mmg its ship and [mmg] overrides are the MMG's."),
    integrator: Optional[str] = typer.Option(None, "--integrator", help="euler (the protocol's) or rk4 (default: the config's, else euler)."),
    ship: Optional[str] = typer.Option(None, "--ship", help="Ship name (configs/ships/NAME.toml) or path to a ship TOML (default: the config's, else esso_osaka; with a run: the run's copy of the ship file it was trained with, and --ship FILE loads the run with FILE instead)."),
    set_: Optional[List[str]] = SetOption,
    quadrature: str = QuadratureOption,
    compiled: Optional[bool] = CompiledOption,
) -> None:
    """The protocol's windowed RMSE of u, v_m, r per file and horizon (MMG or a trained run).

    A trained run is shown beside its physics baselines (the ship file's MMG with the run's
    [mmg] overrides, from the run's copy of the ship file it was trained with; the identified
    MMG under a hybrid's FNN) on the same windows, with its verdict (docs: How sysid judges a
    model)."""
    import pandas as pd
    from sysid.config.experiment import load_experiment
    from sysid.data.recordings import read_runs
    from sysid.evaluation.evaluate import evaluate_model
    from sysid.store.files import write_csv
    from sysid.config import checks
    from sysid.progress import progress

    for h in horizon or ():
        checks.DURATION.check("--horizon", h)
    start = time.perf_counter()
    exp = load_experiment(config) if config is not None else None
    run_exp, model, label = _model_to_judge(run_dir, model_kind, exp, ship, set_, quadrature)
    source = exp if exp is not None else run_exp   # where the logs, horizons and integrator come from
    files, columns = _logs(data, source, run_dir if exp is None else None)
    horizons = list(horizon) if horizon else list(source.evaluation.horizons if source is not None else (30.0, 100.0))
    chosen = integrator_of(integrator or (str(source.evaluation.integrator) if source is not None else "euler"), False)
    ship_input = ship_file(ship) if ship is not None else (
        None if run_dir is not None else ship_file(exp.experiment.ship if exp is not None else "esso_osaka"))
    claim(output, OutputKind.FILE, [run_dir, config, *(data or []), *files, ship_input, *_logs_of_run(run_exp)])
    rate = source.data.rate if source is not None else 1.0
    checked = source.data.rudder_sign_checked if source is not None else ()
    runs = read_runs(progress(files, desc="reading", unit="files", quiet=len(files) < 4), rate, columns,
                     rudder_sign_checked=checked)
    _check_windows_fit(runs, horizons)
    limits = _training_range(run_dir)
    baselines = _baselines(run_exp, model)
    path = prediction_path("evaluate", compiled, [model, *baselines.values()], _window_work(runs, horizons),
                           chosen.method, runs[0].dt)
    chosen = dataclasses.replace(chosen, compiled=path.compiled)  # the method parsed once, above
    evaluation = evaluate_model(model, runs, horizons, chosen, traces=False, limits=limits)
    for divergence in evaluation.divergences:
        typer.secho(f"WARNING: the prediction diverged on {divergence.text()}", fg=typer.colors.YELLOW, err=True)
    _warn_astern(model, runs, horizons)
    table = _with_gate(evaluation)
    write_csv(table, output, float_format="%.6g")
    with pd.option_context("display.width", 120, "display.float_format", "{:.5f}".format):
        typer.echo(f"{RMSE_UNITS}:\n" + table.to_string(index=False))
    typer.echo(f"evaluate: {len(runs)} file(s), horizons {', '.join(f'{h:g}' for h in horizons)} s, "
               f"{label} -> {output} ({time.perf_counter() - start:.1f} s)")
    _print_gate(model, table)
    if run_exp is not None:
        _beside_baselines(run_exp, model, baselines, runs, horizons, chosen, limits)


def _with_gate(evaluation):
    """The metrics table; of a model with a kNN gate, with ``gate_off_share``: the share of
    each file's window points at that horizon at which the gate switched the FNN off (the
    physics MMG alone there: outside the training data)."""
    from sysid.evaluation.evaluate import trace_name
    table = evaluation.metrics
    if not evaluation.gate_off_share:
        return table
    shares = [evaluation.gate_off_share.get(trace_name(f, h)) for f, h in zip(table.file, table.horizon_s)]
    return table.assign(gate_off_share=[float("nan") if s is None else s for s in shares])


def _print_gate(model, table) -> None:
    """Per file and horizon, how much of the prediction ran outside the training data."""
    from sysid.hybrid.force_models import gate_off_meaning
    if "gate_off_share" not in table:
        return
    gate = getattr(model, "gate", None)
    shown = f", threshold {float(gate.threshold):.4g}" if gate is not None else ""
    typer.echo(f"outside the training data (kNN gate{shown}; where it is off, {gate_off_meaning(model)}), "
               "gate_off_share in the metrics CSV:")
    for row in table.itertuples():
        if row.gate_off_share != row.gate_off_share:   # NaN: the file is shorter than the horizon
            typer.echo(f"  {row.file} at {row.horizon_s:g} s: no window (the log is shorter than the horizon)")
            continue
        typer.echo(f"  {row.file} at {row.horizon_s:g} s: gate off on {100 * row.gate_off_share:.1f} % of the "
                   "window points" + (" (mostly outside the training data)" if row.gate_off_share > 0.5 else ""))


def _model_to_judge(run_dir, model_kind: str, exp, ship, set_, quadrature: str):
    """(the run's config or None, the model, its label): a trained run's (its MMG and physics
    baseline from its copy of its ship file, or from ``--ship``), or the MMG of ``--ship``
    (else the config's) with the config's [mmg] overrides and ``--set``."""
    if run_dir is not None:
        from sysid.runs.layout import load_model
        run_exp, model = load_model(run_dir, ship=ship)
        label = f"{run_exp.experiment.model} run {run_dir}" + (f" with ship {ship}" if ship is not None else "")
    else:
        from sysid.config.choices import ModelKind
        if model_kind != ModelKind.MMG:
            raise DataError(f"--model {model_kind!r}: give a run directory for trained models, or --model mmg")
        run_exp = None
        ship_name = ship or (exp.experiment.ship if exp is not None else "esso_osaka")
        overrides = [f"{k}={v!r}" for k, v in (exp.mmg.overrides.items() if exp is not None and not ship else ())]
        model = mmg_of(ship_name, overrides + list(set_ or []), quadrature)
        shown = ", ".join(f"{k}={v:g}" for k, v in model.ship.overrides.items()) or "none"
        label = f"MMG ({model.ship.name}, overrides: {shown})"
    return run_exp, model, label


def _warn_astern(model, runs, horizons) -> None:
    """A WARNING naming the logs whose windows hold samples with astern revolutions or going
    astern when the model's propeller model is one-quadrant (`sysid.data.splits.log_conditions`):
    scored as they are, outside that model's validity."""
    from sysid.data.splits import log_conditions
    from sysid.identify.windowing import AsternSamples
    from sysid.mmg.coverage import one_quadrant_propeller

    ship = getattr(getattr(model, "mmg", model), "ship", None)
    if ship is None or not one_quadrant_propeller(ship.models):
        return
    astern = AsternSamples(tuple(sorted(ship.models.items())))
    named = []
    for run in runs:
        found = log_conditions(run, astern.of, horizons)
        if found["astern_samples"]:
            named.append(f"{run.name} {found['astern_samples']} samples, " + ", ".join(
                f"{n} of the {h}-s windows" for h, n in found["astern_windows"].items()))
    if named:
        typer.secho("WARNING: samples with astern revolutions or going astern, outside the one-quadrant propeller "
                    "model of the model's ship file, are scored as they are: " + "; ".join(named),
                    fg=typer.colors.YELLOW, err=True)


def _logs(data, source, run_dir=None):
    """(the logs to evaluate on, their [data.columns] or None): ``--data``, else the [data]
    test logs of the config or of the run at `run_dir` (found where they are now, checked
    against what the run recorded: `RunDir.read_test_logs`), else the paper's six test
    logs; exit 2 without any."""
    from sysid.data.datasets import test_files
    from sysid.data.recordings import expand_paths
    from sysid.data.splits import config_paths

    if data:
        files, columns = expand_paths(data), source.data.columns if source is not None else None
    elif run_dir is not None and source.data.test:
        from sysid.runs.rundir import RunDir
        files, columns = RunDir(run_dir).read_test_logs(source), source.data.columns
    elif source is not None and source.data.test:   # only the test logs need to exist here
        files, columns = list(config_paths(source.data.test, "test", source.source)), source.data.columns
    elif source is not None and source.experiment.dataset:
        files, columns = list(test_files().values()), None   # the paper's six, in the processed schema
    else:
        raise DataError("evaluate: no logs: name them with --data, or give --config EXP (or a run) whose "
                        "[data] test lists them")
    return files, columns


def _logs_of_run(run_exp) -> list[Path]:
    """The logs a run was made from (its config's [data] train, validation and test, as
    written: resolved files): -o may not overwrite them, read or not."""
    if run_exp is None:
        return []
    listed = [*run_exp.data.train, *run_exp.data.validation, *run_exp.data.test]
    return [Path(p) for f in listed for p in (sorted(glob.glob(f)) if glob.has_magic(f) else [f])]


def _check_windows_fit(runs, horizons) -> None:
    """Exit 2 when no log holds one window of a horizon; a warning for each log too short for
    one (its metrics row is empty)."""
    from sysid.evaluation.evaluate import short_runs

    short = short_runs(runs, horizons)
    for h in horizons:
        if sum(s == h for _, s in short) == len(runs):
            longest = max(r.duration for r in runs)
            raise DataError(f"--horizon {h:g} s: no file is long enough for one window "
                            f"(the longest lasts {longest:.0f} s); nothing written")
    for run, h in short:
        typer.secho(f"warning: {run.path}: {len(run)} samples ({run.duration:.0f} s), fewer than one {h:g}-s "
                    "window: its metrics row is empty (n_windows 0)", fg=typer.colors.YELLOW, err=True)


def _training_range(run_dir):
    """The run's training range (`PhysicalRange`; None: no run, or none recorded), said in one line."""
    limits = None
    if run_dir is not None:
        from sysid.evaluation.divergence import PhysicalRange
        from sysid.runs.rundir import RunDir
        limits = PhysicalRange.of_summary(RunDir(run_dir).read_summary())
    typer.echo(f"divergence: a non-finite state, or speed or |r| beyond {limits.factor:g} x the run's training range "
               f"({limits.speed:.3g} m/s, {limits.yaw_rate:.3g} rad/s, widened to each window's record)"
               if limits is not None else "divergence: a non-finite state only (no training range recorded)")
    return limits


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
        samples = [window_samples("--horizon", h, run.dt) for run in runs]
        windows = sum(len(protocol_windows(len(run), n)) for run, n in zip(runs, samples))
        if windows:
            work.append((windows, max(samples) - 1))
    return work


def _beside_baselines(exp, model, baselines, runs, horizons, method, limits=None) -> None:
    """The run's physics baselines on the same windows, their RMSE printed beside the
    model's, and the model's verdict against each (last line; stderr when not beaten); a
    prediction beyond the run's training range `limits` diverged, as in its metrics."""
    import pandas as pd
    from sysid.evaluation.comparison import Contender, judge_against_baselines, metrics_of
    from sysid.evaluation.verdict import MODEL_NAMES

    if not baselines:
        typer.echo("verdict: none: an MMG used as defined is itself the physics baseline")
        return
    name = f"The {MODEL_NAMES.get(str(exp.experiment.model), str(exp.experiment.model))}"
    errors, verdicts = judge_against_baselines(Contender(name, (model,), limits=limits),
                                               [Contender(k, (m,), limits=limits) for k, m in baselines.items()],
                                               runs, horizons, method)
    rows = [metrics_of(errors, name).assign(model=name[4:])]
    rows += [metrics_of(errors, label).assign(model=label) for label in baselines]
    side = pd.concat(rows, ignore_index=True)[["file", "horizon_s", "n_windows", "model", "rmse_u", "rmse_v", "rmse_r"]]
    with pd.option_context("display.width", 140, "display.float_format", "{:.5f}".format):
        order = {(e.log, e.horizon_s): i for i, e in enumerate(errors)}   # horizon, then the logs' order
        side = side.iloc[sorted(range(len(side)), key=lambda i: order[(side.file[i], side.horizon_s[i])])]
        typer.echo(f"beside its physics baseline(s), on the same windows ({RMSE_UNITS}):\n" + side.to_string(index=False))
    for judgement in verdicts.values():
        if judgement.beats:
            typer.echo("verdict: " + judgement.sentence)
        else:
            typer.secho("WARNING: " + judgement.sentence, fg=typer.colors.YELLOW, err=True)

