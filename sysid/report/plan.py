"""Which figures a report shows: the paper's scenarios for each figure type (section 4.4),
with the models the paper shows (D2 for comparisons), degraded to what the source holds.

Every figure is a `FigureSpec` with a lazy factory, so the page count is known before any
figure is drawn; a figure whose data is missing is replaced by a note saying why.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import pandas as pd
from matplotlib.figure import FigureBase

from sysid.report import figures as F
from sysid.report.palette import model_colour, model_label
from sysid.report.paper import scenario_key
from sysid.report.quality import FILES_PER_FIGURE, quality_timeline
from sysid.report.source import ReportSource, RunRecord

BOX_SCENARIOS = ["Turning 20", "Zigzag 30/30", "Random"]                 # Figs. 3-5
SERIES_WINDOWS = [("Zigzag 30/30", 0.0), ("Random", 500.0)]              # Figs. 6-9
TRAJECTORY_SCENARIOS = ["Turning 20", "Zigzag 30/30", "Random"]          # Figs. 10-12
KNN_SCENARIOS = ["Turning 20", "Random"]                                 # Figs. 13-16
FORCE_SCENARIOS = ["Turning 20", "Zigzag 30/30"]                         # Figs. 17-20


@dataclass
class FigureSpec:
    key: str
    section: str
    title: str
    caption: str
    factory: Callable[..., FigureBase]  # factory(into=None): into a sub-figure or a new figure


@dataclass
class FigurePlan:
    figures: list[FigureSpec] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _label(run: RunRecord) -> str:
    return model_label(run.name, run.model, run.dataset)


def _colour(run: RunRecord, index: int = 0) -> str:
    return model_colour(run.name, run.model, run.dataset, index)


def _pick(preferred: list[str], available: list[str]) -> list[str]:
    """The preferred scenarios the source has (any spelling), else its first scenario."""
    found = [_find(s, available) for s in preferred]
    return [s for s in found if s is not None] or available[:1]


def _find(scenario: str, available: list[str]) -> str | None:
    """The source's spelling of `scenario`, or None."""
    return next((s for s in available if scenario_key(s) == scenario_key(scenario)), None)


def _horizon(runs: list[RunRecord], wanted: int, short: bool) -> int | None:
    horizons = sorted({h for r in runs for h in r.horizons()})
    if not horizons:
        return None
    if wanted in horizons:
        return wanted
    return horizons[0] if short else horizons[-1]


def _traces(runs: list[RunRecord], scenario: str, horizon: int) -> list[F.ModelTrace]:
    out = []
    for i, run in enumerate(runs):
        frame = run.trace(scenario, horizon)
        if frame is not None and len(frame):
            out.append(F.ModelTrace(_label(run), _colour(run, i), frame))
    return out


def _quality_figures(source: ReportSource, plan: FigurePlan) -> FigurePlan:
    """Timelines of the preprocessing quality reports, FILES_PER_FIGURE files each."""
    chunks = [source.quality[i:i + FILES_PER_FIGURE] for i in range(0, len(source.quality), FILES_PER_FIGURE)]
    for i, chunk in enumerate(chunks, 1):
        part = f" ({i} of {len(chunks)})" if len(chunks) > 1 else ""
        plan.figures.append(FigureSpec(
            f"quality_{i}", "Preprocessing quality", f"Preprocessing quality timeline{part}",
            "Per preprocessed file: kept and dropped segments, gaps split or interpolated, and GNSS fixes "
            "rejected by the antenna-baseline check (above the bar) or the heading gate (below), over the "
            "log's time.", lambda into=None, c=chunk, p=part: quality_timeline(c, f"Preprocessing quality{p}", into=into)))
    return plan


def figure_plan(source: ReportSource, ship_size: tuple[float, float] | None) -> FigurePlan:
    """The figures of a report for `source`; `ship_size` = (L_pp, B) [m] for outlines."""
    plan = FigurePlan()
    runs = source.runs
    if not runs:
        return _quality_figures(source, plan)
    scenarios = list(dict.fromkeys(s for r in runs for s in r.scenarios()))
    datasets = sorted({r.dataset for r in runs if r.model != "mmg" and r.dataset != "-"})
    fig_dataset = "D2" if "D2" in datasets else (datasets[-1] if datasets else None)
    compared = [r for r in runs if r.model == "mmg" or r.dataset == fig_dataset]
    hybrids = [r for r in runs if r.model == "hybrid"]
    trained_on = f" (trained models: {fig_dataset})" if fig_dataset else ""

    def add(key, section, title, caption, factory, needs):
        if needs:
            plan.figures.append(FigureSpec(key, section, title, caption, factory))
        else:
            plan.notes.append(f"{title}: skipped, {caption}")

    short = _horizon(runs, 30, short=True)
    long = _horizon(runs, 100, short=False)
    # Figs. 3-5: absolute-error box plots
    for scenario in _pick(BOX_SCENARIOS, scenarios):
        traces = _traces(runs, scenario, short) if short else []
        add(f"box_{scenario}", "Prediction errors", f"Absolute error, {scenario}, {short} s predictions",
            f"Absolute errors of u, v_m and r pooled over every point of every {short} s window of the "
            f"{scenario} test, per model (cf. the paper's Figs. 3-5)." if traces else "no traces in the source",
            lambda into=None, t=traces, s=scenario: F.error_boxplots(t, f"Absolute error, {s} ({short} s predictions)", into=into),
            traces)
    # Figs. 6-9: actuator/wind and state time series
    series = [(_find(s, scenarios), t0) for s, t0 in SERIES_WINDOWS if _find(s, scenarios)]
    for scenario, start in series or [(s, 0.0) for s in scenarios[:1]]:
        traces = _traces(compared, scenario, long) if long else []
        span = f"{start:.0f}-{start + long:.0f} s" if long else ""
        add(f"inputs_{scenario}", "Time series", f"Actuators and relative wind, {scenario}, {span}",
            f"Propeller speed, rudder angle and relative wind in the {long} s window of the {scenario} test "
            f"starting nearest {start:.0f} s{trained_on}; each model's relative wind follows its own "
            "predicted state, 'measured' uses the recorded state (cf. Figs. 6, 8)." if traces
            else "no traces in the source",
            lambda into=None, t=traces, s=scenario, a=start, sp=span: F.actuator_wind(t, a, f"Actuator and relative wind state, {s} ({sp})", into=into),
            traces)
        add(f"states_{scenario}", "Time series", f"Heading and velocities, {scenario}, {span}",
            f"Heading ψ and velocities u, v_m, r predicted over the {long} s window of the {scenario} test "
            f"against the measurement{trained_on} (cf. Figs. 7, 9)." if traces else "no traces in the source",
            lambda into=None, t=traces, s=scenario, a=start, sp=span: F.state_timeseries(t, a, f"Attitude and velocity, {s} ({sp})", into=into),
            traces)
    # Figs. 10-12: trajectories
    for scenario in _pick(TRAJECTORY_SCENARIOS, scenarios):
        traces = _traces(compared, scenario, long) if long else []
        ok = bool(traces) and ship_size is not None
        L, B = ship_size or (0.0, 0.0)
        add(f"track_{scenario}", "Trajectories", f"Trajectories, {scenario}, {long} s predictions",
            f"Earth-frame track of the {scenario} test and every {long} s window predicted from the recorded "
            f"start state{trained_on}; outlines of the {L:g} m x {B:g} m ship at fixed intervals "
            "(cf. Figs. 10-12)." if ok else ("no traces in the source" if not traces else "ship dimensions unknown"),
            lambda into=None, t=traces, s=scenario: F.trajectories(t, L, B, f"Trajectory prediction, {s} ({long} s windows)", into=into),
            ok)
    # Figs. 13-16: kNN distance
    if not hybrids:
        plan.notes.append("kNN distance (Figs. 13-16): skipped, no hybrid run in the source")
    for scenario in _pick(KNN_SCENARIOS, scenarios) if hybrids else []:
        for run in hybrids:
            frame = run.trace(scenario, short) if short else None
            ok = frame is not None and frame["knn_distance"].notna().any()
            threshold = run.gate_threshold
            add(f"knn_{run.name}_{scenario}", "Out-of-distribution gate",
                f"kNN distance, {scenario}, {_label(run)}",
                f"kNN distance of the hybrid model's inputs ({_label(run)}) in the {short} s predictions of the "
                f"{scenario} test; dashed: gate threshold"
                + ("" if threshold is not None else " (not recorded in summary.json or knn.pt)")
                + "; shaded: steps judged out of distribution, FNN switched off (cf. Figs. 13-16)." if ok
                else "the trace has no kNN distances",
                lambda into=None, r=run, f=frame, s=scenario, th=threshold: F.knn_distance(
                    F.ModelTrace(_label(r), _colour(r), f), th, f"kNN distance and OOD detection, {s} ({_label(r)})", into=into),
                ok)
    # Figs. 17-20: forces
    force_run = next((r for r in hybrids if r.dataset == fig_dataset), hybrids[0] if hybrids else None)
    force_run = force_run or next((r for r in runs if r.model == "mmg"), None)
    for scenario in _pick(FORCE_SCENARIOS, scenarios) if force_run else []:
        frame = force_run.trace(scenario, long) if long else None
        ok = frame is not None and len(frame) > 0
        label = _label(force_run)
        add(f"forces_{scenario}", "Forces", f"Forces by module, {scenario}, {label}",
            f"Hull (H), propeller (P), rudder (R), wind (A) and FNN (NN) forces and moment along the {long} s "
            f"predictions of the {scenario} test, {label} (cf. Figs. 17, 19)." if ok else "no trace in the source",
            lambda into=None, f=frame, s=scenario: F.force_components(
                F.ModelTrace(label, _colour(force_run), f), f"External forces by module, {s} ({label})", into=into),
            ok)
        if force_run.model == "hybrid":
            add(f"force_models_{scenario}", "Forces", f"F_MMG, F_NN and their sum, {scenario}, {label}",
                f"MMG forces (H + P + R + A), the FNN correction and their sum along the {long} s predictions "
                f"of the {scenario} test, {label} (cf. Figs. 18, 20)." if ok else "no trace in the source",
                lambda into=None, f=frame, s=scenario: F.force_models(
                    F.ModelTrace(label, _colour(force_run), f), f"External forces by internal model, {s} ({label})", into=into),
                ok)
    # Fig. 21: |F_NN| vs velocity error
    groups = []
    for i, run in enumerate(hybrids):
        frames = [run.trace(s, short) for s in run.scenarios()] if short else []
        frames = [f for f in frames if f is not None]
        if frames:
            groups.append((_label(run), _colour(run, i), pd.concat(frames, ignore_index=True)))
    if hybrids:
        add("fnn_scatter", "Forces", "|F_NN| against velocity prediction error",
            f"Magnitude of the FNN correction against the absolute velocity error at every point of the "
            f"{short} s predictions of all test scenarios (cf. Fig. 21)." if groups else "no traces in the source",
            lambda into=None, g=groups: F.fnn_error_scatter(g, "|F_NN| and absolute velocity prediction error", into=into),
            groups)
    # loss curves
    histories = [(_label(r), _colour(r, i), r.history, r.summary.get("best_epoch"))
                 for i, r in enumerate(runs) if r.history is not None and len(r.history)]
    if histories:
        add("loss", "Training", "Training and validation loss",
            "Training (solid) and validation (dashed) loss per epoch of every trained model; star: the "
            "epoch whose weights were kept.", lambda into=None, h=histories: F.loss_curves(h, "Training and validation loss", into=into),
            True)
    else:
        plan.notes.append("Loss curves: skipped, no run has a history.csv (MMG-only runs are not trained)")
    return _quality_figures(source, plan)
