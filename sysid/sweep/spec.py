"""Sweep files: a TOML file to a typed, validated `SweepSpec`.

```toml
[sweep]
name = "hybrid_D2_lr"
base = "../experiments/hybrid_D2.toml"   # experiment config (relative to this file)
search = "grid"          # grid | random | optuna
samples = 8              # random / optuna: configurations drawn
seeds = [0, 1, 2]        # every configuration is trained with each seed
objective = "val_loss_multistep"   # validation multi-step loss, minimised (never a test file)
max_retries = 2          # a trial that crashes or is killed is retried this often
search_seed = 0          # seed of the random / optuna sampler
scheduler = "asha"       # none | asha | median: Tune stops poor trials early

[scheduler]              # the scheduler's settings (in epochs; each trial reports every epoch)
grace_period = 2         # asha, median: epochs every trial runs before it can be stopped
reduction_factor = 3     # asha: keep the best 1/3 at each rung

[set]                    # options set in every trial (not varied)
"training.objective_s" = 20.0

[vary]                   # "section.option" of the experiment config
"training.learning_rate" = [1e-3, 3e-3]              # grid: the values
"network.hidden" = [[64, 64], [128, 128]]
"training.lambda_F" = { loguniform = [1e-3, 1e-1] }   # random / optuna: a distribution

[tracking]
mlflow = "mlruns"        # log every trial to MLflow (a tracking URI; a path is a file store)
```

Distributions: ``{ uniform = [low, high] }``, ``{ loguniform = [low, high] }``,
``{ randint = [low, high] }`` (high exclusive) and ``{ choice = [values] }``; a plain list is
a grid axis, or a choice in random / optuna search. Every value is checked against the
experiment schema before anything runs: errors name the sweep file and the key.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sysid.config.choices import Search
from sysid.errors import ConfigError
from sysid.store.toml_file import read_toml
from sysid.config.experiment import Experiment, load_experiment, parse_experiment

SCHEDULERS = ("none", "asha", "median")
# scheduler -> {setting: (default, smallest allowed, integer?)}; times in epochs
SCHEDULER_SETTINGS: dict[str, dict[str, tuple[float, float, bool]]] = {
    "none": {},
    "asha": {"grace_period": (1, 1, True), "reduction_factor": (3.0, 1.0 + 1e-9, False), "brackets": (1, 1, True)},
    "median": {"grace_period": (1, 1, True), "min_samples_required": (3, 1, True)},
}
OBJECTIVES = ("val_loss_multistep",)
SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")   # one path component, never "." or ".."
DISTRIBUTIONS = ("uniform", "loguniform", "randint", "choice")


@dataclass(frozen=True)
class Axis:
    """One varied option: ``values`` (grid or choice) or a continuous ``distribution``."""

    key: str                              # "section.option"
    values: tuple = ()
    distribution: str = ""                # "" (values) | uniform | loguniform | randint
    bounds: tuple[float, float] = (0.0, 0.0)

    @property
    def section(self) -> str:
        return self.key.split(".", 1)[0]

    @property
    def option(self) -> str:
        return self.key.split(".", 1)[1]


@dataclass(frozen=True)
class SchedulerSpec:
    """Tune's trial scheduler: ``kind`` (none | asha | median) and its settings (every
    setting filled in; times in epochs, each trial reporting its validation loss every epoch)."""

    kind: str = "none"
    settings: tuple[tuple[str, float], ...] = ()

    def as_dict(self) -> dict:
        return dict(self.settings)


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep: the base experiment, the axes, the seeds and how to search."""

    name: str
    base: Experiment
    base_path: Path
    axes: tuple[Axis, ...]
    seeds: tuple[int, ...] = (0,)
    search: Search = Search.GRID
    samples: int = 1
    objective: str = "val_loss_multistep"
    max_retries: int = 2
    search_seed: int = 0
    source: str = ""
    text: str = ""                        # the sweep file as written (kept beside the results)
    scheduler: SchedulerSpec = SchedulerSpec()
    mlflow: str = ""                      # [tracking] mlflow: tracking URI or path ("" = no tracking)
    directory: Path | None = None         # the sweep file's; relative paths in [set] / [vary] resolve here

    @property
    def keys(self) -> list[str]:
        return [a.key for a in self.axes]

    @property
    def most_epochs(self) -> int:
        """The most epochs one seed of a trial can report (gradient identification plus
        training, at the largest values the axes allow): the schedulers' horizon."""
        def largest(key: str, base: int) -> int:
            axis = next((a for a in self.axes if a.key == key), None)
            if axis is None:
                return int(base)
            return int(max([axis.bounds[1]] if axis.distribution else list(axis.values)))
        return largest("identify.epochs", self.base.identify.epochs) + largest("training.epochs",
                                                                               self.base.training.epochs)

    def experiment(self, values: dict[str, Any], seed: int, name: str) -> Experiment:
        """The base experiment with `values` ({"section.option": value}) and `seed` set."""
        return apply_values(self.base, values, seed, name, self.source, self.directory)


def safe_name(text: str) -> str:
    """`text` as one safe path component (`SAFE_NAME`): other characters become ``_``."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", text)[:128]
    return name if SAFE_NAME.fullmatch(name) else f"_{name}"[:128]


def base_document(exp: Experiment) -> dict:
    """An experiment as a TOML document (every option filled in)."""
    return exp.to_table()


def apply_values(base: Experiment, values: dict[str, Any], seed: int, name: str,
                 source: str = "<sweep>", directory: Path | None = None) -> Experiment:
    """`base` with ``{"section.option": value}`` applied and validated like a config file;
    relative paths among the values resolve against `directory` (the sweep file's)."""
    doc = base_document(base)
    for key, value in values.items():
        section, option = key.split(".", 1)
        doc[section][option] = list(value) if isinstance(value, tuple) else value
    doc["experiment"]["seed"] = int(seed)
    doc["experiment"]["name"] = name
    where = f"{source}: [vary] " + ", ".join(f"{k} = {v!r}" for k, v in values.items()) if values else source
    exp = parse_experiment(doc, where, directory)
    return dataclasses.replace(exp, source=base.source)


def _number(where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _axis(src: str, key: str, value: Any, base: Experiment) -> Axis:
    where = f"{src}: [vary] {key!r}"
    section, _, option = key.partition(".")
    if not option or section not in base_document(base) or option not in base_document(base)[section]:
        raise ConfigError(f"{where}: not an experiment option (write \"section.option\", e.g. "
                          "\"training.learning_rate\")")
    if key in ("experiment.seed", "experiment.name"):
        raise ConfigError(f"{where}: set seeds with [sweep] seeds; trial names are made by the sweep")
    if isinstance(value, list):
        if not value:
            raise ConfigError(f"{where}: an empty list of values")
        return Axis(key, tuple(tuple(v) if isinstance(v, list) else v for v in value))
    if isinstance(value, dict):
        if len(value) != 1 or next(iter(value)) not in DISTRIBUTIONS:
            raise ConfigError(f"{where}: a distribution is one of {', '.join(DISTRIBUTIONS)}, "
                              f"e.g. {{ loguniform = [1e-4, 1e-2] }}; got {value!r}")
        kind, arg = next(iter(value.items()))
        if kind == "choice":
            if not isinstance(arg, list) or not arg:
                raise ConfigError(f"{where}: choice needs a non-empty list, got {arg!r}")
            return Axis(key, tuple(tuple(v) if isinstance(v, list) else v for v in arg))
        if not isinstance(arg, list) or len(arg) != 2:
            raise ConfigError(f"{where}: {kind} needs [low, high], got {arg!r}")
        low, high = _number(where, arg[0]), _number(where, arg[1])
        if not low < high or (kind == "loguniform" and low <= 0):
            raise ConfigError(f"{where}: {kind} needs low < high" + (" and low > 0" if kind == "loguniform" else "")
                              + f", got {arg!r}")
        if kind == "randint" and not (float(low).is_integer() and float(high).is_integer()):
            raise ConfigError(f"{where}: randint needs integer bounds, got {arg!r}")
        return Axis(key, (), kind, (low, high))
    raise ConfigError(f"{where}: expected a list of values or a distribution table, got {value!r}")


def _check_axis_values(spec_src: str, axis: Axis, base: Experiment, directory: Path | None = None) -> None:
    """Apply every value (or both bounds) alone to the base config: bad ones fail now."""
    if axis.distribution:
        low, high = axis.bounds
        probes = [int(low), int(high) - 1] if axis.distribution == "randint" else [low, high]
    else:
        probes = list(axis.values)
    for value in probes:
        apply_values(base, {axis.key: value}, base.experiment.seed, base.experiment.name, spec_src, directory)


def parse_scheduler(source: str, kind, table) -> SchedulerSpec:
    """``[sweep] scheduler`` and the ``[scheduler]`` table to a `SchedulerSpec`."""
    if kind not in SCHEDULERS:
        raise ConfigError(f"{source}: [sweep] scheduler = {kind!r}: choose one of {', '.join(SCHEDULERS)}")
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: [scheduler] must be a table of settings")
    known = SCHEDULER_SETTINGS[kind]
    for key in table:
        if key not in known:
            raise ConfigError(f"{source}: [scheduler] {key!r} is not a setting of scheduler {kind!r} "
                              f"(known: {', '.join(known) or 'none'})")
    settings = []
    for key, (default, low, integer) in known.items():
        value = table.get(key, default)
        bad = isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < low or (integer and not float(value).is_integer())
        if bad:
            kind_of = "an integer" if integer else "a number"
            bound = f">= {low:g}" if integer else f"> {math.floor(low):g}"
            raise ConfigError(f"{source}: [scheduler] {key} must be {kind_of} {bound}, got {value!r}")
        settings.append((key, int(value) if integer else float(value)))
    return SchedulerSpec(kind, tuple(settings))


def _tracking(source: str, table) -> str:
    if not isinstance(table, dict) or set(table) - {"mlflow"}:
        raise ConfigError(f"{source}: [tracking] holds one key, mlflow = \"URI or path\"")
    value = table.get("mlflow", "")
    if not isinstance(value, str):
        raise ConfigError(f"{source}: [tracking] mlflow must be a tracking URI or a path, got {value!r}")
    return value


def parse_sweep(doc: dict, source: str = "<sweep>", directory: Path | None = None, text: str = "") -> SweepSpec:
    """A parsed sweep TOML document to a validated `SweepSpec`."""
    table = _sweep_table(doc, source)
    base, base_path = _base(doc, table, source, directory)
    try:
        search = Search.parse(table.get("search", "grid"), f"{source}: [sweep] search")
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    objective = table.get("objective", "val_loss_multistep")
    objective = "val_loss_multistep" if objective == "val_loss" else objective  # its older name
    if objective not in OBJECTIVES:
        raise ConfigError(f"{source}: [sweep] objective = {objective!r}: the objective is the validation "
                          "loss (val_loss_multistep); test files are never used to choose")
    seeds, ints = _seeds_and_counts(table, base, source)
    name = _sweep_name(table, source)
    axes = _axes(doc, source, base, search, directory)
    scheduler = parse_scheduler(source, table.get("scheduler", "none"), doc.get("scheduler", {}))
    mlflow = _tracking(source, doc.get("tracking", {}))
    if mlflow and not Path(mlflow).is_absolute() and "://" not in mlflow and not mlflow.startswith("file:"):
        mlflow = str((directory or Path.cwd()) / mlflow)   # a path relative to the sweep file
    return SweepSpec(name, base, base_path, axes, tuple(seeds), search, ints["samples"], objective,
                     ints["max_retries"], ints["search_seed"], source, text, scheduler, mlflow, directory)


def _sweep_table(doc: dict, source: str) -> dict:
    """The [sweep] table; `ConfigError` for an unknown section or key, or no [sweep]."""
    unknown = set(doc) - {"sweep", "set", "vary", "scheduler", "tracking"}
    if unknown:
        raise ConfigError(f"{source}: unknown section(s) {sorted(unknown)} "
                          "(known: sweep, set, vary, scheduler, tracking)")
    table = doc.get("sweep")
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: [sweep] is required (base, seeds, search)")
    known = {"name", "base", "search", "samples", "seeds", "objective", "max_retries", "search_seed", "scheduler"}
    for key in table:
        if key not in known:
            raise ConfigError(f"{source}: [sweep] unknown key {key!r} (known: {', '.join(sorted(known))})")
    return table


def _base(doc: dict, table: dict, source: str, directory: Path | None):
    """(the base experiment with [set] applied, the path of its config)."""
    if not isinstance(table.get("base"), str):
        raise ConfigError(f"{source}: [sweep] base must name the experiment config (a path)")
    base_path = Path(table["base"])
    if not base_path.is_absolute():
        base_path = (directory or Path.cwd()) / base_path
    base = load_experiment(base_path)
    fixed = doc.get("set", {})
    if not isinstance(fixed, dict):
        raise ConfigError(f"{source}: [set] must be a table of \"section.option\" = value")
    for key, value in fixed.items():
        _axis(source, key, [value], base)  # the key is an option (and not the seed)
    if fixed:
        base = apply_values(base, {k: tuple(v) if isinstance(v, list) else v for k, v in fixed.items()},
                            base.experiment.seed, base.experiment.name, source, directory)
    return base, base_path


def _seeds_and_counts(table: dict, base, source: str) -> tuple[list, dict]:
    """(the seeds, {samples, max_retries, search_seed}) of [sweep], each checked."""
    seeds = table.get("seeds", [base.experiment.seed])
    if (not isinstance(seeds, list) or not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0
                                                       for s in seeds) or len(set(seeds)) != len(seeds)):
        raise ConfigError(f"{source}: [sweep] seeds must be a list of distinct integers >= 0, got {seeds!r}")
    ints = {}
    for key, default, low in (("samples", 1, 1), ("max_retries", 2, 0), ("search_seed", 0, 0)):
        value = table.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ConfigError(f"{source}: [sweep] {key} must be an integer >= {low}, got {value!r}")
        ints[key] = value
    return seeds, ints


def _sweep_name(table: dict, source: str) -> str:
    """[sweep] name (one safe path component), else the sweep file's stem."""
    if "name" in table:
        name = table["name"]
        if not isinstance(name, str) or not SAFE_NAME.fullmatch(name):
            raise ConfigError(f"{source}: [sweep] name = {name!r}: a sweep name names a folder (Tune's experiment "
                              "under --storage): ASCII letters, digits, '_', '-' and '.', not first, e.g. "
                              "\"hybrid_D2_lr\"")
    else:
        name = safe_name(Path(source).stem if source != "<sweep>" else "sweep")
    return name


def _axes(doc: dict, source: str, base, search: Search, directory: Path | None) -> tuple:
    """The [vary] axes, each checked against the base experiment and the search."""
    vary = doc.get("vary", {})
    if not isinstance(vary, dict):
        raise ConfigError(f"{source}: [vary] must be a table of \"section.option\" = values")
    axes = tuple(_axis(source, key, value, base) for key, value in vary.items())
    for axis in axes:
        if search is Search.GRID and axis.distribution:
            raise ConfigError(f"{source}: [vary] {axis.key!r}: a {axis.distribution} distribution needs "
                              "search = \"random\" or \"optuna\" (grid search takes a list of values)")
        _check_axis_values(source, axis, base, directory)
    return axes


def load_sweep(path: str | os.PathLike) -> SweepSpec:
    """Read and validate a sweep file; errors name the file and key."""
    path = Path(path)
    doc, text = read_toml(path, "sweep file", ConfigError)
    return parse_sweep(doc, str(path), path.resolve().parent, text)
