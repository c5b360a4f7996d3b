"""The seed paper's Tables 7 (30 s) and 8 (100 s): RMSE of u, v_m [m/s] and r [rad/s], and
the one long table of our runs beside them (`comparison_table`), with the model labels
every table and figure uses (`model_label`, `run_label`).

One source: ``sysid/configs/paper/tables_7_8.csv`` (package data) (the paper's numbers; MMG rows are the same for
both data sets). Scenario names match in any spelling ("Turning 20°", "turning 20 test").
"""
from __future__ import annotations

import re
from functools import lru_cache

import pandas as pd

from sysid.package_data import bundled_dir
from sysid.errors import ConfigError

KIND_LABELS = {"mmg": "MMG", "nn": "NN", "hybrid": "Hybrid"}  # the paper's model names


def scenario_key(name: str) -> str:
    """Spelling-independent scenario key: "Turning 20°", "turning 20 test" and "Turning 20"
    all give "turning20"; "Zigzag 20°/20°" gives "zigzag20/20"."""
    name = name.lower().replace("maneuver", "").replace("manoeuvre", "").replace("test", "")
    return re.sub(r"[^a-z0-9/]", "", name)


@lru_cache(maxsize=1)
def paper_table() -> pd.DataFrame:
    """Rows scenario, model (MMG/NN/Hybrid), dataset, horizon_s, rmse_u, rmse_v, rmse_r."""
    table = bundled_dir("paper") / "tables_7_8.csv"
    if not table.is_file():
        raise ConfigError(f"{table}: the paper's Tables 7/8 are missing")
    return pd.read_csv(table)


@lru_cache(maxsize=1)
def _cells() -> dict:
    return {(scenario_key(r.scenario), r.model, r.dataset, int(r.horizon_s)): (r.rmse_u, r.rmse_v, r.rmse_r)
            for r in paper_table().itertuples()}


def paper_rmse(scenario: str, kind: str, dataset: str, horizon_s: float) -> tuple[float, float, float] | None:
    """The paper's (u, v_m, r) RMSE for a scenario, model kind ("mmg", "nn", "hybrid"),
    data set and horizon [s]; None when the paper has no such cell (held-out files, ...)."""
    model = KIND_LABELS.get(kind)
    if kind == "mmg" and dataset not in ("D1", "D2"):
        dataset = "D1"  # the paper's MMG rows are the same for both data sets
    return _cells().get((scenario_key(scenario), model, dataset, int(round(horizon_s))))


# -- our runs beside the paper's ----------------------------------------------------------

# run variant (the run's name without its data set) -> label; the paper's three models first
MODEL_LABELS = {
    "mmg_paper": "MMG",
    "mmg_lab": "MMG (lab X'vr)",
    "mmg_identified": "MMG (identified)",
    "nn": "NN",
    "hybrid": "Hybrid",
    "hybrid_identified": "Hybrid (identified MMG)",
    # the mean-of-seeds ensembles of `sysid reproduce --seeds N` (forces averaged over the seeds)
    "nn_ensemble": "NN (ensemble)",
    "hybrid_ensemble": "Hybrid (ensemble)",
    "hybrid_identified_ensemble": "Hybrid (id. MMG, ensemble)",
}
PAPER_VARIANTS = {"mmg_paper": "mmg", "nn": "nn", "hybrid": "hybrid"}  # variants the paper reports
SCENARIO_ORDER = ["Berthing", "Turning 20", "Turning 35", "Zigzag 20/20", "Zigzag 30/30", "Random"]
COMPARISON_COLUMNS = ["scenario", "model", "dataset", "horizon_s",
                      "rmse_u", "rmse_v", "rmse_r", "paper_u", "paper_v", "paper_r",
                      "std_u", "std_v", "std_r", "n_seeds"]  # rmse_*: mean over n_seeds seeds; std_*: their std


def run_variant(name: str, dataset: str = "-") -> str:
    """A run's name without its data-set suffix: hybrid_D2 -> hybrid, mmg_lab -> mmg_lab."""
    suffix = f"_{dataset}"
    return name[: -len(suffix)] if dataset not in ("", "-") and name.endswith(suffix) else name


def model_label(name: str, kind: str, dataset: str = "-") -> str:
    """The model's label in tables (data set not included): "MMG", "Hybrid", "MMG (lab X'vr)"."""
    variant = run_variant(name, dataset)
    if variant in MODEL_LABELS:
        return MODEL_LABELS[variant]
    base = KIND_LABELS.get(kind, kind)
    if variant in ("", kind):
        return base
    rest = variant[len(kind) + 1:] if variant.startswith(f"{kind}_") else variant
    return f"{base} ({rest.replace('_', ' ')})"


def run_label(name: str, kind: str, dataset: str = "-") -> str:
    """A run's label in legends: the model label and, for runs trained on a paper data set,
    that data set ("Hybrid D2"; a run on the user's own logs: "Hybrid (name)")."""
    label = model_label(name, kind, dataset)
    return f"{label} {dataset}" if dataset not in ("", "-", None, "files") else label


def _order(values, first: list[str], key=lambda v: v) -> list:
    rank = {key(v): i for i, v in enumerate(first)}
    return sorted(values, key=lambda v: rank.get(key(v), len(rank)))


def comparison_table(runs, datasets: tuple[str, ...] = ("D1", "D2")) -> pd.DataFrame:
    """Ours beside the paper's: one row per scenario, model, data set and horizon.

    `runs` yields (name, kind, dataset, metrics) with metrics in `sysid.evaluation.evaluate`'s
    METRICS_COLUMNS, or a seed group's `sysid.protocol.seeds.seed_metrics` (the spread columns are
    carried over; one seed has std NaN and n_seeds 1). A run without training data (dataset
    "-") stands in every data set's column; paper values are given for the paper's own three models only.
    """
    rows = []
    for name, kind, dataset, metrics in runs:
        variant = run_variant(name, dataset)
        label = model_label(name, kind, dataset)
        for m in metrics.itertuples(index=False):
            for ds in (datasets if dataset in ("", "-", None) else (dataset,)):
                ref = paper_rmse(str(m.scenario), kind, ds, m.horizon_s) if variant in PAPER_VARIANTS else None
                rows.append({"scenario": str(m.scenario), "model": label, "dataset": ds,
                             "horizon_s": int(round(m.horizon_s)), "rmse_u": m.rmse_u, "rmse_v": m.rmse_v,
                             "rmse_r": m.rmse_r, **dict(zip(("paper_u", "paper_v", "paper_r"),
                                                            ref if ref else (float("nan"),) * 3)),
                             "std_u": getattr(m, "std_u", float("nan")), "std_v": getattr(m, "std_v", float("nan")),
                             "std_r": getattr(m, "std_r", float("nan")), "n_seeds": int(getattr(m, "n_seeds", 1))})
    table = pd.DataFrame(rows, columns=COMPARISON_COLUMNS)
    if table.empty:
        return table
    scenarios = _order(table.scenario.unique(), SCENARIO_ORDER, scenario_key)
    models = _order(table.model.unique(), list(MODEL_LABELS.values()))
    rank_s = {s: i for i, s in enumerate(scenarios)}
    rank_m = {m: i for i, m in enumerate(models)}
    table["_o"] = table.scenario.map(rank_s) * 100 + table.model.map(rank_m) * 10 + table.dataset.map(
        {d: i for i, d in enumerate(sorted(table.dataset.unique()))})
    return table.sort_values(["horizon_s", "_o"], kind="stable").drop(columns="_o").reset_index(drop=True)
