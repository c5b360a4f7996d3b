"""``sysid compare MODEL... -o DIR``: any models side by side on the same logs and horizons,
one table per log, horizon and channel, each model's verdict against the first or against
its physics baseline (`sysid.evaluation.comparison`)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid import logs
from sysid.cli.app import app
from sysid.cli.interrupts import on_interrupt
from sysid.errors import DataError
from sysid.records.columns import RMSE_UNITS


def _label(path: str, taken: set[str], ship_name: str | None, kind: str = "", seeds: int = 0) -> str:
    """A model's name in the tables: the run directory's or seed folder's name, "MMG (ship
    file NAME)" for a ship, a sweep's point folder (``trials/POINT``, `seeds` seed run
    directories of models of `kind`) by its kind and seeds: "Hybrid (3 seeds)", "Hybrid
    lr=0.003 (3 seeds)"; made unique with its parent folder, then a number."""
    from sysid.protocol.paper import KIND_LABELS
    from sysid.sweep.plan import TRIALS_DIR
    from sysid.sweep.points import point_name
    from sysid.store.target import OutputKind, record_file

    p = Path(path)
    label = f"MMG (ship file {ship_name})" if ship_name else p.name
    if seeds and p.parent.name == TRIALS_DIR and record_file(p.parent.parent, OutputKind.SWEEP).is_file():
        point = "" if p.name == point_name({}) else f" {p.name}"
        label = f"{KIND_LABELS.get(kind, kind)}{point} ({seeds} seed{'s' if seeds != 1 else ''})"
    if label in taken and not ship_name:
        label = f"{p.parent.name}/{p.name}"
    base, k = label, 2
    while label in taken:
        label, k = f"{base} ({k})", k + 1
    taken.add(label)
    return label


def _run_experiment(path: Path):
    """The experiment of a run directory (a seed folder: its first seed's), or None for a ship
    file."""
    from sysid.maneuvers.recorded import model_paths
    from sysid.runs.rundir import RunDir
    from sysid.store.manifest import has_manifest

    first = model_paths(path)[0]
    return RunDir.open(first).read_experiment() if first.is_dir() and has_manifest(first) else None


def _run_columns(path: Path):
    """The ``[data.columns]`` of a run directory (a seed folder: its first seed's), or None
    for a ship file."""
    from sysid.maneuvers.recorded import model_paths
    from sysid.runs.rundir import RunDir
    from sysid.store.manifest import has_manifest

    first = model_paths(path)[0]
    if not (first.is_dir() and has_manifest(first)):
        return None
    exp = RunDir.open(first).read_experiment()
    if exp.ensemble.members:  # an ensemble's config names its members' runs
        return _run_columns((first / exp.ensemble.members[0]).resolve())
    return exp.data.columns


@app.command()
def compare(
    models: List[str] = typer.Argument(..., help="Models to compare, the first the reference: run directories "
                                                 "(MMG, identified MMG, NN-only, hybrid, ensemble), folders of seed "
                                                 "run directories, ship files or bundled ship names (their MMG)."),
    output: Path = typer.Option(..., "-o", "--output", help="Directory to write (comparison.csv, verdicts.csv, "
                                                             "windows.csv, comparison.json, report.html/.pdf)."),
    data: Optional[List[Path]] = typer.Option(None, "--data", help="Logs to compare on: files, folders or patterns "
                                                                    "(several may follow one --data; default: the "
                                                                    "config's [data] test, else for runs of D1/D2 "
                                                                    "the paper's six test files)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment config whose [data] test logs, "
                                                                  "[data.columns], [data] rate and [evaluation] "
                                                                  "horizons and integrator are used."),
    ship: Optional[List[str]] = typer.Option(None, "--ship", help="Add a ship file's MMG (a ship TOML or bundled "
                                                                   "name) after the models (repeatable)."),
    horizon: Optional[List[float]] = typer.Option(None, "--horizon", help="Horizon [s] (repeatable; default: the "
                                                                           "config's [evaluation] horizons, else 30 "
                                                                           "and 100)."),
    against: str = typer.Option("first", "--against", help="first: every model judged against the first; "
                                                            "baseline: each against its physics baseline (its "
                                                            "ship file's MMG with its [mmg] overrides)."),
    integrator: Optional[str] = typer.Option(None, "--integrator", help="euler (the protocol's) or rk4 (default: "
                                                                         "the config's, else euler)."),
    threads: Optional[int] = typer.Option(None, "--threads", help="torch CPU threads (default 1; 0: one per core)."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write report.html and report.pdf too."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing comparison directory (all of it)."),
) -> None:
    """Compare any models on the same logs and horizons: RMSE per log, horizon and channel with
    its number of windows, and each model's verdict (the project's one rule) against the first
    model or against its physics baseline. Nothing is trained."""
    from sysid.cli.outputs import claim, ship_file
    from sysid.config.choices import Method
    from sysid.config.experiment import load_experiment
    from sysid.device import compute_threads
    from sysid.evaluation.comparison import FIRST
    from sysid.store.target import OutputKind

    started = time.perf_counter()
    _check_options(against, threads, horizon)
    exp = load_experiment(config) if config is not None else None
    sources = list(models) + list(ship or [])
    if len(sources) < 2 and against == FIRST:
        raise DataError("compare: give at least two models (the first is the reference), or --against baseline")
    inputs = [Path(s) if Path(s).exists() else ship_file(s) for s in sources]
    for s, found in zip(sources, inputs):
        if found is None and (Path(s).name != str(s) or s in models):  # a path, or a model that is none
            from sysid.mmg.ship import known_ships
            known = ", ".join(known_ships())
            raise DataError(f"compare: {s}: no such run directory, folder of seed runs or ship file, and no bundled "
                            f"ship of that name ({known}); check the path")
    files = _logs(data, exp, sources)
    horizons = tuple(horizon) if horizon else (exp.evaluation.horizons if exp is not None else (30.0, 100.0))
    method = Method.parse(integrator, "--integrator", offered_only=True) if integrator else (
        exp.evaluation.integrator if exp is not None else Method.EULER)
    target = claim(output, OutputKind.COMPARISON, [config, *(data or []), *files, *inputs],   # --data folders too
                   overwrite)  # a bad -o fails now

    columns, rate = _log_columns(exp, data, sources)
    chosen = _contenders(sources)
    with compute_threads(1 if threads is None else threads):
        result, paths = _compare_and_write(chosen, files, rate, columns, horizons, against, method, target,
                                           sources, report, output, exp.data.rudder_sign_checked if exp else ())
    _print(result)
    typer.echo(f"compare: {output} ({len(paths)} files, {time.perf_counter() - started:.1f} s)")


def _compare_and_write(chosen, files, rate: float, columns, horizons, against: str, method, target, sources,
                       report: bool, output: Path, rudder_sign_checked: tuple[str, ...] = ()):
    """Read the logs, predict every model on them, judge, and write the comparison staged
    into `target`; (the `Comparison`, the paths written)."""
    from sysid.dynamics.integrators import Integrator
    from sysid.evaluation.comparison import FIRST, compare as run_compare
    from sysid.progress import progress
    from sysid.report.comparison_report import write_comparison

    runs = _read_logs(files, rate, columns, horizons, rudder_sign_checked)
    logs.info(f"compare: {len(chosen)} models on {len(runs)} log(s) at {', '.join(f'{h:g}' for h in horizons)} s "
              f"({method.value}); verdicts against " + ("the first model, " + chosen[0].label if against == FIRST
                                                         else "each model's physics baseline"))
    on_interrupt(f"nothing written to {output} (it is moved into place only when complete)")
    bar = progress(total=sum(len(c.members) for c in chosen) * len(horizons), desc="predicting",
                   unit="model-horizons")
    result = run_compare(chosen, runs, horizons, against, Integrator(method), on_done=bar.update)
    bar.close()
    with target.staged() as staging:
        paths = write_comparison(staging, result, [str(s) for s in sources], [str(f) for f in files],
                                 report=report)
    return result, paths


def _check_options(against: str, threads, horizon) -> None:
    """Exit 2 for an unknown ``--against``, a bad ``--threads`` or ``--horizon``."""
    from sysid.config import checks
    from sysid.evaluation.comparison import BASELINE, FIRST

    if against not in (FIRST, BASELINE):
        raise DataError(f"--against {against!r}: choose {FIRST} (the first model) or {BASELINE} (each model's "
                        "physics baseline)")
    if threads is not None:
        checks.threads("--threads", threads)
    for h in horizon or ():
        checks.DURATION.check("--horizon", h)


def _logs(data, exp, sources=()) -> list[Path]:
    """The logs to compare on: ``--data``, else the config's [data] test logs, else the
    paper's six test logs (a config, or without one every run given, of the paper's data
    sets D1/D2 and no [data] test); exit 2 without any."""
    from sysid.data.datasets import test_files
    from sysid.data.recordings import expand_paths
    from sysid.data.splits import config_paths

    runs = [e for e in (_run_experiment(Path(s)) for s in sources if Path(s).is_dir()) if e is not None]
    if data:
        files = expand_paths(data)
    elif exp is not None and exp.data.test:   # only the test logs need to exist here
        files = list(config_paths(exp.data.test, "test", exp.source))
    elif exp is not None and exp.experiment.dataset:
        files = list(test_files().values())   # the paper's six test files
    elif exp is None and runs and all(e.experiment.dataset and not e.data.test for e in runs):
        files = list(test_files().values())
        logs.info("compare: the paper's six test files (every run was trained on its data sets D1/D2; --data names "
                  "others)")
    else:
        raise DataError("compare: no logs to compare on: name them with --data, or give --config with [data] test")
    return files


def _log_columns(exp, data, sources):
    """([data.columns] the logs are read with or None, [data] rate [Hz]): the config's, else
    the run directories' (which must agree)."""
    if exp is not None:
        columns, rate = exp.data.columns, exp.data.rate
        split_columns = exp.data.test or data
        columns = columns if split_columns else None   # the paper's files are in the processed schema
    else:
        found = {}
        for s in sources:
            cols = _run_columns(Path(s)) if Path(s).is_dir() else None
            if cols is not None:
                found[s] = cols
        distinct = {c for c in found.values()}
        if len(distinct) > 1:
            listed = "; ".join(f"{s}: {dict(c.as_table()) or 'the processed schema'}" for s, c in found.items())
            raise DataError(f"compare: the runs read their logs with different [data.columns] ({listed}); "
                            "give --config EXP whose [data.columns] fits the logs of --data")
        columns, rate = (next(iter(distinct)) if distinct else None), 1.0
    return columns, rate


def _contenders(sources):
    """Every model of `sources` as a `Contender` (its label, members, kind and physics
    baseline's label), followed by the ship file MMGs that are a learned model's physics
    baseline and were not given."""
    from sysid.evaluation.comparison import Contender
    from sysid.evaluation.divergence import PhysicalRange
    from sysid.maneuvers.any_model import load_maneuver_model
    from sysid.mmg.model import MMG
    from sysid.progress import progress

    contenders, taken, ships = [], set(), {}
    for s in progress(sources, desc="loading models", unit="models", quiet=len(sources) < 4):
        subject = load_maneuver_model(s)
        is_ship = not Path(s).is_dir()
        members = tuple(m for _, m in subject.members) if subject.spread == "seeds" else (subject.model,)
        label = _label(s, taken, subject.ship.name if is_ship else None, subject.kind,
                       len(members) if subject.spread == "seeds" else 0)
        key = (subject.ship.name, tuple(sorted(subject.ship.overrides.items())))
        if is_ship:
            ships.setdefault(key, label)
        contenders.append((label, members, subject.kind, key, subject.ship, subject.training_range))
    # a ship file's MMG is judged against its learned models' widest training range, given or
    # added, as `sysid train` judges a run's baselines
    widest = {key: PhysicalRange.widest([c[5] for c in contenders if c[3] == key]) for key in {c[3] for c in contenders}}
    baselines = {}
    for _, _, _kind, key, ship_, _range in contenders:
        if key not in ships:   # the physics baseline, always shown beside the learned models
            name = "MMG (ship file)" if len({c[3] for c in contenders}) == 1 else f"MMG (ship file {ship_.name})"
            ships[key] = name
            baselines[key] = (name, (MMG(ship_),), "mmg", key, ship_, widest[key])
    rows = contenders + list(baselines.values())
    # a run's training range: beyond it a prediction diverged, as in `sysid train` and `sysid evaluate`
    chosen = [Contender(label, members, kind, ships[key], limits if limits is not None else widest[key])
              for label, members, kind, key, _, limits in rows]
    return chosen


def _read_logs(files, rate: float, columns, horizons, rudder_sign_checked: tuple[str, ...] = ()):
    """The logs read (those named in `rudder_sign_checked` whatever their rudder check says); exit 2 when none holds a window of a horizon, a warning for each too short."""
    from sysid.data.recordings import read_runs
    from sysid.evaluation.evaluate import short_runs
    from sysid.progress import progress

    runs = read_runs(progress(files, desc="reading", unit="logs", quiet=len(files) < 4), rate, columns,
                     rudder_sign_checked=rudder_sign_checked)
    short = short_runs(runs, horizons)
    for h in horizons:
        if sum(s == h for _, s in short) == len(runs):
            raise DataError(f"--horizon {h:g} s: no log is long enough for one window (the longest lasts "
                            f"{max(r.duration for r in runs):.0f} s); nothing written")
    for run, h in short:
        logs.warning(f"{run.path}: {run.duration:.0f} s, shorter than one {h:g}-s window: no cell at {h:g} s")
    return runs


def _print(result) -> None:
    import pandas as pd

    shown = result.table.assign(change=lambda f: f.change.map(lambda v: "" if pd.isna(v) else f"{100 * v:+.1f} %"))
    for (log, h), block in shown.groupby(["log", "horizon_s"], sort=False):
        scenario, n = block.scenario.iloc[0], int(block.n_windows.iloc[0])
        named = f" ({scenario})" if scenario and scenario != log else ""
        typer.echo(f"\n{log}{named} at {h:g} s, {n} window{'s' if n != 1 else ''}: {RMSE_UNITS}")
        wide = block.pivot_table(index="model", columns="channel", values="rmse", sort=False)
        with pd.option_context("display.width", 160, "display.float_format", "{:.4f}".format):
            typer.echo(wide[[c for c in ("u", "v_m", "r") if c in wide]].to_string())
    typer.echo("")
    for j in result.verdicts.values():
        line = f"verdict: {j.sentence}"
        if j.beats:
            typer.echo(line)
        else:
            typer.secho(line, fg=typer.colors.YELLOW)
