"""Which figures a report shows: the paper's scenarios for each figure type (section 4.4),
with the models the paper shows (D2 for comparisons), degraded to what the source holds.

Every figure is a `FigureSpec` with a lazy factory, so the page count is known before any
figure is drawn; a figure whose data is missing is replaced by a note saying why.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import partial
from typing import Callable

import pandas as pd
from matplotlib.figure import FigureBase

from sysid.config.choices import ModelKind
from sysid.report import figures as F
from sysid.protocol.paper import run_label
from sysid.report.methods import estimator_text
from sysid.report.palette import BASELINE_COLOURS, model_colour
from sysid.protocol.paper import scenario_key
from sysid.report.quality import FILES_PER_FIGURE, quality_timeline
from sysid.report.source import ReportSource, RunRecord

BOX_SCENARIOS = ["Turning 20", "Zigzag 30/30", "Random"]                 # Figs. 3-5
SERIES_WINDOWS = [("Zigzag 30/30", 0.0), ("Random", 500.0)]              # Figs. 6-9
TRAJECTORY_SCENARIOS = ["Turning 20", "Zigzag 30/30", "Random"]          # Figs. 10-12
KNN_SCENARIOS = ["Turning 20", "Random"]                                 # Figs. 13-16
FORCE_SCENARIOS = ["Turning 20", "Zigzag 30/30"]                         # Figs. 17-20
_PAPER_POINTER = re.compile(r"\s*\(cf\. [^)]*\)")   # " (cf. Figs. 10-12)" in a caption


@dataclass
class FigureSpec:
    key: str
    section: str
    title: str
    caption: str
    factory: Callable[..., FigureBase]  # factory(into=None): draws into a sub-figure or a new figure


@dataclass
class FigurePlan:
    figures: list[FigureSpec] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _label(run: RunRecord) -> str:
    return run_label(run.name, run.model, run.dataset)


def _colour(run: RunRecord, index: int = 0) -> str:
    return model_colour(run.name, run.model, run.dataset, index)


def _pick(preferred: list[str], available: list[str]) -> list[str]:
    """The preferred scenarios the source has (any spelling), else every scenario it has
    (a user's own test logs: one figure each)."""
    found = [_find(s, available) for s in preferred]
    return [s for s in found if s is not None] or list(available)


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


def _traces(runs: list[RunRecord], scenario: str, horizon: int, baselines: bool = False) -> list[F.ModelTrace]:
    """Each run's trace of `scenario` at `horizon` [s]; `baselines`: each run's physics
    baselines' traces on the same windows after it (dashed)."""
    out = []
    for i, run in enumerate(runs):
        frame = run.trace(scenario, horizon)
        if frame is not None and len(frame):
            out.append(F.ModelTrace(_label(run), _colour(run, i), frame))
            for j, label in enumerate(run.baselines if baselines else []):
                base = run.trace(scenario, horizon, baseline=label)
                if base is not None and len(base):
                    out.append(F.ModelTrace(baseline_label(label), BASELINE_COLOURS[j % len(BASELINE_COLOURS)],
                                            base, baseline=True))
    return out


BASELINE_SUFFIX = ", physics baseline"


def baseline_label(label: str) -> str:
    """A physics baseline's name in the figures' legends."""
    return label + BASELINE_SUFFIX


def _quality_figures(source: ReportSource, plan: FigurePlan) -> FigurePlan:
    """Timelines of the preprocessing quality reports, FILES_PER_FIGURE files each."""
    reports = source.quality
    chunks = [reports[i:i + FILES_PER_FIGURE] for i in range(0, len(reports), FILES_PER_FIGURE)]
    for i, chunk in enumerate(chunks, 1):
        part = f" ({i} of {len(chunks)})" if len(chunks) > 1 else ""
        plan.figures.append(FigureSpec(
            f"quality_{i}", "Preprocessing quality", f"Preprocessing quality timeline{part}",
            "Per preprocessed file: kept and dropped segments, gaps split or interpolated, and GNSS "
            "fixes rejected by the antenna-baseline check (above the bar) or the heading gate (below), "
            "over the log's time.", partial(quality_timeline, chunk, f"Preprocessing quality{part}")))
    return plan


@dataclass
class _Context:
    """What every figure family needs: the runs, horizons and the plan being filled."""

    plan: FigurePlan
    runs: list[RunRecord]
    scenarios: list[str]
    compared: list[RunRecord]   # MMG runs and the trained runs of the paper's figures' data set
    hybrids: list[RunRecord]
    fig_dataset: str | None
    short: int | None           # horizon [s] of the 30 s figures
    long: int | None            # horizon [s] of the 100 s figures
    paper: bool = True          # a paper protocol: captions point to the paper's figures
    baselines: bool = False     # a learned run's physics baselines drawn beside it (a run's or sweep's report)

    def traces(self, runs: list[RunRecord], scenario: str, horizon: int | None) -> list[F.ModelTrace]:
        """`_traces` of the runs, with their physics baselines when `baselines`; [] without a horizon."""
        return _traces(runs, scenario, horizon, self.baselines) if horizon else []

    @staticmethod
    def beside(traces: list[F.ModelTrace], drawn: str = "Dashed grey") -> str:
        """The caption's sentence naming the physics baselines among `traces`, `drawn` so
        (empty when none)."""
        labels = list(dict.fromkeys(t.label.removesuffix(BASELINE_SUFFIX) for t in traces if t.baseline))
        if not labels:
            return ""
        return (f" {drawn}: the learned model's physics baseline{'s' if len(labels) > 1 else ''} "
                f"{' and '.join(labels)}, on the same windows.")

    @property
    def trained_on(self) -> str:
        return f" (trained models: {self.fig_dataset})" if self.fig_dataset in ("D1", "D2") else ""

    def add(self, key: str, section: str, title: str, caption: str, factory, ok) -> None:
        """Plan the figure, or note why it is skipped (`caption` then says why); outside a
        paper protocol without the pointers to the paper's figures."""
        if not self.paper:
            caption = _PAPER_POINTER.sub("", caption)
        if ok:
            self.plan.figures.append(FigureSpec(key, section, title, caption, factory))
        else:
            self.plan.notes.append(f"{title}: skipped, {caption}")


def _baseline_notes(c: _Context) -> None:
    """Say when a learned run's figures cannot show its physics baseline."""
    if not c.baselines:
        return
    for run in c.runs:
        if run.model == ModelKind.MMG or len(run.metrics) == 0:
            continue
        if not run.baselines:
            c.plan.notes.append(f"{_label(run)}: no physics baseline on its test logs (baseline_metrics.csv): "
                                "its figures show it alone")
        elif not run.run_dir.baseline_traces.is_dir():
            c.plan.notes.append(f"{_label(run)}: its physics baseline's traces are not in the run directory "
                                "(written before sysid kept baseline_traces/): its figures show it alone; "
                                "train it again to draw the baseline beside it")


def _error_figures(c: _Context) -> None:
    """Figs. 3-5: absolute-error box plots, every model, 30 s."""
    for scenario in _pick(BOX_SCENARIOS, c.scenarios):
        traces = c.traces(c.runs, scenario, c.short)
        c.add(f"box_{scenario}", "Prediction errors", f"Absolute error, {scenario}, {c.short} s predictions",
              f"Absolute errors of u, v_m and r pooled over every point of every {c.short} s window of the "
              f"{scenario} test, per model (cf. the paper's Figs. 3-5).{c.beside(traces, 'Hatched grey')}" if traces
              else "no traces in the source",
              partial(F.error_boxplots, traces, f"Absolute error, {scenario} ({c.short} s predictions)"), traces)


def _series_figures(c: _Context) -> None:
    """Figs. 6-9: actuators, relative wind and states over one 100 s window."""
    series = [(_find(s, c.scenarios), t0) for s, t0 in SERIES_WINDOWS if _find(s, c.scenarios)]
    for scenario, start in series or [(s, 0.0) for s in c.scenarios]:
        traces = c.traces(c.compared, scenario, c.long)
        span = f"{start:.0f}-{start + c.long:.0f} s" if c.long else ""
        missing = "no traces in the source"
        c.add(f"inputs_{scenario}", "Time series", f"Actuators and relative wind, {scenario}, {span}",
              f"Propeller speed, rudder angle and relative wind in the {c.long} s window of the {scenario} "
              f"test starting nearest {start:.0f} s{c.trained_on}; each model's relative wind follows its "
              f"own predicted state, 'measured' uses the recorded state (cf. Figs. 6, 8).{c.beside(traces)}" if traces
              else missing,
              partial(F.actuator_wind, traces, start, f"Actuator and relative wind state, {scenario} ({span})"),
              traces)
        c.add(f"states_{scenario}", "Time series", f"Heading and velocities, {scenario}, {span}",
              f"Heading ψ and velocities u, v_m, r predicted over the {c.long} s window of the {scenario} "
              f"test against the measurement{c.trained_on} (cf. Figs. 7, 9).{c.beside(traces)}" if traces else missing,
              partial(F.state_timeseries, traces, start, f"Attitude and velocity, {scenario} ({span})"), traces)


def _trajectory_figures(c: _Context, ship_size: tuple[float, float] | None) -> None:
    """Figs. 10-12: earth-frame tracks with the ship's outline."""
    L, B = ship_size or (0.0, 0.0)
    for scenario in _pick(TRAJECTORY_SCENARIOS, c.scenarios):
        traces = c.traces(c.compared, scenario, c.long)
        ok = bool(traces) and ship_size is not None
        why = "no traces in the source" if not traces else "ship dimensions unknown"
        c.add(f"track_{scenario}", "Trajectories", f"Trajectories, {scenario}, {c.long} s predictions",
              f"Earth-frame track of the {scenario} test and every {c.long} s window predicted from the "
              f"recorded start state{c.trained_on}; outlines of the {L:g} m x {B:g} m ship at fixed "
              f"intervals (cf. Figs. 10-12).{c.beside(traces)}" if ok else why,
              partial(F.trajectories, traces, L, B, f"Trajectory prediction, {scenario} ({c.long} s windows)"), ok)


def _gate_figures(c: _Context) -> None:
    """Figs. 13-16: kNN distance of every hybrid run, 30 s."""
    if not c.hybrids:
        c.plan.notes.append("kNN distance" + (" (Figs. 13-16)" if c.paper else "") + ": skipped, no hybrid run "
                            "in the source")
        return
    for scenario in _pick(KNN_SCENARIOS, c.scenarios):
        for run in c.hybrids:
            frame = run.trace(scenario, c.short) if c.short else None
            ok = frame is not None and frame["knn_distance"].notna().any()
            threshold = run.gate_threshold
            unknown = "" if threshold is not None else " (not recorded in summary.json or knn.pt)"
            label = _label(run)
            c.add(f"knn_{run.name}_{scenario}", "Out-of-distribution gate", f"kNN distance, {scenario}, {label}",
                  f"kNN distance of the hybrid model's inputs ({label}) in the {c.short} s predictions of the "
                  f"{scenario} test; dashed: gate threshold{unknown}; shaded: steps judged out of "
                  "distribution, FNN switched off (cf. Figs. 13-16)." if ok else "the trace has no kNN distances",
                  partial(F.knn_distance, F.ModelTrace(label, _colour(run), frame), threshold,
                          f"kNN distance and OOD detection, {scenario} ({label})"), ok)


def _force_figures(c: _Context) -> None:
    """Figs. 17-20 (forces of the hybrid of the figures' data set) and Fig. 21."""
    run = next((r for r in c.hybrids if r.dataset == c.fig_dataset), c.hybrids[0] if c.hybrids else None)
    run = run or next((r for r in c.runs if r.model == ModelKind.MMG), None)
    for scenario in _pick(FORCE_SCENARIOS, c.scenarios) if run else []:
        frame = run.trace(scenario, c.long) if c.long else None
        ok = frame is not None and len(frame) > 0
        label = _label(run)
        trace = F.ModelTrace(label, _colour(run), frame)
        c.add(f"forces_{scenario}", "Forces", f"Forces by module, {scenario}, {label}",
              f"Hull (H), propeller (P), rudder (R), wind (A) and FNN (NN) forces and moment along the "
              f"{c.long} s predictions of the {scenario} test, {label} (cf. Figs. 17, 19)." if ok
              else "no trace in the source",
              partial(F.force_components, trace, f"External forces by module, {scenario} ({label})"), ok)
        if run.model == ModelKind.HYBRID:
            c.add(f"force_models_{scenario}", "Forces", f"F_MMG, F_NN and their sum, {scenario}, {label}",
                  f"MMG forces (H + P + R + A), the FNN correction and their sum along the {c.long} s "
                  f"predictions of the {scenario} test, {label} (cf. Figs. 18, 20)." if ok
                  else "no trace in the source",
                  partial(F.force_models, trace, f"External forces by internal model, {scenario} ({label})"), ok)
    groups = []
    for i, hybrid in enumerate(c.hybrids):
        frames = [hybrid.trace(s, c.short) for s in hybrid.scenarios()] if c.short else []
        frames = [f for f in frames if f is not None]
        if frames:
            groups.append((_label(hybrid), _colour(hybrid, i), pd.concat(frames, ignore_index=True)))
    if c.hybrids:
        c.add("fnn_scatter", "Forces", "|F_NN| against velocity prediction error",
              "Magnitude of the FNN correction against the absolute velocity error at every point of the "
              f"{c.short} s predictions of all test scenarios (cf. Fig. 21)." if groups else "no traces in the source",
              partial(F.fnn_error_scatter, groups, "|F_NN| and absolute velocity prediction error"), groups)


def _loss_figure(c: _Context) -> None:
    histories = [(_label(r), _colour(r, i), r.history, r.summary.best_epoch)
                 for i, r in enumerate(c.runs) if r.history is not None and len(r.history)]
    if histories:
        c.add("loss", "Training", "Training and early-stopping loss",
              "Training loss (solid) and early-stopping loss (dashed: L_v on the validation windows while "
              "training, before the kNN gate exists; val_loss_multistep is that of the final, gated model) per "
              "epoch of every trained model; star: the epoch whose weights were kept.", partial(F.loss_curves, histories, "Training and early-stopping loss"),
              True)
    else:
        c.plan.notes.append("Loss curves: skipped, no run has a history.csv (MMG-only runs are not trained)")


def _uncertainty_figures(c: _Context) -> None:
    """Identified coefficients with ± 2 sigma beside their prior, and their correlations."""
    for run in c.runs:
        u = run.summary.identified_uncertainty
        if u is None or not u.names:
            continue
        names = list(u.names)
        prior_map = run.summary.identified_initial
        prior = [prior_map.get(n) for n in names] if all(n in prior_map for n in names) else []
        two_sigma = [None if s is None else 2.0 * s for s in u.std_error]
        title = f"Identified coefficients of {_label(run)}"
        c.add(f"identified_{run.name}", "Identification", title,
              "Estimates with ± 2 standard errors from the curvature of the multi-step loss (Jacobian of "
              "the residuals on disjoint training windows, windows as independent clusters), beside the "
              f"ship file's values; right: correlations of the estimates. Estimator: {estimator_text(run.summary)}.",
              partial(F.identified_coefficients, names, list(u.estimate), two_sigma, prior,
                      [list(row) for row in u.correlation], title), True)


def _seed_figures(c: _Context) -> None:
    """The spread over seeds of every learned model's short-horizon RMSE, per data set."""
    from sysid.protocol.paper import paper_rmse

    groups = [r for r in c.runs if r.seeds]
    if not groups or not c.short:
        return
    for dataset in sorted({r.dataset for r in groups}):
        models = []
        for i, run in enumerate(r for r in groups if r.dataset == dataset):
            rows = []
            for record in run.seeds:
                m = record.metrics[(record.metrics.horizon_s - c.short).abs() < 0.5]
                rows.append(m.assign(seed=record.summary.seed))
            models.append(F.SeedSpread(_label(run), _colour(run, i), pd.concat(rows, ignore_index=True)))
        scenarios = list(dict.fromkeys(s for m in models for s in m.rmse.scenario.astype(str)))
        paper = {s: paper_rmse(s, "hybrid", dataset, c.short) for s in scenarios}
        n = max(len(r.seeds) for r in groups)
        title = f"Spread over {n} seeds, {c.short} s predictions, trained on {dataset}"
        c.add(f"seeds_{dataset}", "Seed spread", title,
              f"RMSE of every {c.short} s prediction per scenario for each seed of each learned model "
              f"(boxes: spread over the seeds; dots: single seeds; black bars: the paper's hybrid, {dataset}).",
              partial(F.seed_boxplots, models, scenarios, title, {k: v for k, v in paper.items() if v}), True)


def _cell_figures(source: ReportSource, c: _Context) -> None:
    """Per data set: every Table 7/8 cell of NN-only and the hybrid relative to the MMG the
    hybrid corrects, with the seed spread and the paper's printed hybrid."""
    from sysid.report.cell_ratios import dataset_cells

    for cells in dataset_cells(source):
        labels = [m.label for m in cells.models]
        n = len(cells.cells[cells.cells.model == labels[0]])
        seeds = cells.seeds
        spread = (f"markers: seed means over {seeds} seeds, bars: min to max over the seeds"
                  if seeds > 1 else "one seed: points without spread")
        counts = []
        hybrid = next((m for m in labels if m.startswith("Hybrid")), None)
        nn = next((m for m in labels if m.startswith("NN")), None)
        if hybrid and nn:
            beats, total = cells.beating(hybrid, nn)
            counts.append(f"{hybrid} below {nn} in {beats} of {total} cells")
        if hybrid:
            mine = cells.cells[cells.cells.model == hybrid].set_index(["scenario", "horizon_s", "channel"]).ratio
            paper = cells.paper.set_index(["scenario", "horizon_s", "channel"]).ratio
            shared = mine.index.intersection(paper.index)
            counts.append(f"below the paper's hybrid in {int((mine.loc[shared] < paper.loc[shared]).sum())} "
                          f"of {len(shared)}")
        title = f"Every cell relative to {cells.baseline}, trained on {cells.dataset}"
        c.add(f"cells_{cells.dataset}", "Hybrid against NN-only and MMG-only", title,
              f"RMSE of each of the {n} cells of Tables 7 and 8 (scenario x u, v_m, r x horizon) divided by the "
              f"RMSE of {cells.baseline}, the MMG the hybrid corrects and the baseline of every cut: "
              f"{', '.join(labels)} ({spread}); black bars: the paper's printed hybrid over the same baseline; "
              f"dashed: the baseline (1). Log axis, below 1: a smaller error than the baseline. "
              + ("; ".join(counts) + "." if counts else ""),
              partial(F.relative_rmse, cells, title), len(cells.cells) > 0)


def _sweep_figures(sweep, plan: FigurePlan, linked: bool = False) -> None:
    """A sweep (`SweepRecord`): validation loss against each varied key; the seed spread per
    configuration. `linked`: a sweep shown beside another source (titled by its name)."""
    from sysid.report import sweep_figures as SF

    chosen = sweep.summary.best.point if sweep.summary.best else None
    seeds = len(sweep.summary.seeds)
    name = sweep.summary.name
    section, key, of = (f"Sweep {name}", f"sweep_{name}_", f" (sweep {name})") if linked else ("Sweep", "sweep_", "")
    plan.figures.append(FigureSpec(
        f"{key}keys", section, f"val_loss_multistep against the varied keys{of}",
        "val_loss_multistep (the sweep's objective; validation windows only, never the test files) of every "
        "trial against each varied option; grey: means; red circles: the chosen configuration.",
        partial(SF.objective_by_key, sweep.trials, sweep.keys, chosen, f"val_loss_multistep against the varied keys{of}")))
    plan.figures.append(FigureSpec(
        f"{key}seeds", section, f"Spread over {seeds} seeds per configuration{of}",
        "val_loss_multistep of each configuration over its seeds (box: spread; dots: single seeds), best mean "
        "first; red: the chosen configuration.",
        partial(SF.seed_spread, sweep.trials, sweep.points, chosen, f"Spread over {seeds} seeds per configuration{of}")))


def figure_plan(source: ReportSource, ship_size: tuple[float, float] | None) -> FigurePlan:
    """The figures of a report for `source`; `ship_size` = (L_pp, B) [m] for outlines."""
    plan = FigurePlan()
    if source.sweep is not None:
        _sweep_figures(source.sweep, plan)
    runs = source.runs
    if runs:
        datasets = sorted({r.dataset for r in runs if r.model != ModelKind.MMG and r.dataset != "-"})
        fig_dataset = "D2" if "D2" in datasets else (datasets[-1] if datasets else None)
        c = _Context(plan, runs, list(dict.fromkeys(s for r in runs for s in r.scenarios())),
                     [r for r in runs if r.model == ModelKind.MMG or r.dataset == fig_dataset],
                     [r for r in runs if r.model == ModelKind.HYBRID], fig_dataset,
                     _horizon(runs, 30, short=True), _horizon(runs, 100, short=False), source.paper_protocol,
                     baselines=source.kind != "reproduction")
        _baseline_notes(c)
        if source.kind == "reproduction":
            _cell_figures(source, c)
        _error_figures(c)
        _series_figures(c)
        _trajectory_figures(c, ship_size)
        _gate_figures(c)
        _force_figures(c)
        _loss_figure(c)
        _seed_figures(c)
        _uncertainty_figures(c)
    for sweep in source.linked_sweeps:
        _sweep_figures(sweep, plan, linked=True)
    return _quality_figures(source, plan)
