"""``sysid logs check PATH...``: each log's channels against its own GNSS track, as a table."""
from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from sysid.cli.app import app

logs_app = typer.Typer(no_args_is_help=True, help="Logs: check a folder of logs against their own GNSS tracks.")
app.add_typer(logs_app, name="logs")


@logs_app.command("check")
def check(
    paths: List[Path] = typer.Argument(..., help="Log files, folders (searched for .csv and .parquet) or patterns."),
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment config whose [data.columns] maps the "
                                                                 "logs' columns and units (default: the processed "
                                                                 "schema's) and whose [data] rudder_sign_checked "
                                                                 "names the logs whose rudder sign you checked."),
) -> None:
    """Check u, v_m and r of every log against its own track (d(x, y)/dt turned by psi, and
    dpsi/dt), and the rudder's sign against the yaw response: a table of file, channel, factor
    (log / track; for delta_rudder +1 or -1, the sign found), correlation and verdict. Exit
    code 2 with one line per clear mismatch (file, channel, factor or fix)."""
    from sysid.data.consistency import Verdict, report_checks
    from sysid.data.recordings import expand_paths, log_track
    from sysid.errors import DataError

    columns = None
    rudder_sign_checked: tuple[str, ...] = ()
    if config is not None:
        from sysid.config.experiment import load_experiment
        data = load_experiment(config).data
        columns, rudder_sign_checked = data.columns, data.rudder_sign_checked
    files = expand_paths(paths)
    checks, unreadable = [], []
    width = min(48, max(len(f.name) for f in files))
    typer.echo(f"{'file':{width}s} {'channel':>12s} {'factor':>9s} {'corr':>6s}  verdict")
    for f in files:
        try:
            found = log_track(f, columns, rudder_sign_checked)
        except DataError as exc:
            unreadable.append(str(exc))
            typer.echo(f"{f.name[:width]:{width}s} {'-':>12s} {'':>9s} {'':>6s}  unreadable (below)")
            continue
        checks.append(found)
        if not found.checked:
            typer.echo(f"{f.name[:width]:{width}s} {'-':>12s} {'':>9s} {'':>6s}  not checked: {found.reason}")
        for c in found.channels:
            hint = f" ({c.hint})" if c.hint else ""
            typer.echo(f"{f.name[:width]:{width}s} {c.channel:>12s} {c.factor:9.4g} {c.correlation:6.3f}  "
                       f"{c.verdict.value}{hint}")
    bad = sum(len(c.worst(Verdict.MISMATCH)) for c in checks)
    marginal = sum(len(c.worst(Verdict.MARGINAL)) for c in checks)
    typer.echo(f"logs check: {len(files)} log(s), {bad} clear mismatch(es), {marginal} marginal, "
               f"{len(unreadable)} unreadable, {sum(not c.checked for c in checks)} without a track")
    for line in unreadable:
        typer.secho(f"error: {line}", fg=typer.colors.RED, err=True)
    report_checks(checks)  # the clear mismatches: one DataError, a line each (exit 2)
    if unreadable:
        raise SystemExit(2)
