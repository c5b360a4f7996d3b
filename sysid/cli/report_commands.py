"""``sysid report RUN_OR_REPRODUCE_DIR -o reports/NAME``: report.html and report.pdf."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from sysid import logs
from sysid.cli.app import app
from sysid.cli.outputs import claim
from sysid.store.target import OutputKind


@app.command()
def report(
    source: Path = typer.Argument(..., help="Run directory (sysid train), reproduction directory (sysid reproduce) or maneuvers directory (sysid maneuver)."),
    out: Path = typer.Option(None, "-o", "--out", help="Output directory [default: reports/<source name>]."),
    sweep: Optional[List[Path]] = typer.Option(None, "--sweep", help="A sweep directory (sysid sweep) whose validation landscape and chosen configuration the report shows beside (repeatable)."),
) -> None:
    """Write an accuracy report (self-contained HTML and page-numbered PDF) for a run or a reproduction."""
    from sysid.device import cpu_cores
    from sysid.report import build_report
    from sysid.report.maneuver_report import build_maneuver_report, is_maneuvers_directory

    out = out or Path("reports") / source.resolve().name
    sweeps = list(sweep or [])
    claim(out, OutputKind.REPORT, [source, *sweeps], adds_to=source)
    if is_maneuvers_directory(source):  # sysid maneuver's output has a report of its own
        paths = build_maneuver_report(source, out)
    else:
        paths = build_report(source, out, logs.indented(), sweeps, workers=cpu_cores())
    typer.echo(f"report: {paths.html}")
    typer.echo(f"        {paths.pdf} ({paths.n_pages} pages, {paths.n_figures} figures, {paths.seconds:.1f} s)")
    for note in paths.notes:
        typer.secho(f"  note: {note}", fg=typer.colors.YELLOW)
