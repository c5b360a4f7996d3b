"""``sysid train`` and ``sysid reproduce``."""
from __future__ import annotations

import atexit
import gc
import os
import sys
import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid import logs
from sysid.cli.app import app
from sysid.cli.interrupts import on_interrupt
from sysid.cli.outputs import claim, experiment_inputs
from sysid.config.choices import Solver
from sysid.errors import DataError
from sysid.records.columns import RMSE_UNITS
from sysid.store.target import OutputKind


@app.command()
def train(
    config: Path = typer.Argument(..., help="Experiment TOML (configs/experiments/*.toml)."),
    output: Path = typer.Option(..., "-o", "--output", help="Run directory to write (runs/NAME)."),
    data: Optional[Path] = typer.Option(None, "--data", help="Root of the paper's FRT-DS-ESSO data set, for a config with [experiment] dataset = D1 or D2 (default: SYSID_DATA or ../shared/data/frt-ds-esso); your own logs are listed in the config's [data] train."),
    test: Optional[List[Path]] = typer.Option(None, "--test", help="Logs to score the run on after training, instead of the config's [data] test (default: [data] test; the paper's six test files are never read by training: sysid evaluate or sysid reproduce score on them)."),
    epochs: Optional[int] = typer.Option(None, "--epochs", help="Override [training] epochs."),
    threads: Optional[int] = typer.Option(None, "--threads", help="Override [training] threads (torch CPU threads; 0: one per core)."),
    resume: bool = typer.Option(False, "--resume", help="Continue an interrupted training from its checkpoint."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing run directory (all of it)."),
    mlflow: Optional[str] = typer.Option(None, "--mlflow", help="Log the run to this MLflow tracking URI (a path: a file store): options, every epoch, metrics, the run directory."),
) -> None:
    """Train an MMG (identified), NN-only or hybrid model and write a run directory.

    The run directory is moved into place only when complete (with a manifest); an
    interrupted training leaves no run, only its checkpoint for --resume.
    """
    _import_training()
    from sysid.runs.lifecycle import checkpoint_path, evaluation_runs, training_runs, validation_runs

    _cheap_exit()
    start = time.perf_counter()
    exp = _experiment(config, epochs, threads, test)
    if data is not None and not exp.experiment.dataset:   # it would be ignored: the config names its logs
        raise DataError(f"--data {data}: the root of the paper's FRT-DS-ESSO data set, read only with [experiment] "
                        f"dataset = \"D1\" or \"D2\"; {config} names its own logs ([data] train): drop --data "
                        "(list the logs to train on in [data] train, those to score on with --test)")
    # a bad -o fails now, not after training
    claim(output, OutputKind.RUN, [config, *experiment_inputs(exp, data)], overwrite)
    checkpoint = checkpoint_path(output)
    if resume and exp.needs_training and not checkpoint.is_file():
        logs.warning(f"--resume: no checkpoint {checkpoint} to resume from: {output} trains from the first epoch "
                     "(a checkpoint is kept beside the run directory only after an interrupted training)")
    on_interrupt(lambda: f"nothing written to {output}" + (
        f"; the training checkpoint {checkpoint} is kept: rerun with --resume to continue"
        if checkpoint.is_file() else ""))
    runs = training_runs(exp, data) if exp.needs_training else None
    validation = validation_runs(exp) if exp.needs_training else []
    # the logs the config (or --test) names are scored after training; the paper's six test
    # files are never opened by training (sysid evaluate and sysid reproduce read them)
    tests = evaluation_runs(exp, data) if exp.data.test else []
    _say_logs(exp, runs, validation, tests)
    result = _run_tracked(exp, output, tests, runs, data, resume, overwrite, validation, mlflow)
    _say_result(result, exp, output, tests, start)


def _import_training() -> None:
    """The training stack's first import in this process (sysid.runs.lifecycle: torch, pandas,
    about 230 000 objects that live as long as the process) with the cyclic garbage collector
    paused, then its objects kept out of the collector's later passes (`gc.freeze`): its
    passes over them while they are created, and the first one after, cost about 0.3 s CPU.
    The import's own cyclic garbage (about 7 000 objects) then stays until the process ends.
    Nothing when the stack is already imported (an embedding process, a test session)."""
    if "sysid.runs.lifecycle" in sys.modules:
        return
    paused = gc.isenabled()
    gc.disable()
    try:
        import sysid.runs.lifecycle  # noqa: F401
    finally:
        gc.freeze()
        if paused:
            gc.enable()


def _cheap_exit() -> None:
    """At the process's exit, before the interpreter's own clean-up: every object then alive
    out of the cyclic collector's last passes (`gc.freeze`), which would otherwise walk the
    ~230 000 objects of torch, pandas and the rest (about 0.5 s CPU per process here). The
    objects are still freed by their reference counts; nothing changes while the process runs."""
    atexit.unregister(gc.freeze)  # once, however often the command runs in one process
    atexit.register(gc.freeze)


def _experiment(config: Path, epochs: Optional[int], threads: Optional[int], test: Optional[List[Path]]):
    """The experiment of `config` with ``--epochs``, ``--threads`` and ``--test``; exit 2 for
    a bad option or a config of an ensemble."""
    from sysid.config import checks
    from sysid.config.experiment import load_experiment
    from sysid.data.recordings import expand_paths
    from sysid.errors import ConfigError

    if epochs is not None and epochs < 0:
        raise ConfigError(f"--epochs {epochs}: must be >= 0")
    if threads is not None:
        checks.threads("--threads", threads)
    exp = load_experiment(config)
    if exp.ensemble.members:  # a run of averaged trained runs: nothing to train, and no weights of its own
        raise ConfigError(f"{config}: [ensemble] members: sysid train trains one model, and its run would name "
                          "members relative to a run directory they are not beside; remove [ensemble] (an "
                          "ensemble of seeds is written by sysid reproduce --seeds N)")
    if epochs is not None:
        exp = exp.replace(training={"epochs": epochs})
    if threads is not None:
        exp = exp.replace(training={"threads": threads})
    if test:
        exp = exp.replace(data={"test": tuple(os.path.abspath(p) for p in expand_paths(test))})
    return exp


def _say_logs(exp, runs, validation, tests) -> None:
    """One line each: the training logs and how validation is drawn, the test logs (or why none)."""
    from sysid.config.choices import Validation

    if runs is not None:
        source = f"data set {exp.experiment.dataset}" if exp.experiment.dataset and not exp.data.train else "your logs"
        logs.info(f"train: {exp.experiment.model} model on {len(runs)} training log(s) from {source} "
                   f"({sum(r.duration for r in runs):.0f} s of data), seed {exp.experiment.seed}; validation: "
                   + (f"{len(validation)} log(s)" if validation else
                      f"{exp.training.val_fraction:g} of each folder's training logs, held out whole "
                      f"(split_seed {exp.training.split_seed})" if exp.training.validation is Validation.FILES else
                      f"{exp.training.val_fraction:g} of every training log's {exp.training.block_s:g}-s blocks"))
    if tests:
        paper = not exp.data.test and exp.experiment.dataset
        logs.info(f"test: {len(tests)} log(s)" + (" (the paper's test files of data set "
                                                  f"{exp.experiment.dataset})" if paper else ""))
    elif exp.experiment.dataset:
        logs.info(f"test: none: training opens no test file; score the run on the paper's test files of data set "
                  f"{exp.experiment.dataset} with sysid evaluate RUN --data FILES, or name logs with --test")
    else:
        logs.info("test: none (no [data] test in the config, no --test): " + (
            "scored on the validation windows only" if exp.needs_training else
            "nothing to evaluate this MMG on; name test logs in [data] test or with --test"))


def _run_tracked(exp, output: Path, tests, runs, data, resume: bool, overwrite: bool, validation, mlflow):
    """`run_experiment`, logged to MLflow at ``--mlflow`` (a failed run marked FAILED there)."""
    from sysid.runs.lifecycle import run_experiment

    tracker = tracked = None
    if mlflow:
        from sysid.experiment_tracking import EpochLogger, Tracker, config_params
        tracker = Tracker(mlflow, exp.experiment.name)
        tracked = tracker.start(output.name, config_params(exp),
                                tags={"sysid.kind": "run", "sysid.output": str(output.resolve())})
    try:
        result = run_experiment(exp, output, tests, runs, data, log=logs.indented(), resume=resume,
                                overwrite=overwrite, validation=validation,
                                on_epoch=EpochLogger(tracker, tracked) if tracker else None)
    except BaseException:
        if tracker is not None:
            tracker.finish(tracked, status="FAILED")
        raise
    if tracker is not None:
        tracker.finish(tracked, {"run": output}, "FAILED" if result.failure else "FINISHED")
    return result


def _say_result(result, exp, output: Path, tests, start: float) -> None:
    """The test metrics, what training did and the verdict (its last line; on stderr, a
    WARNING, when the model does not beat its baseline); exit 1 for a failed run."""
    from sysid.data.display_units import DisplayUnits

    if tests:
        typer.echo(f"test logs, {RMSE_UNITS}:\n"
                   + result.evaluation.metrics.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    if result.failure:
        typer.secho(f"train: FAILED: {result.failure}; the run in {output} is marked failed", fg=typer.colors.RED, err=True)
        raise SystemExit(1)
    t = result.training
    stops = ", ".join(f"{k}: {v}" for k, v in t.stopped.items()) if t else "not trained"
    detail = ""
    if t is not None:
        steps = []
        if t.identification is not None and t.identification.solver is Solver.LEVENBERG_MARQUARDT:  # no epochs
            steps.append(f"{t.identification.iterations} Levenberg-Marquardt iterations")
        if not steps or "train" in t.stopped:
            steps.append(f"{t.epochs} epochs, best {t.best_epoch}")
        detail = f" ({', '.join(steps)}; {stops})"
    typer.echo(f"train: wrote {output} in {time.perf_counter() - start:.0f} s{detail}")
    if result.verdict is not None:
        units = DisplayUnits.of(exp.data.columns)
        if not units.si and units.verdict_cells(result.verdict):  # the user's units ([data.columns])
            typer.echo(f"verdict in your units (vs {result.verdict.baselines[0]}): "
                       f"{units.verdict_cells(result.verdict)}", err=not result.verdict.beats_baseline)
        if result.verdict.beats_baseline:
            typer.echo("verdict: " + result.verdict.statement())
        else:  # the last line, on stderr
            typer.secho(result.verdict.warning(), fg=typer.colors.YELLOW, err=True)


@app.command()
def reproduce(
    output: Path = typer.Option(Path("reports/reproduction"), "-o", "--output", help="Output directory."),
    data: Optional[Path] = typer.Option(None, "--data", help="Dataset root (default: SYSID_DATA or ../shared/data/frt-ds-esso)."),
    only: Optional[List[str]] = typer.Option(None, "--only", help="Run only these protocol entries (repeatable)."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write report.html and report.pdf too."),
    jobs: Optional[int] = typer.Option(None, "--jobs", help="Runs trained side by side, one worker process each (default: one per core)."),
    seeds: int = typer.Option(1, "--seeds", help="Train every learned model with N seeds (on Ray): cells are seed means ± std."),
    address: Optional[str] = typer.Option(None, "--address", help="With --seeds: join this Ray cluster (HOST:PORT or auto; default: RAY_ADDRESS, else a local Ray)."),
    storage: Optional[str] = typer.Option(None, "--storage", help="With --seeds: Tune's experiment here (a shared path or a URI such as s3://bucket/dir) instead of OUTPUT/tune."),
    mlflow: Optional[str] = typer.Option(None, "--mlflow", help="With --seeds: log every seed run to this MLflow tracking URI (a path: a file store)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output directory (all of it)."),
) -> None:
    """The whole protocol: MMG, NN-only and hybrid on D1 and D2; Tables 7/8 beside the paper's.

    The output directory is moved into place only when every run is done (with a manifest);
    an interrupted reproduction leaves nothing behind.
    """
    from sysid.device import cpu_cores
    from sysid.data.datasets import data_root
    from sysid.protocol.reproduce import reproduce as run_protocol
    from sysid.config import checks

    started = time.perf_counter()
    if jobs is not None:  # on a cluster: its cores, not this machine's
        checks.workers("--jobs", jobs, cluster=address or os.environ.get("RAY_ADDRESS"))
    checks.POSITIVE_COUNT.check("--seeds", seeds)
    cluster = False
    if seeds > 1:
        from sysid.sweep.connect import check_reachable, import_ray, ray_target
        ray_at = ray_target(address)
        check_reachable(ray_at)  # an address nobody answers at: one line in seconds, before any work
        import_ray()  # a clear error now if Ray is not installed
        cluster = ray_at.address is not None
    if mlflow:
        from sysid.experiment_tracking import Tracker
        Tracker(mlflow, "sysid-reproduce")  # a store that cannot be used fails now
    target = claim(output, OutputKind.REPRODUCTION, [data_root(data)], overwrite)
    on_interrupt(f"nothing written to {output} (it is moved into place only when every run is done)")
    with target.staged() as staging:
        summary = run_protocol(staging, data, only, log=logs.info, jobs=jobs or (None if cluster else cpu_cores()),
                               seeds=seeds, address=address, storage=storage, mlflow=mlflow)
    for name in ("table7.md", "table8.md"):
        path = output / name
        if path.is_file():
            typer.echo("\n" + path.read_text())
    if report:
        from sysid.report import build_report
        on_interrupt(f"the reproduction in {output} is complete; its report was not written "
                     f"(sysid report {output} -o {output} writes it)")
        logs.info("report: writing report.html and report.pdf")
        paths = build_report(output, output, logs.indented(), workers=cpu_cores())  # the HTML's figures beside the PDF's pages
        typer.echo(f"report: {paths.html} and {paths.pdf} ({paths.n_figures} figures, {paths.n_pages} pages, "
                   f"{paths.seconds:.0f} s)")
    _say_scorecards(summary, seeds)
    for name, why in (summary.failed or {}).items():
        typer.secho(f"reproduce: run {name} FAILED: {why}", fg=typer.colors.RED, err=True)
    typer.echo(f"reproduce: {output} in {(time.perf_counter() - started) / 60:.1f} min"
               + (f" (runs and tables {summary.seconds / 60:.1f} min, the rest the report)" if report else ""))
    _warn_below_baseline(output)
    if summary.failed:
        raise SystemExit(1)


def _say_scorecards(summary, seeds: int) -> None:
    """Each scorecard per data set (the RMSE cut against MMG-only at 30 s, cells beating the
    paper's hybrid, per scenario) and the kNN gate's off share on the Random test."""
    for card in summary.scorecards:
        model = f"Hybrid (mean over {seeds} seeds)" if seeds > 1 and card.model == "Hybrid" else card.model
        for ds, c in card.datasets.items():
            typer.echo(f"{ds}: {model} vs {card.baseline} at 30 s: {100 * c.reduction_vs_mmg_30s_mean:.0f} % lower RMSE "
                       f"on average (least {100 * c.least_reduction_30s:.0f} %); beats the paper's hybrid on "
                       f"{c.cells_beating_paper_hybrid}/{c.cells} cells" + (f"; {c.nn_text()}" if c.nn_text() else ""))
            typer.echo(f"    30 s cut per scenario: {c.by_scenario_text()}")
    shares = summary.gate_off_share_random_30s or {}
    if shares:
        typer.echo("kNN gate off on the Random test (30 s): " +
                   ", ".join(f"{k} {100 * v:.0f} %" for k, v in shares.items() if v is not None))


def _warn_below_baseline(output: Path) -> None:
    """Every model's verdict, as the report states it: a WARNING on stderr for a model of a
    reproduction that does not beat its physics baseline, a "verdict:" line otherwise, each
    with its verdict's statement (evidence, interval and worst cells). The seeds of
    ``--seeds N`` (``runs/NAME/seed*/``) are members of one model (`seed_mean_verdict`)."""
    from sysid.evaluation.verdict import BaselineVerdict, seed_mean_verdict
    from sysid.runs.rundir import RunDir
    from sysid.store.manifest import seed_order

    runs = output / "runs"
    models: dict[str, list] = {}  # the model's name -> its run's summary, or its seeds'
    def in_seed_order(path: Path) -> tuple:   # seed2 before seed10, as the report reads a seed folder
        return tuple(seed_order(part) if part.startswith("seed") else (0, part) for part in path.parts)

    for path in sorted(runs.glob("**/summary.json"), key=in_seed_order):
        rel = path.parent.relative_to(runs)
        group = rel.parent if rel.name.startswith("seed") and rel.parent != Path(".") else rel
        models.setdefault(group.as_posix(), []).append(RunDir(path.parent).read_summary())
    unjudged = [name for name, summaries in models.items() if any(s.verdict is None for s in summaries)
                and any(s.model.lower() != "mmg" or s.identified for s in summaries)]
    if unjudged:
        typer.echo(f"not judged against a physics baseline (no verdict recorded): {', '.join(unjudged)}; "
                   f"sysid compare {output / 'runs' / unjudged[0]} --against baseline judges one")
    for name, summaries in models.items():
        verdicts = [s.verdict for s in summaries]
        if any(v is None for v in verdicts):
            continue
        verdict = seed_mean_verdict([BaselineVerdict.from_dict(v.to_json()) for v in verdicts])
        seeds = f" ({len(verdicts)} seeds)" if len(verdicts) > 1 else ""
        if not verdict.beats_baseline:
            typer.secho(f"WARNING: run {name}{seeds}: {verdict.statement()}", fg=typer.colors.YELLOW, err=True)
        else:
            typer.echo(f"verdict: run {name}{seeds}: {verdict.statement()}")
