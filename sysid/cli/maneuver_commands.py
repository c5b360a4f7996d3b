"""``sysid maneuver MODEL -o DIR``: standard maneuvers of any model, indices, IMO criteria, report."""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import List, Optional

import typer

from sysid.cli.app import app
from sysid.cli.interrupts import on_interrupt
from sysid.fast.payoff import MANEUVER_REPAY_STEPS

LIMITS = {  # option -> (low, high, unit): finite numbers inside, else one line naming the option
    "--speed": (1e-3, 50.0, "m/s"), "--rps": (-200.0, 200.0, "rps"), "--rudder-rate": (0.1, 100.0, "deg/s"),
    "--dt": (1e-4, 10.0, "s"), "--duration": (1e-3, 1e5, "s"),
}
MAX_STEPS = 2_000_000  # duration / dt beyond this: surely a typo


def _error(message: str):
    from sysid.maneuvers import ManeuverError
    return ManeuverError(message)


def _number(option: str, text: str, unit: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _error(f"{option} {text!r}: not a number [{unit}] (give MODEL before the options)") from None
    if not math.isfinite(value):
        raise _error(f"{option} {text!r}: must be a finite number [{unit}]")
    return value


def _check(option: str, value: float | None) -> float | None:
    if value is None:
        return None
    low, high, unit = LIMITS[option]
    if not (math.isfinite(value) and low <= value <= high):
        raise _error(f"{option} {value:g}: must be a finite number in [{low:g}, {high:g}] {unit}")
    return value


def parse_maneuvers(turning: list[str], zigzag: list[str], crash_stop: bool, side: str):
    """The maneuvers the options ask for (`sysid.maneuvers.base` specs); none asked: IMO's
    (35 deg turning, 10/10 and 20/20 zig-zag on `side`, crash stop)."""
    from sysid.maneuvers import CrashStop, Side, TurningCircle, ZigZag, imo_maneuvers

    if side not in ("port", "starboard", "both"):
        raise _error(f"--side {side!r}: choose port, starboard or both")
    sides = (Side.STARBOARD, Side.PORT) if side == "both" else (Side(side),)
    if not (turning or zigzag or crash_stop):
        return imo_maneuvers(sides)
    out: list[TurningCircle | ZigZag | CrashStop] = []
    for text in turning:
        angle = _number("--turning", text, "deg")
        out += [TurningCircle(angle, s) for s in sides]
    for text in zigzag:
        parts = text.split("/")
        if len(parts) != 2:
            raise _error(f"--zigzag {text!r}: expected RUDDER/CHECK in deg, e.g. 10/10")
        rudder, check = (_number("--zigzag", p, "deg") for p in parts)
        out += [ZigZag(rudder, check, s) for s in sides]
    if crash_stop:
        out.append(CrashStop())
    names = [m.name for m in out]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise _error(f"maneuver {repeated[0]} asked for twice")
    return out


def parse_wind(text: str | None) -> tuple[float, float]:
    """``"V,DIR"`` -> (speed [m/s], direction it comes from [rad]); DIR in deg."""
    if text is None:
        return 0.0, 0.0
    parts = text.split(",")
    if len(parts) != 2:
        raise _error(f"--wind {text!r}: expected SPEED,DIRECTION (m/s, deg the wind comes from), e.g. 2,45")
    speed, direction = _number("--wind", parts[0], "m/s"), _number("--wind", parts[1], "deg")
    if not 0.0 <= speed <= 100.0:
        raise _error(f"--wind {text!r}: speed {speed:g} m/s must be in [0, 100]")
    if not -360.0 <= direction <= 360.0:  # far beyond, cos and sin of it are rounding noise
        raise _error(f"--wind {text!r}: direction {direction:g} deg must be in [-360, 360] (the direction the "
                     "wind comes from, e.g. 45)")
    return speed, math.radians(direction)


@app.command()
def maneuver(
    model: Path = typer.Argument(..., help="Ship file or bundled ship name (its MMG), run directory (MMG, identified, "
                                           "NN-only, hybrid, ensemble) or folder of seed run directories."),
    output: Path = typer.Option(..., "-o", "--output", help="Directory to write (indices.csv, criteria.csv, "
                                                             "trajectories.csv, maneuvers.json, report.html/.pdf)."),
    turning: Optional[List[str]] = typer.Option(None, "--turning", help="Turning circle, rudder [deg] (several)."),
    zigzag: Optional[List[str]] = typer.Option(None, "--zigzag", help="Zig-zag RUDDER/CHECK [deg], e.g. 10/10."),
    crash_stop: bool = typer.Option(False, "--crash-stop", help="Crash stop: minus the approach revolutions."),
    side: str = typer.Option("both", "--side", help="Side of the first rudder order: port, starboard or both."),
    speed: Optional[float] = typer.Option(None, "--speed", help="Approach speed U0 [m/s] (default: the ship file's)."),
    rps: Optional[float] = typer.Option(None, "--rps", help="Propeller revolutions [rps] (default: those holding U0)."),
    rudder_rate: Optional[float] = typer.Option(None, "--rudder-rate", help="Steering rate [deg/s] (default: the ship "
                                                "file's, or 2.32 deg/s at full scale Froude-scaled)."),
    dt: float = typer.Option(0.1, "--dt", help="Integration step [s]."),
    duration: Optional[float] = typer.Option(None, "--duration", help="Time after the execute [s] (default: 80 L/U0)."),
    wind: Optional[str] = typer.Option(None, "--wind", help="True wind SPEED,DIRECTION [m/s, deg from]; calm."),
    integrator: str = typer.Option("rk4", "--integrator", help="rk4 (classical) or euler."),
    compiled: Optional[bool] = typer.Option(None, "--compiled/--eager", show_default=False,
                                            help="Force the compiled loop (compiled once per model, cached) or the "
                                                 "eager step. Default: the compiled loop when every model's loop is "
                                                 "in the cache, or when the eager steps (duration / dt per model) "
                                                 f"reach {MANEUVER_REPAY_STEPS} per loop not yet cached; else eager "
                                                 "(decided from the "
                                                 "step count and the cache alone)."),
    recorded: Optional[List[Path]] = typer.Option(None, "--recorded", help="Logs or folders of logs: their turning "
                                                  "circles and zig-zags (recognised from rudder and heading) beside "
                                                  "the model's, like for like (recorded_indices.csv)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Experiment config whose [data.columns] maps the "
                                                                 "--recorded logs' columns and units (default: the "
                                                                 "run directory's)."),
    baseline: bool = typer.Option(True, "--baseline/--no-baseline", help="Of a learned model (NN-only, hybrid, "
                                  "their ensembles or seeds): run the same maneuvers under the same conditions with "
                                  "its physics baseline, the MMG of its ship file, and show it beside."),
    report: bool = typer.Option(True, "--report/--no-report", help="Write report.html and report.pdf too."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output directory (all of it)."),
) -> None:
    """Turning circles, zig-zags and a crash stop of any model: IMO indices and criteria, trajectories, report;
    a learned model beside its physics baseline (the MMG of its ship file)."""
    from sysid.cli.outputs import claim, ship_file
    from sysid.store.target import OutputKind

    start = time.perf_counter()
    method, wind_from, maneuvers = _checked_options(speed, rps, rudder_rate, dt, duration, integrator, wind,
                                                    turning or [], zigzag or [], crash_stop, side)
    source = model if model.is_dir() else ship_file(model)  # what the command reads
    target = claim(output, OutputKind.MANEUVERS, [source, *(recorded or []), config], overwrite)  # a bad -o fails now
    subject, logged, maneuvers = _loaded(model, maneuvers, bool(turning or zigzag or crash_stop), recorded, config)
    physics = _baseline_of(subject, baseline)
    conditions, sources = _approach(subject, maneuvers, speed, rps, rudder_rate, dt, duration, wind_from, method)
    on_interrupt(f"nothing written to {output} (it is moved into place only when complete)")
    results, shown, compiled, seconds = _simulated(subject, physics, maneuvers, conditions, compiled)
    compared = _written(target, subject, physics, conditions, sources, results, shown, compiled, seconds, logged,
                        report)
    _say_outcome(output, results, shown, compared, subject.model)
    typer.echo(f"maneuver: {output} ({seconds:.1f} s simulating, {time.perf_counter() - start:.1f} s in all)")


def _checked_options(speed, rps, rudder_rate, dt: float, duration, integrator: str, wind: str | None,
                     turning: list[str], zigzag: list[str], crash_stop: bool, side: str):
    """The options checked and parsed, each bad one a `ManeuverError` naming it: the
    integrator (`Method`), the wind (speed [m/s], direction it comes from [rad]) and the
    maneuvers asked for."""
    from sysid.config.choices import Method

    for option, value in (("--speed", speed), ("--rps", rps), ("--rudder-rate", rudder_rate), ("--dt", dt),
                          ("--duration", duration)):
        _check(option, value)
    try:
        method = Method.parse(integrator, "--integrator", offered_only=True)
    except ValueError as exc:
        raise _error(str(exc)) from None
    if duration is not None and duration / dt > MAX_STEPS:
        raise _error(f"--duration {duration:g} s at --dt {dt:g} s: {duration / dt:.0f} steps, more than {MAX_STEPS}")
    wind_from = parse_wind(wind)
    return method, wind_from, parse_maneuvers(turning, zigzag, crash_stop, side)


def _loaded(model: Path, maneuvers: list, asked: bool, recorded: Optional[List[Path]], config: Optional[Path]):
    """The model to maneuver (`load_maneuver_model`), the --recorded logs' runs, and the
    maneuvers it can run: IMO's without the crash stop (said) when the propeller model is
    for ahead motion only and no maneuver was `asked` for."""
    from sysid.maneuvers import load_maneuver_model
    from sysid.maneuvers.simulate import ahead_only

    subject = load_maneuver_model(model)
    logged = _recorded_runs(recorded or [], config, subject.columns)
    if not asked and ahead_only(subject.model):
        maneuvers = [m for m in maneuvers if m.kind != "crash_stop"]
        typer.echo(f"maneuver: no crash stop: the propeller model {subject.ship.models.get('propeller')!r} is for "
                   "ahead motion only")
    return subject, logged, maneuvers


def _baseline_of(subject, wanted: bool):
    """The physics baseline of a learned subject (`physics_baseline`), said in one line;
    None for an MMG, or with --no-baseline (said)."""
    from sysid.maneuvers import physics_baseline

    physics = physics_baseline(subject)
    if physics is None:
        return None
    if not wanted:
        typer.echo(f"maneuver: --no-baseline: {subject.label} ({subject.kind}) is shown without its physics baseline")
        return None
    typer.echo(f"maneuver: beside {subject.label} ({subject.kind}): its physics baseline {physics.label}, the MMG of "
               f"{subject.ship.source or subject.ship.name}, with the same maneuvers and conditions")
    return physics


def _approach(subject, maneuvers: list, speed, rps, rudder_rate, dt: float, duration, wind_from, method):
    """The approach conditions (`default_conditions`) and where each came from, said in one line."""
    from sysid.maneuvers import default_conditions

    wind_speed, wind_direction = wind_from
    conditions, sources = default_conditions(subject.model, subject.ship, speed=speed, rps=rps,
                                             rudder_rate=rudder_rate, dt=dt, duration=duration,
                                             wind_speed=wind_speed, wind_direction=wind_direction,
                                             method=method)
    if conditions.steps > MAX_STEPS:
        raise _error(f"duration {conditions.duration:g} s at --dt {dt:g} s: {conditions.steps} steps, "
                     f"more than {MAX_STEPS}")
    members = f", spread over {len(subject.members)} {subject.spread}" if subject.members else ""
    typer.echo(f"maneuver: {len(maneuvers)} maneuvers of {subject.label} ({subject.kind}{members}); "
               f"U0 {conditions.speed:.4g} m/s ({sources['speed']}), n {conditions.rps:.4g} rps ({sources['rps']}), "
               f"rudder rate {conditions.rudder_rate:.3g} deg/s ({sources['rudder_rate']}), dt {conditions.dt:g} s, "
               f"{conditions.duration:g} s ({sources['duration']}), {conditions.method.value}")
    return conditions, sources


def _simulated(subject, physics, maneuvers: list, conditions, compiled: Optional[bool]):
    """The maneuvers run on the chosen path (`choose_loop` over every model, the physics
    baseline's too, said): the results, the baseline's (`run_baseline`: results and the
    maneuvers it cannot run; None without a baseline), whether the compiled loop ran, and
    the seconds simulating."""
    from sysid.maneuvers import run_baseline, run_maneuvers
    from sysid.maneuvers.simulate import choose_loop

    simulated = time.perf_counter()
    models = [subject.model, *(m for _, m in subject.members), *([physics.model] if physics else [])]
    choice = choose_loop(models, maneuvers, conditions, compiled)
    typer.echo(f"maneuver: {choice.reason}")
    results = run_maneuvers(subject, maneuvers, conditions, compiled=choice.compiled)
    shown = None
    if physics is not None:
        shown = run_baseline(physics, maneuvers, conditions, compiled=choice.compiled)
        if shown[1]:
            typer.echo(f"maneuver: {physics.label} does not run {', '.join(shown[1])}: the propeller model "
                       f"{physics.ship.models.get('propeller')!r} is for ahead motion only")
    return results, shown, choice.compiled, time.perf_counter() - simulated


def _written(target, subject, physics, conditions, sources, results, shown, compiled: bool, seconds: float,
             logged: dict, report: bool):
    """The output directory written (staged, moved into place when complete): the maneuvers'
    files (the physics baseline's rows after the model's), the comparison with the
    --recorded logs (returned; None without; the baseline's predictions of them too) and
    the report."""
    from sysid.maneuvers.outputs import summary_document, write_maneuvers

    beside, left_out = shown if shown is not None else (None, ())
    summary = summary_document(subject.label, subject.kind, subject.ship, conditions, sources, results, compiled,
                               seconds, subject.spread, beside, left_out)
    compared = None
    with target.staged() as staging:
        write_maneuvers(staging, results, subject.ship, conditions, summary, beside or ())
        if logged:
            compared = _against_record(staging, subject, physics, logged)
        if report:
            from sysid.report.maneuver_report import build_maneuver_report
            build_maneuver_report(staging)
    return compared


def _say_outcome(output: Path, results, shown, compared, model=None) -> None:
    """The indices (beside the physics baseline's, if any), the comparison with the recorded
    maneuvers (if any), and warnings for diverged maneuvers and for maneuvers mostly outside
    the kNN gate's training data."""
    from sysid.maneuvers.outputs import MOSTLY_OUTSIDE

    _print_results(output, results)
    if shown is not None and results:
        _print_beside(output, results[0].model)
    if compared is not None:
        _print_record(compared)
    beside = shown[0] if shown is not None else []
    diverged = [own for r in [*results, *beside] for own in (r, *r.members) if own.diverged]
    if diverged:
        typer.secho("WARNING: diverged (indices not valid): " + "; ".join(
            f"{own.maneuver.name} ({own.model}) at t = {own.diverged_at_s:.1f} s, {own.divergence}" for own in diverged),
            fg=typer.colors.YELLOW, err=True)
    _print_gate(results, model)
    for r in results:
        if r.gate_off_share is not None and r.gate_off_share > MOSTLY_OUTSIDE:
            typer.secho(f"  {r.maneuver.name}: kNN gate off on {100 * r.gate_off_share:.1f} % of the steps: the "
                        "maneuver runs mostly outside the training data (the FNN is switched off there)",
                        fg=typer.colors.YELLOW)


def _print_gate(results, model=None) -> None:
    """Of a model with a kNN gate: per maneuver, the share of its steps outside the training
    data (gate off: the FNN switched off; `gate_off_meaning` of the model) and its largest
    d_kNN against the gate's threshold."""
    from sysid.hybrid.force_models import gate_off_meaning
    gated = [r for r in results if r.gate_off_share is not None]
    if not gated:
        return
    threshold = next((r.knn_threshold for r in gated if r.knn_threshold is not None), None)
    shown = f"threshold {threshold:.4g}" if threshold is not None else "each member's own threshold"
    typer.echo(f"outside the training data (kNN gate, {shown}; where it is off, {gate_off_meaning(model)}; "
               "per step in trajectories.csv: gate_on, knn_distance):")
    for r in gated:
        largest = f", largest d_kNN {r.knn_distance_max:.4g}" if r.knn_distance is not None else ""
        typer.echo(f"  {r.maneuver.name}: gate off on {100 * r.gate_off_share:.1f} % of the steps{largest}")


def _recorded_runs(paths: list[Path], config: Optional[Path], run_columns=None):
    """label -> run of the turning circles and zig-zags among the logs of `paths` (read
    and checked, through the config's [data.columns], else the run's `run_columns`); {}
    without --recorded."""
    if not paths:
        if config is not None:
            raise _error("--config maps the columns of --recorded logs: give --recorded too")
        return {}
    from sysid.data.recordings import expand_paths, read_runs
    from sysid.maneuvers.recorded import recorded_maneuver_runs

    columns = run_columns
    checked: tuple[str, ...] = ()
    if config is not None:
        from sysid.config.experiment import load_experiment
        data = load_experiment(config).data
        columns, checked = data.columns, data.rudder_sign_checked
    runs = read_runs(expand_paths(paths), columns=columns, rudder_sign_checked=checked)
    found, other = recorded_maneuver_runs(runs)
    if not found:
        raise _error(f"--recorded: none of the {len(runs)} log(s) is a turning circle or a zig-zag (recognised "
                     "from the rudder and heading: docs/maneuvers.md)")
    typer.echo(f"maneuver: {len(found)} recorded maneuver(s) in {len(runs)} log(s): {', '.join(found)}"
               + (f"; {len(other)} other log(s) left out" if other else ""))
    return found


def _against_record(staging: Path, subject, physics, logged):
    """recorded_indices.csv in `staging`: the logged maneuvers' indices beside the model's
    and its physics baseline's (if any) (`sysid.maneuvers.recorded.record_comparison`); the
    frame."""
    from sysid.maneuvers.recorded import record_comparison
    from sysid.store.files import write_csv

    members = [m for _, m in subject.members] if subject.spread == "seeds" else [subject.model]
    models = {subject.label: members, **({physics.label: [physics.model]} if physics is not None else {})}
    frame = record_comparison(models, logged)
    write_csv(frame, staging / "recorded_indices.csv", float_format="%.6g")
    return frame


def _print_record(frame) -> None:
    import pandas as pd
    from sysid.maneuvers.recorded import differences

    wide = differences(frame).drop(columns=["maneuver"])
    with pd.option_context("display.width", 160, "display.max_columns", 20, "display.float_format", "{:.3f}".format):
        typer.echo(wide.to_string(index=False, na_rep=""))


def _print_results(output: Path, results) -> None:
    import pandas as pd

    frame = pd.read_csv(output / "indices.csv")
    shown = [c for c in frame.columns if c.endswith(("_m", "_deg", "_ratio")) and frame[c].notna().any()]
    several = frame["model"].nunique() > 1  # a learned model and its physics baseline
    with pd.option_context("display.width", 160, "display.max_columns", 20, "display.float_format", "{:.3f}".format):
        typer.echo(frame[["maneuver", *(["model"] if several else []), *shown]].to_string(index=False, na_rep=""))
    criteria = pd.read_csv(output / "criteria.csv")
    for row in criteria.itertuples(index=False):
        typer.echo(f"  IMO {row.maneuver}{f' ({row.model})' if several else ''}: {row.rule}: {row.met}")


def _print_beside(output: Path, learned: str) -> None:
    """Each index of the learned model beside its physics baseline's, and the difference."""
    import pandas as pd
    from sysid.maneuvers import BASELINE_LABEL
    from sysid.maneuvers.outputs import beside_baseline

    table = beside_baseline(pd.read_csv(output / "indices.csv"), learned)
    if table.empty:
        return
    typer.echo(f"{learned} beside its physics baseline {BASELINE_LABEL} (same maneuvers and conditions; difference = "
               f"{learned} - {BASELINE_LABEL}; no pass/fail rule for indices: docs/maneuvers.md):")
    table = table.rename(columns={"learned": learned, "baseline": BASELINE_LABEL})
    if not (table["diverged"] != "").any():
        table = table.drop(columns="diverged")
    with pd.option_context("display.width", 160, "display.max_columns", 20, "display.float_format", "{:.3f}".format):
        typer.echo(table.to_string(index=False, na_rep="NaN"))
