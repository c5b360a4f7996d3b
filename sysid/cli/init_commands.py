"""``sysid init DIR [--ship NAME]``: a project of one's own (ship file, experiment config,
next steps)."""
from __future__ import annotations

from pathlib import Path

import typer

from sysid.cli.app import app


@app.command()
def init(
    folder: Path = typer.Argument(..., help="Project folder (created if missing; may hold your logs already)."),
    ship: str = typer.Option("my_ship", "--ship", help="Your ship's name: names the ship file NAME.toml."),
) -> None:
    """Start a project: a ship file of the standard MMG model (every value commented with its
    unit and source), an experiment config with every key and its meaning, and the next
    steps (printed, and in NEXT_STEPS.md). Existing files are never overwritten."""
    from sysid.cli.outputs import claim
    from sysid.config.templates import project_files
    from sysid.store.project import write_project
    from sysid.store.target import OutputKind

    project = project_files(folder, ship)
    for name in project.files:  # no link, nothing inside a sealed run; locked while written
        claim(project.folder / name, OutputKind.FILE)
    for path in write_project(project):
        typer.echo(f"init: wrote {path}")
    typer.echo("")
    typer.echo(project.steps.rstrip())
