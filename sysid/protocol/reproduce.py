"""The whole benchmark protocol in one call: MMG-only (paper's and lab's X'vr), NN-only and
hybrid on D1 and D2, evaluated on the six test files, tables beside the paper's 7 and 8."""
from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from sysid.data.datasets import TEST_FILES, data_root
from sysid.package_data import bundled_dir
from sysid.errors import ConfigError
from sysid.config.choices import ModelKind
from sysid.config.experiment import Experiment, load_experiment
from sysid.store.files import write_csv, write_text
from sysid.store.target import RECORD_FILES, OutputKind
from sysid.runs.lifecycle import cached_test_runs, cached_training_runs, run_experiment
from sysid.runs.reproduction import DatasetScore, Reproduction, Scorecard
from sysid.maneuvers.recorded import RECORD_FILE, write_record_comparison
from sysid.protocol.paper import MODEL_LABELS, comparison_table, model_label, run_label
from sysid.device import cpu_cores
from sysid.workers import in_workers

# run name -> experiment config; labels and data sets come from the configs
PROTOCOL = {
    "mmg_paper": "mmg_paper.toml",
    "mmg_lab": "mmg_lab.toml",
    "nn_D1": "nn_D1.toml",
    "nn_D2": "nn_D2.toml",
    "hybrid_D1": "hybrid_D1.toml",
    "hybrid_D2": "hybrid_D2.toml",
    # beyond the paper: hull coefficients identified by gradient, alone and under the FNN
    "mmg_identified_D2": "mmg_identified_D2.toml",
    "hybrid_identified_D2": "hybrid_identified_D2.toml",
}


def protocol_experiment(name: str) -> Experiment:
    """The experiment of a protocol run."""
    if name not in PROTOCOL:
        raise ConfigError(f"unknown protocol run {name!r}: choose from {', '.join(PROTOCOL)}")
    return load_experiment(bundled_dir("experiments") / PROTOCOL[name])


def markdown_table(table: pd.DataFrame, horizon: int) -> str:
    """The paper's layout: ours (paper) per cell, u v_m r for D1 and D2."""
    t = table[table.horizon_s == horizon]
    seeds = int(t["n_seeds"].max()) if "n_seeds" in t and len(t) else 1
    spread = f" Learned models: mean ± std over {seeds} seeds." if seeds > 1 else ""
    head = (f"RMSE [m/s, m/s, rad/s] of {horizon}-s predictions: ours (paper). Table "
            f"{7 if horizon == 30 else 8} of the paper.{spread}\n\n"
            "| test | model | D1 u | D1 v_m | D1 r | D2 u | D2 v_m | D2 r |\n|---|---|---|---|---|---|---|---|\n")
    lines = []
    for scenario in dict.fromkeys(t.scenario):
        for model in dict.fromkeys(t.model):
            if t[(t.scenario == scenario) & (t.model == model)].empty:
                continue
            cells = []
            for ds in ("D1", "D2"):
                row = t[(t.scenario == scenario) & (t.model == model) & (t.dataset == ds)]
                for c in ("u", "v", "r"):
                    if row.empty:
                        cells.append("–")
                        continue
                    ours, ref = row[f"rmse_{c}"].iloc[0], row[f"paper_{c}"].iloc[0]
                    spread = row[f"std_{c}"].iloc[0] if f"std_{c}" in row else np.nan  # type: ignore[assignment]
                    cells.append(f"{ours:.4f}" + ("" if np.isnan(spread) else f" ± {spread:.4f}")
                                 + ("" if np.isnan(ref) else f" ({ref:.4f})"))
            lines.append(f"| {scenario} | {model} | " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


RMSE_COLUMNS = ["rmse_u", "rmse_v", "rmse_r"]
PAPER_COLUMNS = ["paper_u", "paper_v", "paper_r"]


def _cells(table: pd.DataFrame, model: str, dataset: str) -> pd.DataFrame:
    """The rows of one model on one data set, indexed by (scenario, horizon_s)."""
    return table[(table.model == model) & (table.dataset == dataset)].set_index(["scenario", "horizon_s"])


def dataset_score(table: pd.DataFrame, dataset: str, baseline: str, model: str, nn: str | None) -> DatasetScore:
    """`model` on `dataset` against `baseline` (MMG), the paper's hybrid and `nn` (NN-only's
    label; None or absent from the table: not compared), cell by cell: a cell is one
    scenario, horizon and channel (u, v_m, r), RMSE as in `table` (seed means)."""
    hyb = _cells(table, model, dataset)
    mmg = _cells(table, baseline, dataset)
    ratio = hyb[RMSE_COLUMNS] / mmg.loc[hyb.index, RMSE_COLUMNS]
    at30 = ratio.xs(30, level="horizon_s")
    ref = _cells(table, "Hybrid", dataset)
    beats = hyb[RMSE_COLUMNS].to_numpy() < ref.loc[hyb.index, PAPER_COLUMNS].to_numpy()
    nn_rows = _cells(table, nn, dataset) if nn else hyb.iloc[:0]
    beats_nn = paper_beats_nn = None
    if len(nn_rows):
        shared = hyb.index.intersection(nn_rows.index)
        beats_nn = int((hyb.loc[shared, RMSE_COLUMNS].to_numpy() < nn_rows.loc[shared, RMSE_COLUMNS].to_numpy()).sum())
        paper_nn = _cells(table, "NN", dataset)
        if len(paper_nn) and len(ref):
            paper_shared = ref.index.intersection(paper_nn.index)
            paper_beats_nn = int((ref.loc[paper_shared, PAPER_COLUMNS].to_numpy()
                                  < paper_nn.loc[paper_shared, PAPER_COLUMNS].to_numpy()).sum())
    return DatasetScore(
        reduction_vs_mmg_30s_by_scenario={s: float(1 - at30.loc[s].mean()) for s in at30.index},
        reduction_vs_mmg_30s_mean=float(1 - at30.to_numpy().mean()),
        reduction_vs_mmg_100s_mean=float(1 - ratio.xs(100, level="horizon_s").to_numpy().mean()),
        cells_beating_paper_hybrid=int(beats.sum()), cells=int(beats.size),
        nn=nn if beats_nn is not None else None, cells_beating_nn=beats_nn,
        paper_cells_hybrid_beating_nn=paper_beats_nn)


def scorecard(table: pd.DataFrame, baseline: str = "MMG", model: str = "Hybrid", nn: str | None = "NN",
              datasets: tuple[str, ...] = ("D1", "D2")) -> Scorecard:
    """`model` (the hybrid; with seeds, its seed mean) against MMG-only with the same X'vr
    (`baseline` label), against the paper's hybrid and against NN-only (`nn` label, its seed
    mean), cell by cell, on each of `datasets` the table holds `model` and `baseline` for
    at the paper's horizons (30 and 100 s)."""
    def scored(ds: str) -> bool:
        return all({30, 100} <= set(_cells(table, label, ds).index.get_level_values("horizon_s"))
                   for label in (model, baseline))

    scores = {ds: dataset_score(table, ds, baseline, model, nn) for ds in datasets if scored(ds)}
    return Scorecard(baseline, model, **scores)  # type: ignore[arg-type]


def hybrid_baseline() -> tuple[str, str]:
    """(run name, label) of the MMG-only run whose MMG the protocol's hybrid corrects (same
    overrides): the baseline every cut is measured against."""
    hybrid = protocol_experiment("hybrid_D2").mmg.overrides
    for name in ("mmg_paper", "mmg_lab"):
        if protocol_experiment(name).mmg.overrides == hybrid:
            return name, model_label(name, "mmg")
    return "mmg_paper", MODEL_LABELS["mmg_paper"]


@dataclass
class ProtocolRun:
    """What the protocol keeps of one finished run."""

    name: str
    kind: str
    dataset: str          # "-" for an MMG used as defined
    metrics: pd.DataFrame
    gate_off_share: dict
    failure: str | None
    seconds: float


def _run_one(name: str, exp: Experiment, out: Path, data, progress: bool, log) -> ProtocolRun:
    """One protocol run through `run_experiment` (in this process or a worker's)."""
    train = cached_training_runs(exp, data) if exp.needs_training else None
    result = run_experiment(exp, out / "runs" / name, cached_test_runs(data), train, data, progress, log=log)
    return ProtocolRun(name, exp.experiment.model, exp.experiment.dataset if exp.needs_training else "-",
                       result.evaluation.metrics, result.evaluation.gate_off_share, result.failure, result.seconds)


def expected_cost(exp: Experiment) -> float:
    """Relative training cost of a run, to start the longest first (results do not depend
    on the order; the wall time does): hybrid > NN-only > identification, D2 about twice D1."""
    cost = {ModelKind.HYBRID: 5.0, ModelKind.NN: 3.5, ModelKind.MMG: 0.0}[exp.experiment.model] + 1.5 * bool(exp.identify.parameters)
    return cost * (2.0 if exp.data.train or exp.experiment.dataset == "D2" else 1.0)


def _worker(name: str, experiments: dict[str, Experiment], out: Path, data) -> ProtocolRun:
    """A worker process: its lines are prefixed with the run's name."""
    return _run_one(name, experiments[name], out, data, True, lambda m: print(f"[{name}] {m.strip()}", flush=True))


def _seeded(names, trained, experiments, seeds, out, data, jobs, address, log, done, storage=None,
            mlflow=None) -> tuple[list[str], dict]:
    """Learned runs with `seeds` seeds on Ray into `done`; their ensembles' names and the
    recorded maneuvers' predictions made while the last trials ran (`sysid.protocol.overlap`;
    the runs already in `done` are queued for it first)."""
    from sysid.data.datasets import data_root
    from sysid.protocol.overlap import AfterTraining
    from sysid.protocol.seed_runs import ensemble_name, train_seeds, write_ensembles

    ordered = sorted(trained, key=lambda n: -expected_cost(experiments[n]))  # longest first
    log(f"training {len(trained)} runs x {seeds} seeds on Ray (a run's seeds side by side in one trial where "
        "they can), " + (f"{jobs} trials at a time" if jobs else "one trial per CPU of the cluster")
        + (f" on {address}" if address else ""))
    workers = _driver_workers(jobs)
    after = AfterTraining(experiments, out, cached_test_runs(data), data, workers, log) \
        if workers > 1 and address is None else None
    with after.pool if after is not None else contextlib.nullcontext():
        for name in (n for n in names if n in done and after is not None):
            after.ready(name)
        groups = train_seeds({n: experiments[n] for n in ordered}, seeds, out, str(data_root(data)), jobs, address,
                             log, storage, mlflow, cost=lambda n: expected_cost(experiments[n]), watch=after)
        learned = []
        for name in trained:
            exp, group = experiments[name], groups[name]
            done[name] = ProtocolRun(name, exp.experiment.model, exp.experiment.dataset, group.metrics,
                                     group.gate_off_share, group.failure, group.seconds)
            if exp.experiment.model is not ModelKind.MMG and group.seeds:
                learned.append((name, exp, group))
        written, predicted = {}, {}
        if after is not None:
            after.finish()
            # an ensemble of the seeds the final groups hold (a seed is never complete, then not)
            written = {n: r for n, (g, r) in after.ensembles.items() if g.seeds == groups[n].seeds}
            predicted = after.predicted
    sizes = {ensemble_name(n, e.experiment.dataset): len(g.seeds) for n, e, g in learned}
    written.update(write_ensembles([x for x in learned if x[0] not in written], out, cached_test_runs(data), workers,
                                   on_result=lambda r: log(f"[{r[0]}] mean of {sizes[r[0]]} seeds' networks evaluated")))
    ensembles = []
    for name, exp, _ in learned:  # in the protocol's order, whichever was written first
        target, evaluation, _ = written[name]
        done[target] = ProtocolRun(target, exp.experiment.model, exp.experiment.dataset, evaluation.metrics,
                                   evaluation.gate_off_share, None, 0.0)
        ensembles.append(target)
    return ensembles, predicted


def _driver_workers(jobs: int | None) -> int:
    """Worker processes for the driver's own work after training (ensembles, recorded
    maneuvers): `jobs`, or one per core of this machine (on a cluster, `jobs` counts its
    trials, not this machine's cores)."""
    return max(1, min(jobs or cpu_cores(), cpu_cores()))


def reproduce(out_dir: str | os.PathLike, data: str | os.PathLike | None = None,
              only: list[str] | None = None, progress: bool = True,
              overrides: dict | None = None, log: Callable[[str], None] = print,
              jobs: int = 1, seeds: int = 1, address: str | None = None, storage: str | None = None,
              mlflow: str | None = None) -> Reproduction:
    """Run the protocol; write runs/, comparison.csv, table7.md, table8.md, reproduction.json.

    `jobs` > 1 trains that many runs side by side in worker processes (each with its
    config's ``[training] threads``, 1 by default): the results do not depend on it. Ctrl-C
    (`KeyboardInterrupt`) ends every worker before it propagates (`sysid.workers`).
    `seeds` > 1 trains every learned run with that many seeds on Ray (`jobs` trials side by
    side, or on the cluster at `address`; the seeds of a run side by side in one trial where
    they can, `sysid.protocol.seed_runs.seed_groups`): cells are seed means with their spread, and each
    network's mean-of-seeds ensemble is a model row of its own (`sysid.protocol.seed_runs`);
    `storage` (Tune's experiment) and `mlflow` (tracking) as for sweeps.
    """
    started = time.perf_counter()
    out = Path(out_dir)
    data_root(data)  # clear error before any work when the data is missing
    names = only or list(PROTOCOL)
    experiments = {}
    for name in names:
        exp = protocol_experiment(name)
        experiments[name] = exp.replace(**overrides) if overrides and exp.experiment.model is not ModelKind.MMG else exp
    done: dict[str, ProtocolRun] = {}
    trained = [n for n in names if experiments[n].needs_training]
    ensembles: list[str] = []
    predicted: dict = {}

    def run_here(name: str) -> None:
        exp = experiments[name]
        dataset = exp.experiment.dataset if exp.needs_training else "D1+D2"
        # counted in the order the runs start here, after those already done in workers
        log(f"[{len(done) + 1}/{len(names)}] {name}: {model_label(name, exp.experiment.model, dataset)} on {dataset}")
        run = done[name] = _run_one(name, exp, out, data, progress, lambda m: log("    " + m))
        if run.failure:
            log(f"    FAILED: {run.failure}")
        log(f"    done in {run.seconds:.0f} s")

    if seeds > 1 and trained:
        for name in names:  # the MMGs as defined first: their maneuvers overlap the training
            if name not in trained:
                run_here(name)
        ensembles, predicted = _seeded(names, trained, experiments, seeds, out, data, jobs, address, log, done,
                                       storage, mlflow)
    elif jobs > 1 and len(trained) > 1:
        log(f"training {len(trained)} runs in {min(jobs, len(trained))} worker processes")

        def finished(run: ProtocolRun) -> None:
            done[run.name] = run
            log(f"[{len(done)}/{len(names)}] {run.name} done in {run.seconds:.0f} s"
                + (f"; FAILED: {run.failure}" if run.failure else ""))

        longest_first = sorted(trained, key=lambda n: -expected_cost(experiments[n]))
        work = functools.partial(_worker, experiments=experiments, out=out, data=data)
        in_workers(work, longest_first, jobs, multiprocessing.get_context("spawn"), finished)
    for name in names:
        if name not in done:
            run_here(name)
    names = names + ensembles
    runs = [done[n] for n in names]
    results = [(r.name, r.kind, r.dataset, r.metrics) for r in runs]
    shares = {r.name: r.gate_off_share for r in runs}
    failed = {r.name: r.failure for r in runs if r.failure}
    table = comparison_table(results)
    write_csv(table, out / "comparison.csv", float_format="%.5f")
    for horizon, fname in ((30, "table7.md"), (100, "table8.md")):
        write_text(markdown_table(table, horizon), out / fname)
    card = card_ensemble = identified_cells = None
    baseline_run, baseline = hybrid_baseline()
    hybrids = tuple(ds for ds in ("D1", "D2") if f"hybrid_{ds}" in names)
    if hybrids and baseline_run in names:   # a partial reproduction: the data sets it holds
        card = scorecard(table, baseline, datasets=hybrids)
        ensembles_done = tuple(ds for ds in hybrids if f"hybrid_ensemble_{ds}" in names)
        if ensembles_done:
            card_ensemble = scorecard(table, baseline, MODEL_LABELS["hybrid_ensemble"], MODEL_LABELS["nn_ensemble"],
                                      ensembles_done)
        card, card_ensemble = (c if c is not None and c.datasets else None for c in (card, card_ensemble))
    if "hybrid_identified_D2" in names:
        hyb = table[(table.model == MODEL_LABELS["hybrid_identified"])]
        ref = table[(table.model == "Hybrid") & (table.dataset == "D2")].set_index(["scenario", "horizon_s"])
        ours = hyb.set_index(["scenario", "horizon_s"])[["rmse_u", "rmse_v", "rmse_r"]]
        paper = ref.loc[ours.index, ["paper_u", "paper_v", "paper_r"]].to_numpy()
        identified_cells = (int((ours.to_numpy() < paper).sum()), int(paper.size))
    random_file = Path(TEST_FILES["Random"]).stem
    _recorded_maneuvers(out, runs, data, log, _driver_workers(jobs), predicted)
    summary = Reproduction(
        seconds=time.perf_counter() - started, runs=tuple(names), failed=failed, protocol=tuple(PROTOCOL),
        seeds=seeds, scorecard=card, scorecard_ensemble=card_ensemble,
        identified_hybrid_D2_cells_beating_paper_hybrid=identified_cells,
        gate_off_share_random_30s={n: shares[n].get(f"{random_file}_h30.csv") for n in names if n.startswith("hybrid")})
    write_text(summary.to_text(), out / RECORD_FILES[OutputKind.REPRODUCTION])
    return summary


def _recorded_maneuvers(out: Path, runs: list[ProtocolRun], data, log: Callable[[str], None],
                        workers: int = 1, predicted: dict | None = None) -> None:
    """maneuver_indices.csv: the recorded turning and zig-zag test runs' IMO indices beside
    every finished model's prediction of them (`sysid.maneuvers.recorded`; the models in
    `workers` processes, one torch thread each; `predicted`: those predicted already)."""
    started = time.perf_counter()
    done = {run_label(r.name, r.kind, r.dataset): out / "runs" / r.name for r in runs if not r.failure}
    write_record_comparison(out, done, data, workers=workers, predicted=predicted)
    log(f"{RECORD_FILE}: indices of the recorded turning and zig-zag runs beside {len(done)} models' predictions "
        f"({time.perf_counter() - started:.0f} s)")
