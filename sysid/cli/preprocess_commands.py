"""``sysid synth-raw`` and ``sysid preprocess``: raw 10 Hz logs to processed 1 Hz runs."""
from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid.cli.app import app
from sysid.cli.interrupts import on_interrupt
from sysid.cli.outputs import claim, ship_file
from sysid.store.target import OutputKind
from sysid.errors import DataError

ShipOption = typer.Option("esso_osaka", "--ship", help="Ship name (configs/ships/NAME.toml) or a ship TOML.")


def _parse_dropout(text: str) -> tuple[float, float]:
    from sysid.config import checks

    try:
        start, duration = (float(v) for v in text.split(":"))
    except ValueError:
        raise DataError(f"--dropout {text!r}: expected START:DURATION in seconds, e.g. 100:3") from None
    checks.NON_NEGATIVE_SECONDS.check(f"--dropout {text}: START", start)
    checks.DURATION.check(f"--dropout {text}: DURATION", duration)
    return start, duration


def _parse_latlon(text: Optional[str]) -> Optional[tuple[float, float]]:
    from sysid.config import checks

    if text is None:
        return None
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise DataError(f"--reference {text!r}: expected LAT,LON in degrees") from None
    return checks.LATITUDE.check(f"--reference {text}: LAT", lat), checks.LONGITUDE.check(f"--reference {text}: LON", lon)


@app.command("synth-raw")
def synth_raw(
    processed: Path = typer.Argument(..., help="Processed run (public schema, 10 Hz) to build the truth from."),
    output: Path = typer.Option(..., "-o", "--output", help="Raw log CSV to write; the truth goes to OUTPUT.truth.csv."),
    seed: int = typer.Option(0, "--seed", help="Noise seed."),
    gnss_noise: float = typer.Option(0.015, "--gnss-noise", help="GNSS white noise per antenna and axis [m]."),
    gnss_correlated: float = typer.Option(0.0, "--gnss-correlated", help="Std of a correlated GNSS component [m]."),
    outliers: int = typer.Option(0, "--outliers", help="Number of antenna outliers to inject."),
    dropout: Optional[List[str]] = typer.Option(None, "--dropout", help="GNSS dropout START:DURATION [s] (repeatable, or comma-separated)."),
    dropout_rows: bool = typer.Option(False, "--dropout-rows", help="Drop whole rows instead of emptying GNSS cells."),
    latlon: bool = typer.Option(False, "--latlon", help="Write WGS-84 lat/lon fixes instead of local x/y."),
    reference: Optional[str] = typer.Option(None, "--reference", help="LAT,LON [deg] of the local origin (--latlon)."),
    ship: str = ShipOption,
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing truth file OUTPUT.truth.csv too."),
) -> None:
    """Synthesise a raw 10 Hz log (and its truth) from a processed run."""
    from preprocessing import synth
    from preprocessing.schema import RawLogError
    from sysid.data.csvfiles import read_csv_table
    from sysid.store.files import write_csv
    from sysid.mmg.ship import load_ship
    from sysid.config import checks

    checks.COUNT.check("--seed", seed)
    checks.NOISE.check("--gnss-noise", gnss_noise)
    checks.NOISE.check("--gnss-correlated", gnss_correlated)
    checks.COUNT.check("--outliers", outliers)
    layout = load_ship(ship).sensors
    truth_path = output.with_suffix(".truth.csv")
    inputs = [processed, ship_file(ship)]
    claim(output, OutputKind.FILE, inputs)
    claim(truth_path, OutputKind.FILE, inputs, overwrite, companion=output)
    kwargs = {}
    ref = _parse_latlon(reference)
    if ref is not None:
        kwargs["reference"] = ref
    settings = synth.SynthSettings(
        seed=seed, gnss_noise=gnss_noise, gnss_correlated=gnss_correlated, outliers=outliers,
        dropouts=tuple(_parse_dropout(d) for item in (dropout or []) for d in item.split(",")),
        dropout_rows=dropout_rows,
        latlon=latlon, **kwargs)  # type: ignore[arg-type]
    try:
        run = synth.processed_run(read_csv_table(processed, "a processed run with the header 'name [unit]'"),
                                  processed)
        room = max(0, len(run) - 2 * synth.OUTLIER_MARGIN)
        checks.Range(0, room, whole=True, reason=f"rows of {processed} away from its ends").check("--outliers", outliers)
        result = synth.synthesise(run, layout, settings)
    except (RawLogError, OSError) as exc:
        raise DataError(str(exc)) from None
    write_csv(result.raw, output)
    truth = result.truth.copy()
    truth.columns = [f"{c} [{synth.schema.PROCESSED[c]}]" for c in truth.columns]
    write_csv(truth, truth_path)
    typer.echo(f"wrote {output} ({len(result.raw)} rows) and {truth_path}; "
               f"{len(result.outliers)} outlier(s), {len(result.dropouts)} dropout(s)")
    for o in result.outliers:
        typer.echo(f"  outlier t={o['t']:.1f} s ({o['kind']})")


@app.command()
def preprocess(
    raw: List[Path] = typer.Argument(..., help="Raw 10 Hz log CSV file(s)."),
    ship: str = ShipOption,
    outdir: Path = typer.Option(..., "-o", "--outdir", help="Directory for processed CSVs and reports (written complete, or not at all)."),
    rate: float = typer.Option(1.0, "--rate", help="Output rate [Hz] (divides 10 Hz)."),
    jobs: int = typer.Option(1, "--jobs", "-j", help="Parallel worker processes."),
    max_gap: float = typer.Option(1.0, "--max-gap", help="Interpolate gaps up to this long [s]; longer ones split."),
    reference: Optional[str] = typer.Option(None, "--reference", help="LAT,LON [deg] of the local origin for lat/lon logs."),
    swap_antennas: bool = typer.Option(False, "--swap-antennas", help="Repair logs whose fore/aft antennas are swapped."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output directory (all of it)."),
    rudder_sign_checked: Optional[List[str]] = typer.Option(None, "--rudder-sign-checked", help="A raw log (file name without .csv) whose rudder sign you have checked, read as it is when the rudder check reads it reversed (tugs, wind, current, little rudder); repeat for several. Name it in [data] rudder_sign_checked when you train."),
) -> None:
    """Preprocess raw logs into processed 1 Hz runs plus a JSON quality report per run.

    The output directory is written beside its final place and moved there when every file
    is done; files that fail are reported and left out, the others are complete.
    """
    from preprocessing import pipeline
    from sysid.config import checks
    from sysid.mmg.ship import load_ship

    checks.RATE.check("--rate", rate)
    checks.NON_NEGATIVE_SECONDS.check("--max-gap", max_gap)
    checks.workers("--jobs", jobs)
    try:
        settings = pipeline.PreprocessSettings(
            output_rate=rate, max_interp_gap=max_gap, reference=_parse_latlon(reference),
            swapped_antennas="repair" if swap_antennas else "error")
    except ValueError as exc:
        raise DataError(f"--rate {rate:g}: {exc}" if "output_rate" in str(exc) else str(exc)) from None
    _check_inputs(raw, outdir)
    target = claim(outdir, OutputKind.PREPROCESSING, [*raw, ship_file(ship)], overwrite)  # before any work
    layout = load_ship(ship).sensors
    paths = [str(p) for p in raw]
    start = time.perf_counter()
    on_interrupt(f"nothing written to {outdir} (it is moved into place only when every file is done)")
    with target.staged() as staging:
        results = _processed(paths, layout, settings, staging, jobs, outdir)
        _check_tracks(results, tuple(rudder_sign_checked or ()))  # a clear mismatch: nothing moved into place
    order = {p: i for i, p in enumerate(paths)}
    results.sort(key=lambda r: order[r["file"]])
    _summary(results, outdir, time.perf_counter() - start)
    failed = [r for r in results if not r["ok"]]
    if failed:  # (typer.Exit is swallowed by standalone_mode=False)
        raise SystemExit(_failure_code(failed))


def _failure_code(failed: list[dict]) -> int:
    """The exit code of failed files: 2 when every one is bad input (the log's fault, its line
    names file, column and fix), 1 when any is sysid's own failure."""
    return 2 if all(r.get("bad_input") for r in failed) else 1


def _check_inputs(raw: List[Path], outdir: Path) -> None:
    """Exit 2 for two raw logs of one file name (their outputs would collide) or one that is
    not a file (a directory: how many logs it holds)."""
    stems: dict[str, Path] = {}
    for p in raw:
        if p.stem in stems:
            raise DataError(f"{p}: same file name as {stems[p.stem]}; outputs would collide in {outdir}")
        stems[p.stem] = p
    for p in raw:
        if p.is_dir():
            logs = sorted(q.name for q in p.glob("*.csv") if not q.name.endswith(".truth.csv"))
            held = f"it holds {len(logs)} .csv file(s): give them, e.g. {p / '*.csv'}" if logs else "it holds no .csv file"
            raise DataError(f"{p}: is a directory, not a raw log; {held}")
        if not p.is_file():
            from sysid.data.csvfiles import not_a_file
            raise DataError(f"{p}: {not_a_file(p)}")


def _processed(paths: list[str], layout, settings, staging: Path, jobs: int, outdir: Path) -> list[dict]:
    """Every raw log preprocessed into `staging` (in `jobs` worker processes); each file's
    result. A file that cannot be written (a full disk) keeps none; exit 2 when no file
    could be processed (1 when sysid itself failed on one)."""
    from preprocessing import pipeline
    from sysid.progress import progress
    from sysid.workers import in_workers

    results: list[dict] = []
    bar = progress(total=len(paths), unit="files", desc="preprocess")
    if jobs > 1 and len(paths) > 1:
        work = functools.partial(pipeline.process_file, layout=layout, settings=settings, outdir=str(staging))
        results = in_workers(work, paths, jobs, on_result=lambda r: bar.update())
    else:
        for p in paths:
            results.append(pipeline.process_file(p, layout, settings, str(staging)))
            bar.update()
    bar.close()
    unwritten = next((r for r in results if r.get("write_error") is not None), None)
    if unwritten is not None:  # the output cannot be written (a full disk): no file is kept
        from sysid.store.files import write_failure
        raise write_failure(OSError(unwritten["write_error"], unwritten["error"]), outdir)
    if not any(r["ok"] for r in results):
        for r in results:
            typer.secho(f"error: {r['error']}", fg=typer.colors.RED, err=True)
        raise SystemExit(_failure_code(results))  # nothing to move into place: no output directory at all
    return results


def _check_tracks(results: list[dict], rudder_sign_checked: tuple[str, ...] = ()) -> None:
    """Each processed output against its own GNSS track (`sysid.data.consistency`): a clear
    mismatch is a `DataError`, a line per output naming the raw log; a marginal one a warning.
    The outputs of a raw log named in `rudder_sign_checked` (its file's stem) are kept whatever
    their rudder check says, with a warning."""
    from sysid import logs
    from sysid.data.consistency import Verdict
    from sysid.data.recordings import log_track

    errors = []
    for r in results:
        for out in r.get("outputs", []) if r["ok"] else []:
            if not out.endswith(".csv"):
                continue
            checked = Path(r["file"]).stem in rudder_sign_checked
            found = log_track(out, rudder_sign_checked=(Path(out).stem,) if checked else ())
            where = f"{r['file']}: its processed log {Path(out).name}"
            errors += [f"{where}: {c.sentence()} (the raw log's units or signs; docs: Input formats)"
                       + (_rudder_fix(r["file"], out) if c.channel == "delta_rudder" else "")
                       for c in found.worst(Verdict.MISMATCH)]
            for c in found.worst(Verdict.MARGINAL):
                logs.warning(f"{where}: {c.sentence()} (marginal; docs: Input formats, the track check)")
            if (rudder := found.rudder_overridden) is not None:
                logs.warning(f"{where}: delta_rudder: the rudder check reads the sign reversed (partial correlation "
                             f"{rudder.correlation:.2f}); kept as it is: --rudder-sign-checked names the raw log")
    if errors:
        raise DataError("\n".join(errors))


def _rudder_fix(raw: str, out: str) -> str:
    """The second fix of a processed log's refused rudder sign: the raw log named with
    --rudder-sign-checked, and the processed one in [data] rudder_sign_checked to train."""
    return (f"; or, if you have checked its rudder sign and it is right (tugs, wind, current or little rudder can "
            f"fool this check), give --rudder-sign-checked {Path(raw).stem} and, to train, "
            f'[data] rudder_sign_checked = ["{Path(out).stem}"]')


def _summary(results: list[dict], outdir: Path, seconds: float) -> None:
    """One screen: a line per file (the first 20, then only those split into segments),
    totals, and failures as one-line errors."""
    typer.echo(f"{'file':34s} {'seg':>3s} {'dur[s]':>7s} {'base-rej':>8s} {'gate-rej':>8s} "
               f"{'gaps i/s':>8s} {'bias[deg/10min]':>15s}")
    ok = [r for r in results if r["ok"]]
    shown = [r for i, r in enumerate(ok) if i < 20 or len(r["report"].segments) > 1]
    for r in shown:
        rep = r["report"]
        bias = rep.fog_bias_rad_s["mean"] * 600 * 180 / 3.141592653589793
        typer.echo(f"{Path(r['file']).name[:34]:34s} {len(rep.segments):3d} {rep.kept_s:7.0f} "
                   f"{rep.baseline.rejected:8d} {rep.heading_gate.rejected:8d} "
                   f"{rep.gaps_interpolated:>4d}/{rep.gaps_split:<3d} {bias:15.2f}")
    for r in results:
        if not r["ok"]:
            typer.secho(f"error: {r['error']}", fg=typer.colors.RED, err=True)
    if len(shown) < len(ok):
        typer.echo(f"... {len(ok) - len(shown)} more file(s) with one segment each")
    rej = sum(r["report"].baseline.rejected + r["report"].heading_gate.rejected for r in ok)
    segs = sum(len(r["report"].segments) for r in ok)
    typer.echo(f"{len(ok)} of {len(results)} file(s) processed into {outdir} in {seconds:.1f} s: "
               f"{segs} segment(s), {rej} GNSS sample(s) rejected"
               + (f"; {len(results) - len(ok)} FAILED" if len(ok) < len(results) else ""))
