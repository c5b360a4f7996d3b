"""``sysid sweep``: many configurations and seeds on Ray (local or a cluster)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Optional

import typer

from sysid import logs
from sysid.cli.app import app
from sysid.cli.outputs import claim, experiment_inputs
from sysid.store.target import OutputKind


@app.command()
def sweep(
    sweep_file: Path = typer.Argument(..., help="Sweep TOML (configs/sweeps/*.toml): base config, [vary], seeds."),
    output: Path = typer.Option(..., "-o", "--output", help="Sweep directory to write (trials/, results.csv, ...)."),
    address: Optional[str] = typer.Option(None, "--address", help="Join this Ray cluster: HOST:PORT of its head, or auto (default: RAY_ADDRESS, else a local Ray of the sweep's own)."),
    workers: Optional[int] = typer.Option(None, "--workers", help="Trials side by side (default: one per core locally, one per CPU on a cluster)."),
    resume: bool = typer.Option(False, "--resume", help="Continue an interrupted sweep: finished trials are kept."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing sweep directory."),
    data: Optional[Path] = typer.Option(None, "--data", help="The paper's FRT-DS-ESSO root, read only when the config names dataset = \"D1\" or \"D2\" (default: SYSID_DATA or ../shared/data/frt-ds-esso)."),
    storage: Optional[str] = typer.Option(None, "--storage", help="Tune's experiment in STORAGE/NAME ([sweep] name) instead of OUTPUT/tune: a folder (the rules of -o: not an input, nor a folder of the sweep's logs) or a URI such as s3://bucket/dir."),
    mlflow: Optional[str] = typer.Option(None, "--mlflow", help="Log the sweep and every trial to this MLflow tracking URI (a path: a file store); overrides [tracking] mlflow."),
) -> None:
    """Train every configuration x seed of a sweep on Ray Tune; choose on validation loss.

    Each trial is an ordinary run directory (sysid evaluate / sysid report read it),
    trained on any node of the cluster and sent back to OUTPUT; the data are read here
    and shipped to the trials. A crashed trial, or one whose node is lost, is retried
    from its last epoch ([sweep] max_retries); after an interruption, --resume continues
    without training a finished trial again. [sweep] scheduler stops poor trials early.
    """
    from sysid.cli.interrupts import on_interrupt
    from sysid.config import checks
    from sysid.sweep import load_sweep, run_sweep

    start = time.perf_counter()
    from sysid.sweep.connect import check_reachable, ray_target
    target = ray_target(address)
    if workers is not None:  # on a cluster: its cores, not this machine's
        checks.workers("--workers", workers, cluster=target.address)
    check_reachable(target)  # an address nobody answers at: one line in seconds, before any work
    spec = load_sweep(sweep_file)
    inputs = [sweep_file, spec.base_path, *experiment_inputs(spec.base, data)]
    claim(output, OutputKind.SWEEP, inputs, overwrite, resume=resume)
    on_interrupt(f"finished trials are kept in {output}/trials; rerun with --resume to continue the sweep")
    from sysid.cli.outputs import release
    from sysid.sweep.connect import on_cluster_lost
    on_cluster_lost(release)   # a cluster lost mid-sweep ends the process: its lock goes first
    results, summary = run_sweep(spec, output, workers, address, resume, overwrite, data,
                                 log=logs.info, storage=storage, mlflow=mlflow)
    if len(results.points):
        shown = results.points.head(10)
        typer.echo(shown.to_string(index=False, float_format=lambda v: f"{v:.5g}"))
    best = summary.best
    if best:
        spread = (f" ± {best.val_loss_multistep_std:.5f} (std over seeds)"
                  if best.val_loss_multistep_std is not None else "")
        typer.echo(f"sweep: chosen {best.point}: val_loss_multistep {best.val_loss_multistep_mean:.5f}{spread}")
    counts = f"{summary.complete}/{summary.trials} trials complete"
    if summary.stopped_early:
        counts += f", {summary.stopped_early} stopped early by the {summary.scheduler} scheduler"
    if summary.failed or summary.missing:
        counts += f", {summary.failed} failed, {summary.missing} missing"
    typer.echo(f"sweep: {counts}; wrote {output} in {(time.perf_counter() - start) / 60:.1f} min "
               f"(Tune's experiment: {summary.tune_at(output)})")
    if summary.failed or summary.missing:
        for row in results.trials.itertuples():
            if row.status not in ("complete", "stopped early"):
                typer.secho(f"sweep: {row.run}: {row.status}", fg=typer.colors.RED, err=True)
        raise SystemExit(1)
