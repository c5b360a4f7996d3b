"""The report's summary (what, when, with which software) and its short methods text,
generated from each run's config.toml and summary.json."""
from __future__ import annotations

import datetime as _dt
import hashlib
from dataclasses import dataclass

from pathlib import Path

from sysid.config.choices import ModelKind, Solver, StartStates
from sysid.config.experiment import Experiment
from sysid.protocol.paper import run_label
from sysid.report.quality import quality_rows
from sysid.report.source import ReportSource, RunRecord
from sysid.runs.reproduction import Reproduction
from sysid.records.summary import RunSummary, StartStateCheckSummary
from sysid.store.versions import software_versions

MODEL_TEXT = {
    "mmg": "MMG model (hull, propeller, rudder and wind forces of the ship definition)",
    "nn": "NN-only model: a feed-forward network maps the standardized state, actuator and relative-wind "
          "inputs to the forces",
    "hybrid": "hybrid MMG + FNN model: the MMG forces plus a feed-forward correction F_NN, switched off "
              "by a kNN out-of-distribution gate when the inputs are far from the training data",
}
SOURCE_KINDS = {"reproduction": "reproduction, {n} runs", "run": "single run",
                "sweep": "sweep; runs: its chosen configuration's first seed",
                "preprocessing": "preprocessing output, {q} files"}
PROTOCOL_TEXT = (
    "Evaluation follows the benchmark protocol: each {rate} test file is cut into consecutive windows of "
    "H samples (H = {horizons} s); each window starts from the recorded state at its first sample and is "
    "integrated with {integrator}, dt = {dt}, with the recorded propeller speed, rudder angle and true "
    "wind held over each step (the relative wind follows the predicted state). The RMSE of u, v_m and r "
    "is pooled over the H points of every window of a file (in the units its table states).")
INTEGRATORS = {"euler": "explicit Euler", "rk4": "classical RK4"}


def protocol_text(source: ReportSource) -> str:
    """The evaluation paragraph: the runs' horizons, their `[evaluation] integrator` and
    `[data] rate` (each run's config; the protocol's Euler at 1 Hz when not recorded); that no
    test log was evaluated when no run has test metrics."""
    horizons = sorted({h for r in source.runs for h in r.horizons()})
    if not horizons:
        return ("No test log was evaluated (a sweep's runs, or a run trained without test logs): the verdict is "
                "on the validation windows; score a run on test logs with `sysid evaluate RUN --data LOGS`.")
    configs = [r.config or {} for r in source.runs]
    methods = sorted({str((c.get("evaluation") or {}).get("integrator", "euler")) for c in configs})
    rates = sorted({float((c.get("data") or {}).get("rate", 1.0)) for c in configs})
    return PROTOCOL_TEXT.format(horizons=" and ".join(str(h) for h in horizons),
                                rate=" / ".join(f"{r:g} Hz" for r in rates),
                                integrator=" / ".join(INTEGRATORS.get(m, m) for m in methods),
                                dt=" / ".join(f"{1.0 / r:g} s" for r in rates))


@dataclass
class RunRow:
    """One line of the summary's run table."""

    label: str
    model: str
    dataset: str
    epochs: str
    train_time: str
    config_digest: str
    created: str


def config_digest(run: RunRecord) -> str:
    """First 12 hex digits of the SHA-256 of the resolved config.toml ("-" if absent)."""
    if not run.config_text:
        return "-"
    return hashlib.sha256(run.config_text.encode()).hexdigest()[:12]


def _seconds(value) -> str:
    try:
        s = float(value)
    except (TypeError, ValueError):
        return "-"
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min"


def run_rows(source: ReportSource) -> list[RunRow]:
    rows = []
    for run in source.runs:
        s = run.summary
        why = s.stopped_text
        epochs = ("-" if not s.epochs else f"{s.epochs} (best {_or(s.best_epoch, '-')}"
                  + (f"; {why}" if why else "") + ")")
        est = s.identification
        if est is not None and est.solver == Solver.LEVENBERG_MARQUARDT and "train" not in s.stopped:  # no epochs: LM alone
            epochs = f"{_or(est.iterations, '?')} Levenberg-Marquardt iterations" + (f" ({why})" if why else "")
        if s.failed:
            epochs += f" - {s.status.upper()}"
        dataset = "your logs" if run.dataset == "files" else run.dataset
        rows.append(RunRow(run_label(run.name, run.model, run.dataset), run.model, dataset, epochs,
                           "-" if run.model == ModelKind.MMG else _seconds(s.train_seconds),
                           config_digest(run), _or(s.created, "-")))
    return rows


def _flatten(data, prefix: str = "") -> list[tuple[str, str]]:
    out = []
    for key, value in data.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out += _flatten(value, name + ".")
        elif isinstance(value, float):
            out.append((name, f"{value:.4g}"))
        elif isinstance(value, (list, tuple)) and len(value) > 8:
            out.append((name, f"{len(value)} items"))
        else:
            out.append((name, str(value)))
    return out


def _or(value, default: str) -> str:
    """`value` as text, `default` where it is None."""
    return default if value is None else str(value)


def reproduction_items(summary: Reproduction) -> list[tuple[str, str]]:
    """Readable lines of a reproduction's summary.json (time, scorecard, gate shares)."""
    items = []
    if summary.seconds is not None:
        items.append(("Reproduction time", _seconds(float(summary.seconds)) + " (runs, evaluation, tables; the report not included)"))
    seeds = summary.seeds or 1
    if seeds > 1:
        items.append(("Seeds", f"every learned model trained with {seeds} seeds: table cells are the mean ± std "
                               "over the seeds; an ensemble row averages the forces of the seeds' models"))
    for card in summary.scorecards:
        model = f"Hybrid (mean over {seeds} seeds)" if seeds > 1 and card.model == "Hybrid" else card.model
        for ds, c in card.datasets.items():
            nn = f"; {c.nn_text()}" if c.nn_text() else ""
            items.append((f"{model} {ds} vs {card.baseline}",
                          f"{100 * c.reduction_vs_mmg_30s_mean:.0f} % lower RMSE at 30 s (mean over the scenarios: "
                          f"{c.by_scenario_text()}); {100 * c.reduction_vs_mmg_100s_mean:.0f} % at 100 s; "
                          f"beats the paper's hybrid in {c.cells_beating_paper_hybrid} of {c.cells} cells{nn}"))
    shares = {k: v for k, v in (summary.gate_off_share_random_30s or {}).items() if v is not None}
    if shares:
        items.append(("kNN gate off, Random test (30 s)",
                      ", ".join(f"{k} {100 * float(v):.0f} % of steps" for k, v in shares.items())))
    return items


def nn_count_items(source: ReportSource) -> list[tuple[str, str]]:
    """For a summary.json written before the scorecard counted the cells where the hybrid
    beats NN-only: that count from the runs' metrics (`sysid.report.cell_ratios`)."""
    from sysid.report.cell_ratios import dataset_cells

    cards = source.reproduction.scorecards if source.reproduction is not None else []
    if not cards or all(c.cells_beating_nn is not None for card in cards for c in card.datasets.values()):
        return []
    items = []
    for cells in dataset_cells(source):
        labels = [m.label for m in cells.models]
        hybrid = next((m for m in labels if m.startswith("Hybrid")), None)
        nn = next((m for m in labels if m.startswith("NN")), None)
        if hybrid and nn:
            beats, total = cells.beating(hybrid, nn)
            items.append((f"{hybrid} vs {nn}", f"lower RMSE in {beats} of {total} cells (from the runs' metrics)"))
    return items


def sweep_items(source: ReportSource, top: int = 8) -> list[tuple[str, str]]:
    """Readable lines of the source's sweep (`sweep_record_items`)."""
    return sweep_record_items(source.sweep, top)


def sweep_record_items(sweep, top: int = 8) -> list[tuple[str, str]]:
    """Readable lines of a sweep (`SweepRecord`): what it varied, its trials, the chosen
    configuration and the best configurations by mean validation loss over their seeds."""
    s, best = sweep.summary, sweep.summary.best
    items = [("Sweep", f"{s.name}: {s.search} search over {', '.join(s.keys) or '-'}; "
                       f"seeds {list(s.seeds)}; base {s.base}"),
             ("Trials", f"{s.complete} of {s.trials} complete, {s.failed} failed, "
                        f"{s.missing} missing; {_seconds(s.seconds)}"),
             ("Objective", "val_loss_multistep, the validation multi-step loss of each trial's final model "
                           "(validation windows only; the test files never choose)")]
    if best:
        spread = (f" ± {best.val_loss_multistep_std:.5f} (std over seeds)"
                  if best.val_loss_multistep_std is not None else "")
        items.append(("Chosen", f"{best.point}: val_loss_multistep {best.val_loss_multistep_mean:.5f}{spread}; "
                                f"runs {', '.join(best.runs)}"))
    for i, row in enumerate(sweep.points.head(top).itertuples(), 1):
        std = getattr(row, "val_loss_multistep_std", float("nan"))
        items.append((f"#{i}", f"{row.point}: {row.val_loss_multistep_mean:.5f}" + ("" if std != std else f" ± {std:.5f}")
                      + f" ({row.complete} of {row.seeds} seeds)"))
    return items


def summary_items(source: ReportSource, ship_size: tuple[float, float] | None) -> list[tuple[str, str]]:
    """(key, value) lines of the report's summary section."""
    runs = source.runs
    ships = sorted({_or(r.summary.ship, "-") for r in runs})
    ship = ", ".join(ships)
    if ship_size:
        ship += f" (L_pp {ship_size[0]:g} m, B {ship_size[1]:g} m)"
    datasets = sorted({r.dataset for r in runs if r.dataset != "-"})
    scenarios = list(dict.fromkeys(s for r in runs for s in r.scenarios()))
    trained = [float(s.summary.train_seconds or 0.0) for r in runs for s in (r.seeds or [r])]
    versions: dict[str, set] = {}
    for r in runs:
        for k, v in r.summary.versions.items():
            versions.setdefault(k, set()).add(str(v))
    created = sorted(r.summary.created for r in runs if r.summary.created)
    items = [
        ("Source", f"{source.path} ({SOURCE_KINDS[source.kind].format(n=len(runs), q=len(source.quality))})"),
        ("Ship", ship),
        ("Models", ", ".join(run_label(r.name, r.model, r.dataset) for r in runs)),
        ("Training data sets" if source.paper_protocol else "Training data",
         ", ".join(training_data_text(next(r for r in runs if r.dataset == d)) if d == "files" else d
                   for d in datasets) or "none (MMG only)"),
        ("Test scenarios" if source.paper_protocol else "Test logs",
         ", ".join(scenarios) or "none: no test logs (the verdict is on the validation windows)"),
        ("Configuration digest", ", ".join(f"{r.name}: {config_digest(r)}" for r in runs)),
        ("Software (runs)", ", ".join(f"{k} {'/'.join(sorted(v))}" for k, v in sorted(versions.items())) or "-"),
        ("Software (report)", ", ".join(f"{k} {v}" for k, v in software_versions().items())),
        ("Runs created", created[0] if len(set(created)) == 1 else (f"{created[0]} to {created[-1]}" if created else "-")),
        ("Report built", _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")),
        ("Training time", _seconds(sum(trained)) + " in total"),
    ]
    if source.reproduction is not None:   # the scorecard first: page 1 of the report
        items = reproduction_items(source.reproduction) + nn_count_items(source) + verdict_items(source) + items
    if source.sweep is not None:
        items = sweep_items(source) + items
    missing = source.missing_runs
    if missing:  # first line of page 1
        protocol = len(missing) + len(runs)
        items.insert(0, ("PARTIAL reproduction", f"{len(runs)} of {protocol} protocol runs "
                         f"({', '.join(r.name for r in runs)}); not run: {', '.join(missing)}. "
                         "Tables and figures cover only the runs present."))
    if source.quality:
        rows = quality_rows(source.quality)
        items.append(("Preprocessed files", f"{len(rows)} files, {sum(r.kept_s for r in rows):.0f} s kept in "
                      f"{sum(r.segments for r in rows)} segments, {sum(r.dropped for r in rows)} dropped; gaps "
                      f"{sum(r.gaps_interpolated for r in rows)} interpolated, {sum(r.gaps_split for r in rows)} split"))
    if not runs:
        items = [i for i in items if i[0] not in ("Models", "Training data sets", "Training data", "Test scenarios",
                                                  "Test logs",
                                                  "Configuration digest", "Software (runs)", "Runs created",
                                                  "Training time", "Ship")]
    return items


def verdict_items(source: ReportSource) -> list[tuple[str, str]]:
    """Each learned model of a reproduction against its physics baselines, by the one rule
    (docs: How sysid judges a model), as `sysid reproduce` prints it: a seed group's seeds
    are members of one model, a mean-of-seeds ensemble is one model (its own verdict); a
    learned run without a recorded verdict says so."""
    items = []
    for run in source.runs:
        learned = run.model != ModelKind.MMG or bool(run.summary.identified)
        if not learned:
            continue
        verdict = run.model_verdict
        label = f"Verdict: {run_label(run.name, run.model, run.dataset)}"
        if verdict is None:
            items.append((label, f"not judged: the run records no verdict (sysid compare runs/{run.name} --against "
                                 "baseline judges it)"))
        else:
            items.append((label, ("" if verdict.beats_baseline else "WARNING: ") + verdict.statement()))
    return items


def estimator_text(summary: RunSummary) -> str:
    """Which estimator produced a run's identified coefficients and their ± 2 sigma, from
    summary.json's "identification" and "stopped" (older runs: the generic description)."""
    est = summary.identification
    if est is None or est.solver is None:
        return "± 2σ from the curvature of the multi-step loss on disjoint training windows"
    stopped = summary.stopped.get("identify")
    starts = ("each window's start state estimated along" if est.start_states == StartStates.ESTIMATED
              else "each window integrated from its recorded first sample")
    if est.solver == Solver.LEVENBERG_MARQUARDT:
        how = (f"Levenberg-Marquardt on the multi-step residuals of {_or(est.windows, '?')} disjoint training "
               f"windows, {starts}" + (f", integrated by {INTEGRATORS.get(est.integrator, est.integrator)}"
                                       if est.integrator and est.integrator != "euler" else "")
               + f"; {_or(est.iterations, '?')} iterations" + (f", {stopped}" if stopped else ""))
        if est.prior_weight:
            how += f"; pulled toward the ship file's values with prior weight {est.prior_weight:g}"
    else:
        how = (f"gradient (Adam) on the multi-step loss, {_or(est.stage, 'before')}, "
               f"{_or(est.epochs, '?')} epochs" + (f", {stopped}" if stopped else "") + f"; {starts}")
    return how + ("; ± 2σ: window-clustered sandwich of that estimator on disjoint training windows"
                  + (", start states profiled out" if est.start_states == StartStates.ESTIMATED else "")
                  + start_state_check_text(est.start_state_check))


def start_state_check_text(check: StartStateCheckSummary | None) -> str:
    """The model-error check of a Levenberg-Marquardt run (summary.json's
    identification.start_state_check) in a sentence; "" where there is none."""
    if check is None or check.largest_sigma is None:
        return ""
    return "; check: " + check.verdict()


def methods_paragraphs(source: ReportSource) -> list[str]:
    """A few paragraphs: the protocol, then what was trained, how and on what, per run."""
    out = [protocol_text(source)] if source.runs else []
    if source.quality:
        settings = source.quality[0].settings
        out.append("Preprocessing: raw 10 Hz logs converted to the processed schema (GNSS to local metres, "
                   "antenna-baseline and heading-gate checks, gaps interpolated or split into segments, "
                   "velocities by filtering); settings of the first file: "
                   + (", ".join(f"{k} = {v}" for k, v in _flatten(settings)) or "not recorded") + ".")
    for run in source.runs:
        s = run.summary
        text = f"{run_label(run.name, run.model, run.dataset)}: {MODEL_TEXT.get(run.model, run.model)}"
        identified = bool(s.identified) or (s.identified_uncertainty is not None and bool(s.identified_uncertainty.names))
        text += "; not trained." if run.model == ModelKind.MMG and not identified else "."
        if s.mmg_overrides:
            text += " MMG coefficients changed from the ship file: " + ", ".join(
                f"{k} = {v}" for k, v in s.mmg_overrides.items()) + "."
        if run.model != ModelKind.MMG:
            text += (f" Trained on {training_data_text(run)}{held_out_text(run)} ({_or(s.n_train_windows, '?')} training and "
                     f"{_or(s.n_val_windows, '?')} validation windows) for {s.epochs} epochs; "
                     f"the weights of epoch {_or(s.best_epoch, '?')} were kept "
                     f"(training time {_seconds(s.train_seconds)}, seed {_or(s.seed, '?')}).")
        if s.val_loss_multistep is not None:
            gated = run.model == ModelKind.HYBRID and run.gate_threshold is not None
            text += (f" val_loss_multistep {s.val_loss_multistep:.5f}: the validation loss, L_v of the final "
                     f"model{' (kNN gate included)' if gated else ''} on the validation windows.")
        u = s.identified_uncertainty
        if u is not None and u.names:
            prior = s.identified_initial
            parts = []
            for name, est, sd, weak in zip(u.names, u.estimate, u.std_error, u.undetermined):
                cell = f"{name} = {est:.4g}" + (f" ± {2 * sd:.2g} (2σ)" if sd is not None else " (σ infinite)")
                cell += f", prior {prior[name]:.4g}" if name in prior else ""
                parts.append(cell + (", not determined by the data" if weak else ""))
            text += f" Identified coefficients ({estimator_text(s)}): " + "; ".join(parts) + "."
        elif s.identified:
            text += " Identified coefficients: " + ", ".join(f"{k} = {v}" for k, v in _flatten(s.identified)) + "."
        gate = s.gate.to_json()
        if run.model == ModelKind.HYBRID and gate:
            scalars = {k: v for k, v in gate.items() if not isinstance(v, (dict, list))}
            text += " OOD gate: " + ", ".join(f"{k} = {v}" for k, v in _flatten(scalars)) + "."
        out.append(text)
    return out


def training_data_text(run: RunRecord) -> str:
    """"data set D2", or "5 of your logs (a.csv, b.csv, ...)" from summary.json "data"."""
    data = run.summary.data
    if data is not None and data.training == "files":
        names = [Path(f.file).name for f in data.train]
        return f"{len(names)} of your logs ({_names(names)})"
    return f"data set {run.dataset}"


def held_out_text(run: RunRecord) -> str:
    """"; validated on 3 training logs held out whole (berthing: a; zigzag: b, c; split_seed 0)"
    for a run with ``[training] validation = "files"`` (summary.json "data.held_out"), else ""."""
    data = run.summary.data
    held = data.held_out if data is not None else None
    if not held:
        return ""
    groups = held.get("groups") or {}
    n = sum(len(v) for v in groups.values())
    listed = "; ".join(f"{group}: {', '.join(names)}" for group, names in groups.items())
    return (f", validated on {n} training log{'s' if n != 1 else ''} held out whole ({listed}; "
            f"split_seed {held.get('split_seed')})")


def _names(names: list[str], first: int = 4) -> str:
    return ", ".join(names[:first]) + (f" and {len(names) - first} more" if len(names) > first else "")


def _setting_text(key: str, value) -> str:
    if key in ("data.train", "data.validation", "data.test") and isinstance(value, list):
        return (f"{len(value)} log{'s' if len(value) > 1 else ''}: {_names([Path(str(v)).name for v in value])}"
                if value else "none")
    if value == "" or value == {}:
        return "none"
    if key == "data.columns" and isinstance(value, dict):
        return "; ".join(f"{ch}: {v}" if not isinstance(v, dict) else f"{ch}: {v.get('column')} [{v.get('unit')}]"
                         for ch, v in value.items())
    if isinstance(value, dict):
        return ", ".join(f"{k} = {v}" for k, v in value.items()) or "{}"
    if isinstance(value, list):
        return "[" + ", ".join(str(v) for v in value) + "]"
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def changed_settings(run: RunRecord) -> list[tuple[str, str, str]]:
    """(section.key, value, default) where the run's resolved config.toml differs from the
    defaults of `sysid.config.experiment.Experiment` (the name left out)."""
    defaults = Experiment().to_table()
    rows = []
    for section, values in run.config.items():
        if not isinstance(values, dict):
            continue
        for key, value in values.items():
            default = (defaults.get(section) or {}).get(key)
            if (section, key) == ("experiment", "name") or value == default:
                continue
            name = f"{section}.{key}"
            rows.append((name, _setting_text(name, value), "-" if default is None else _setting_text(name, default)))
    return rows
