"""Experiment configs: a TOML file to typed, validated, frozen options.

```toml
[experiment]
name = "hybrid_D2"
model = "hybrid"            # mmg | nn | hybrid
dataset = "D2"              # D1 | D2: the paper's training and test files; or [data] train
ship = "esso_osaka"         # a bundled ship, or a ship file (relative to this config)
seed = 0

[data]                      # your own logs instead of a paper data set (paths relative to
train = ["logs/turn_*.csv"] # this config; files, directories or glob patterns)
validation = 0.3            # files, or a fraction of the training files' 30-s blocks
test = ["logs/zigzag_20.csv"]   # read only by evaluation; none: no test set
[data.columns]              # your column names and units (sysid.data.columns)
u = { column = "STW", unit = "knots" }

[mmg]
overrides = { X_vr = 0.4535 }

[network]                   # paper Table 6
hidden = [64, 64]

[training]                  # paper Eqs. 13-17; weights are means over windows and steps
steps = 5                   # T, Euler steps of the multi-step loss
stride_s = 2.0              # windows slid by 2 s
validation = "blocks"       # blocks of every file | files: whole files of each maneuver group
val_fraction = 0.3          # 30 % of each file's 30-s blocks (or of each group's files)
...

[gate]                      # paper section 3.4.3
k = 10
alpha = 0.9995

[identify]                  # beyond the paper: identification of MMG coefficients
parameters = ["X_vr", "Y_v"]
bounds = { X_vr = [-1.0, 1.0] }
stage = "before"            # before (then the FNN on the identified MMG) | joint
solver = "gradient"         # gradient (Adam epochs) | levenberg_marquardt (sigma shown honest)
start_states = "estimated"  # levenberg_marquardt: estimated (default) | recorded
prior_weight = 0.0          # levenberg_marquardt: pull toward the ship file's values (0: none)

[ensemble]                  # a mean-of-seeds ensemble: these trained runs, forces averaged
members = ["../hybrid_D2/seed0", "../hybrid_D2/seed1"]
```
Every section and key is optional except ``[experiment] model``; unknown keys are errors.
Every path (``ship``, ``[data] train / validation / test``) resolves against the folder of
the config file that names it (`load_experiment`); a resolved config holds absolute paths.
"""
from __future__ import annotations

import dataclasses
import logging
import math
import os
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from sysid.config.column_map import ColumnMap, parse_columns
from sysid.config.choices import Choice, DType, GateSpace, Method, ModelKind, Solver, Stage, StartStates, Validation, plain_data
from sysid.config.checks import path_component
from sysid.errors import ConfigError
from sysid.mmg.ship import parameter_name
from sysid.store.toml_file import read_toml

_LOG = logging.getLogger(__name__)


_CHOICE_TYPES: dict[str, type[Choice]] = {
    c.__name__: c for c in (DType, GateSpace, Method, ModelKind, Solver, Stage, StartStates, Validation)}


def _choice_type(f: dataclasses.Field) -> type[Choice] | None:
    """The `Choice` an option field holds (its annotation's first type), or None."""
    return _CHOICE_TYPES.get(str(f.type).split(" | ")[0])


class _Options:
    """A section of options: values given as strings for choice fields (by Python callers)
    become their enums here, so that every `Experiment` holds enums."""

    def __post_init__(self):
        for f in fields(self):
            kind, value = _choice_type(f), getattr(self, f.name)
            if kind is None or value is None or isinstance(value, kind):
                continue
            if value == "" and f.default is None:  # "" for an optional choice: its default
                value = None
            else:
                value = kind.parse(value, f.name, offered_only=True)
            object.__setattr__(self, f.name, value)


@dataclass(frozen=True)
class ExperimentOptions(_Options):
    name: str = "experiment"
    model: ModelKind = ModelKind.HYBRID
    dataset: str = ""              # "D1" | "D2": the paper's data (training and test); "": [data] train
    ship: str = "esso_osaka"
    seed: int = 0


@dataclass(frozen=True)
class DataOptions:
    """Your own logs (instead of the paper's D1/D2): files, directories or glob patterns,
    resolved against the config's folder. ``validation`` empty: the ``[training]
    val_fraction`` of every training file's blocks; ``test`` empty (and no data set): no test
    set. ``columns``: the logs' column names and units (`sysid.data.columns`)."""

    train: tuple[str, ...] = ()      # training logs
    validation: tuple[str, ...] = () # validation logs (whole files); empty: blocks of the training logs
    test: tuple[str, ...] = ()       # test logs, read only by evaluation
    columns: ColumnMap = ColumnMap()  # [data.columns]: channel = column or { column, unit }
    rate: float = 1.0                # Hz
    exclude_suspect: bool = True     # drop windows touching frozen-GNSS segments
    exclude_astern: bool = True      # drop training windows outside a one-quadrant propeller (n_prop < 0 or u < 0)
    rudder_sign_checked: tuple[str, ...] = ()   # logs (file names without suffix) whose rudder sign the user checked


@dataclass(frozen=True)
class MMGOptions:
    overrides: dict = field(default_factory=dict)


@dataclass(frozen=True)
class NetworkOptions:
    hidden: tuple[int, ...] = (64, 64)
    members: int = 1               # networks averaged (1 = the paper's single FNN)


PAPER_FORCE_BAND = 0.2  # the output constraint's band of Eq. (17): 20 % of |F_MMG|


@dataclass(frozen=True)
class TrainingOptions(_Options):
    steps: int = 5
    stride_s: float = 2.0
    validation: Validation = Validation.BLOCKS  # blocks (of every training file) | files (whole files held out)
    val_fraction: float = 0.3      # share of the blocks, or of each group's files, held out
    block_s: float = 30.0          # validation blocks of this length, drawn per file
    split_seed: int = 0            # validation = "files": the draw of the held-out files (not the run's seed)
    batch_size: int = 128
    epochs: int = 400
    learning_rate: float = 1e-3
    lr_factor: float = 1.0         # learning rate x factor after lr_patience epochs without progress (1: constant)
    lr_patience: int = 10
    lambda_v: float = 1.0
    lambda_F: float = 1e-3
    force_band: float = PAPER_FORCE_BAND  # the output constraint's band: F_NN free within this share of |F_MMG| (Eq. 17)
    lambda_L2: float = 1e-6
    patience: int = 40
    max_minutes: float = 0.0       # 0: off; > 0: a safety limit whose hit fails the run
    threads: int = 1               # torch intra-op threads; 0: one per core
    warm_start_epochs: int = 150   # one-step regression on the implied residual force
    objective_s: float = 0.0       # horizon [s] of val_loss_multistep (the run's validation loss); 0: [evaluation] horizons
    dtype: DType = DType.FLOAT32
    device: str = "auto"           # auto (CUDA when present) | cpu | cuda | cuda:N


@dataclass(frozen=True)
class GateOptions(_Options):
    enabled: bool = True
    k: int = 10
    alpha: float = 0.9995
    space: GateSpace = GateSpace.FEATURES  # features (paper: last hidden activations) | inputs (standardised s)


@dataclass(frozen=True)
class IdentifyOptions(_Options):
    """How MMG coefficients are identified (`sysid.identify.trainer.Trainer.identify`).

    solver : "gradient" (Adam epochs on the multi-step loss, early stopping; `epochs`,
        `learning_rate`) or "levenberg_marquardt" (least squares on disjoint training
        windows, `sysid.identify.levenberg_marquardt`; `iterations`, `start_states`, `prior_weight`).
    start_states : "estimated" (each window's start (u, v_m, r) fitted too; the default for
        levenberg_marquardt, the estimator whose sigma was shown honest) or "recorded"
        (windows start from their recorded first sample; gradient's only way).
    prior_weight : lambda >= 0 of the residuals sqrt(lambda) (theta - prior) / |prior| toward
        the values identification starts from (ship file with [mmg] overrides);
        levenberg_marquardt only, 0 = none.
    integrator : the rule levenberg_marquardt integrates each window with over the log's
        sample interval: "euler" (as training and the paper) or "rk4".
    """

    parameters: tuple[str, ...] = ()
    bounds: dict = field(default_factory=dict)
    stage: Stage = Stage.BEFORE
    epochs: int = 60
    learning_rate: float = 2e-2
    solver: Solver = Solver.GRADIENT
    start_states: StartStates | None = None  # None: estimated for levenberg_marquardt, recorded for gradient
    prior_weight: float = 0.0
    iterations: int = 40            # levenberg_marquardt's iteration limit
    integrator: Method = Method.EULER   # levenberg_marquardt's integration rule

    def __post_init__(self):
        super().__post_init__()
        if self.start_states is None:
            resolved = StartStates.ESTIMATED if self.solver is Solver.LEVENBERG_MARQUARDT else StartStates.RECORDED
            object.__setattr__(self, "start_states", resolved)


@dataclass(frozen=True)
class EvaluationOptions(_Options):
    horizons: tuple[float, ...] = (30.0, 100.0)
    integrator: Method = Method.EULER


@dataclass(frozen=True)
class EnsembleOptions:
    members: tuple[str, ...] = ()   # run directories (relative to this run's) whose forces are averaged


@dataclass(frozen=True)
class Experiment:
    experiment: ExperimentOptions = ExperimentOptions()
    data: DataOptions = DataOptions()
    mmg: MMGOptions = MMGOptions()
    network: NetworkOptions = NetworkOptions()
    training: TrainingOptions = TrainingOptions()
    gate: GateOptions = GateOptions()
    identify: IdentifyOptions = IdentifyOptions()
    evaluation: EvaluationOptions = EvaluationOptions()
    ensemble: EnsembleOptions = EnsembleOptions()
    source: str = ""

    @property
    def needs_training(self) -> bool:
        """False for an MMG-only model with nothing to identify (it is used as defined)."""
        return not (self.experiment.model is ModelKind.MMG and not self.identify.parameters)

    def replace(self, **sections: dict) -> "Experiment":
        """A copy with some options changed: ``exp.replace(training={"epochs": 2})``."""
        changes = {}
        for name, values in sections.items():
            changes[name] = dataclasses.replace(getattr(self, name), **values)
        return dataclasses.replace(self, **changes)

    def to_table(self) -> dict[str, dict[str, Any]]:
        """The resolved config as the TOML document `to_toml` writes (every default filled
        in): section -> option -> plain value (choices as their words, arrays as lists), as
        ``tomllib.loads(exp.to_toml())`` reads it back."""
        return {section.name: {f.name: _plain(getattr(getattr(self, section.name), f.name))
                               for f in fields(getattr(self, section.name))}
                for section in fields(self) if section.name != "source"}

    def to_toml(self) -> str:
        """The resolved config as TOML (every default filled in)."""
        lines = []
        for section, options in self.to_table().items():
            lines.append(f"[{section}]")
            lines += [f"{name} = {_toml_value(value)}" for name, value in options.items()]
            lines.append("")
        return "\n".join(lines)


def _plain(value: Any) -> Any:
    """An option's value as TOML data: a choice as its word, a tuple as a list, a column
    map as its ``[data.columns]`` table."""
    return plain_data(value, ((ColumnMap, ColumnMap.as_table),))


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} as TOML")


MAX_WIDTH = 4096     # hidden layer width
MAX_MEMBERS = 64     # networks in an ensemble

_SECTIONS = {f.name: f.type for f in fields(Experiment) if f.name != "source"}


# the element type of every list option
_ELEMENT_TYPES = {("data", "train"): str, ("data", "rudder_sign_checked"): str, ("data", "validation"): str, ("data", "test"): str, ("ensemble", "members"): str, ("network", "hidden"): int,
                  ("identify", "parameters"): str, ("evaluation", "horizons"): float}
_NAMES = {int: "an integer", float: "a finite number", str: "a string"}


def _list_element(where: str, item: Any, kind: type):
    """One element of a list option, checked against its type (ints are numbers too)."""
    ok = (not isinstance(item, bool)) and (
        isinstance(item, kind) or (kind is float and isinstance(item, int)))
    if ok and kind is float:
        ok = math.isfinite(item)
    if not ok:
        raise ConfigError(f"{where}: every element must be {_NAMES[kind]}, got {item!r}")
    return float(item) if kind is float else item


def _number_pair(where: str, value: Any) -> None:
    if not (isinstance(value, list) and len(value) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
            and value[0] < value[1]):
        raise ConfigError(f"{where} must be [low, high], two finite numbers with low < high, got {value!r}")


def _coerce(section: str, opt_cls, table: dict, src: str):
    if not isinstance(table, dict):
        raise ConfigError(f"{src}: [{section}] must be a table")
    known = {f.name: f for f in fields(opt_cls)}
    out = {}
    for key, value in table.items():
        if key not in known:
            raise ConfigError(f"{src}: [{section}] unknown key {key!r} (known: {', '.join(known)})")
        default = getattr(opt_cls(), key)
        where = f"{src}: [{section}] {key}"
        choice = _choice_type(known[key])
        if choice is not None:
            if not isinstance(value, str):
                raise ConfigError(f"{where}: expected a string, one of {choice.listing()}; got {value!r}")
            if value == "" and known[key].default is None:  # "" for an optional choice: its default
                continue
            try:
                value = choice.parse(value, where, offered_only=True)
            except ValueError as exc:
                raise ConfigError(str(exc)) from None
        elif isinstance(default, bool):
            if not isinstance(value, bool):
                raise ConfigError(f"{where}: expected true/false, got {value!r}")
        elif isinstance(default, int):
            if isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"{where}: expected an integer, got {value!r}")
        elif isinstance(default, float):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ConfigError(f"{where}: expected a number, got {value!r}")
            if not math.isfinite(value):
                raise ConfigError(f"{where}: expected a finite number, got {value!r}")
            value = float(value)
        elif isinstance(default, str):
            if not isinstance(value, str):
                raise ConfigError(f"{where}: expected a string, got {value!r}")
        elif isinstance(default, tuple):
            if not isinstance(value, list):
                raise ConfigError(f"{where}: expected a list, got {value!r}")
            value = tuple(_list_element(where, item, _ELEMENT_TYPES[(section, key)]) for item in value)
        elif isinstance(default, dict):
            if not isinstance(value, dict):
                raise ConfigError(f"{where}: expected a table, got {value!r}")
        elif isinstance(default, ColumnMap):
            value = parse_columns(value, src)
        out[key] = value
    return opt_cls(**out)


def _validate(exp: Experiment, src: str) -> None:
    """`ConfigError` naming the file `src` and the option for the first option of `exp`
    that is out of range or contradicts another."""
    _check_training_data(exp, src)
    for ok, message in _range_checks(exp):
        if not ok:
            raise ConfigError(f"{src}: {message}")
    _check_coefficient_names(exp, src)
    if exp.experiment.model is ModelKind.NN and exp.identify.parameters:
        raise ConfigError(f"{src}: [identify] parameters need an MMG part (model mmg or hybrid)")


def _check_training_data(exp: Experiment, src: str) -> None:
    """The training and validation data named once: the paper's data set or your logs."""
    e, t = exp.experiment, exp.training
    if e.dataset not in ("", "D1", "D2"):
        raise ConfigError(f"{src}: [experiment] dataset = {e.dataset!r}: choose D1 or D2 (the paper's data), "
                          "or leave it out and list your logs in [data] train")
    if exp.data.train and e.dataset:
        raise ConfigError(f"{src}: [experiment] dataset = {e.dataset!r} and [data] train both name training "
                          "data: keep one (dataset for the paper's D1/D2, [data] train for your logs)")
    if exp.data.validation and not exp.data.train:
        raise ConfigError(f"{src}: [data] validation files need [data] train files")
    if exp.data.validation and t.validation is Validation.FILES:
        raise ConfigError(f"{src}: [data] validation names the validation logs and [training] validation = "
                          "\"files\" draws them from the training logs: keep one")


def _range_checks(exp: Experiment) -> list[tuple[bool, str]]:
    """(holds, what the option must be) for every range and pairing rule of the options."""
    e, t, g, i = exp.experiment, exp.training, exp.gate, exp.identify
    return [
        (t.steps >= 1, "[training] steps must be >= 1"),
        (t.stride_s > 0, "[training] stride_s must be > 0"),
        (0.0 < t.val_fraction < 1.0, "[training] val_fraction must be in (0, 1)"),
        (t.block_s > 0, "[training] block_s must be > 0"),
        (t.batch_size >= 1, "[training] batch_size must be >= 1"),
        (t.epochs >= 0, "[training] epochs must be >= 0"),
        (t.learning_rate > 0, "[training] learning_rate must be > 0"),
        (0 < t.lr_factor <= 1, "[training] lr_factor must be in (0, 1]"),
        (t.lr_patience >= 0, "[training] lr_patience must be >= 0"),
        (min(t.lambda_v, t.lambda_F, t.lambda_L2) >= 0, "[training] lambdas must be >= 0"),
        (t.force_band >= 0, "[training] force_band must be >= 0 (the paper's 0.2)"),
        (t.patience >= 1, "[training] patience must be >= 1"),
        (t.objective_s >= 0, "[training] objective_s must be >= 0 (0: the [evaluation] horizons)"),
        (t.max_minutes >= 0, "[training] max_minutes must be >= 0 (0: no wall-clock limit)"),
        (t.threads >= 0, "[training] threads must be >= 0 (0: one per core)"),
        (re.fullmatch(r"auto|cpu|cuda(:\d{1,3})?", t.device) is not None,
         f"[training] device = {t.device!r}: must be auto, cpu, cuda or cuda:N (N the GPU's number, e.g. cuda:0)"),
        (g.k >= 1, "[gate] k must be >= 1"),
        (0.0 < g.alpha < 1.0, "[gate] alpha must be in (0, 1)"),
        (i.solver is Solver.LEVENBERG_MARQUARDT or i.start_states is StartStates.RECORDED,
         f"[identify] start_states = '{i.start_states}' needs solver = \"levenberg_marquardt\" "
         "(gradient identification integrates every window from its recorded start)"),
        (i.prior_weight >= 0, "[identify] prior_weight must be >= 0 (0: no prior)"),
        (i.solver is Solver.LEVENBERG_MARQUARDT or i.prior_weight == 0,
         "[identify] prior_weight needs solver = \"levenberg_marquardt\""),
        (i.iterations >= 1, "[identify] iterations must be >= 1"),
        (i.integrator in Method.offered(), f"[identify] integrator must be one of {Method.listing()}"),
        (i.solver is Solver.LEVENBERG_MARQUARDT or i.integrator is Method.EULER,
         f"[identify] integrator = '{i.integrator}' needs solver = \"levenberg_marquardt\" (gradient "
         "identification integrates by Euler, as training)"),
        (i.solver is Solver.GRADIENT or i.stage is Stage.BEFORE,
         "[identify] solver = \"levenberg_marquardt\" identifies the MMG alone: stage \"joint\" (with "
         "the FNN) needs solver = \"gradient\""),
        (i.solver is Solver.GRADIENT or bool(i.parameters),
         "[identify] solver = \"levenberg_marquardt\" needs parameters to identify"),
        (0 <= e.seed < 2 ** 32, f"[experiment] seed = {e.seed}: must be >= 0 and < 2^32 (4294967296)"),
        (0 <= t.split_seed < 2 ** 32, f"[training] split_seed = {t.split_seed}: must be >= 0 and < 2^32 (4294967296)"),
        (len(exp.evaluation.horizons) > 0, "[evaluation] horizons must list at least one horizon [s]"),
        (all(h > 0 for h in exp.evaluation.horizons), "[evaluation] horizons must be > 0"),
        (exp.data.rate <= 0 or all(h * exp.data.rate >= 2 - 1e-9 or abs(h * exp.data.rate - round(h * exp.data.rate)) > 1e-9
                                   for h in exp.evaluation.horizons),   # a fractional one: its own error below
         f"[evaluation] horizons must be >= 2 samples at [data] rate ({2 / exp.data.rate if exp.data.rate > 0 else 2:g} "
         "s): a window of one sample is its start state alone, nothing is predicted and its RMSE is 0"),
        (all(w <= MAX_WIDTH for w in exp.network.hidden), f"[network] hidden widths must be <= {MAX_WIDTH}"),
        (exp.network.members <= MAX_MEMBERS, f"[network] members must be <= {MAX_MEMBERS}"),
        (t.steps <= 10_000, "[training] steps must be <= 10000"),
        (exp.evaluation.integrator in Method.offered(),
         f"[evaluation] integrator must be one of {Method.listing()}"),
        (bool(exp.network.hidden) and all(w >= 1 for w in exp.network.hidden), "[network] hidden must list widths >= 1"),
        (exp.data.rate > 0, "[data] rate must be > 0"),
        (exp.network.members >= 1, "[network] members must be >= 1"),
    ]


def _check_coefficient_names(exp: Experiment, src: str) -> None:
    """[mmg] overrides, [identify] parameters and bounds name coefficients of the ship file's
    families; the overrides are finite numbers, the bounds (low, high) pairs."""
    i = exp.identify
    try:
        for key in exp.mmg.overrides:
            parameter_name(key, f"{src}: [mmg] overrides")
        for key in i.parameters:
            parameter_name(key, f"{src}: [identify] parameters")
        for key, value in exp.mmg.overrides.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{src}: [mmg] overrides.{key} must be a finite number, got {value!r}")
        for key, bound in i.bounds.items():
            parameter_name(key, f"{src}: [identify] bounds")
            _number_pair(f"{src}: [identify] bounds.{key}", bound)
    except ConfigError:
        raise
    except Exception as exc:  # ShipDefinitionError on unknown names
        raise ConfigError(str(exc)) from None


# options that name files: a relative path resolves against the directory of the file that
# names it (the experiment config, or the sweep file that sets it); globs stay patterns
_PATH_OPTIONS = {("data", "train"), ("data", "validation"), ("data", "test")}


def is_ship_path(ship: str) -> bool:
    """A ship given as a file (``my_ship.toml``, ``ships/a``), not a bundled name."""
    return ship.endswith(".toml") or "/" in ship or os.sep in ship


def _anchored(path: str, directory: Path) -> str:
    return path if os.path.isabs(path) else os.path.normpath(os.path.join(directory, path))


def resolve_paths(sections: dict, directory: Path) -> dict:
    """Relative file options of parsed `sections` made absolute against `directory`."""
    out = dict(sections)
    ship = out["experiment"].ship
    if is_ship_path(ship):
        out["experiment"] = dataclasses.replace(out["experiment"], ship=_anchored(ship, directory))
    for section, key in _PATH_OPTIONS:
        value = getattr(out[section], key)
        resolved = tuple(_anchored(v, directory) for v in value) if isinstance(value, tuple) else (
            _anchored(value, directory) if value else value)
        out[section] = dataclasses.replace(out[section], **{key: resolved})
    return out


def parse_experiment(doc: dict, source: str = "<config>", directory: str | os.PathLike | None = None) -> Experiment:
    """A parsed TOML document to a validated `Experiment`.

    `directory`: where relative file options (``[experiment] ship`` as a file, ``[data] train
    / validation / test``) are anchored, the directory of the file that names them; None:
    left as given (relative to the working directory)."""
    doc = _normalized_data(doc, source)
    unknown = set(doc) - set(_SECTIONS)
    if unknown:
        raise ConfigError(f"{source}: unknown section(s) {sorted(unknown)} (known: {', '.join(_SECTIONS)})")
    experiment = doc.get("experiment")
    if not isinstance(experiment, dict) or "model" not in experiment:
        raise ConfigError(f"{source}: [experiment] model is required (mmg, nn or hybrid)"
                          + ("; the file is empty" if not doc else ""))
    sections = {name: _coerce(name, cls if isinstance(cls, type) else globals()[cls], doc.get(name, {}), source)
                for name, cls in _SECTIONS.items()}
    if directory is not None:
        sections = resolve_paths(sections, Path(directory))
    exp = Experiment(**sections, source=source)
    _validate(exp, source)
    if exp.data.train and "ship" not in experiment:
        _LOG.warning(f"{source}: [experiment] ship is not set, so your logs are modelled with the bundled "
                     f"{exp.experiment.ship} (the paper's Esso Osaka 3 m model): set ship = \"my_ship.toml\" "
                     f"(your ship file; `sysid init` writes one), or ship = \"{exp.experiment.ship}\" to keep it")
    return exp


def _normalized_data(doc: dict, source: str) -> dict:
    """``[data] files`` (the older name) as ``train``; ``validation = 0.3`` (a fraction) as
    ``[training] val_fraction``."""
    data = doc.get("data")
    if not isinstance(data, dict):
        return doc
    data = dict(data)
    if "files" in data:
        if "train" in data:
            raise ConfigError(f"{source}: [data] files and train both list training logs: keep train")
        data["train"] = data.pop("files")
    fraction = data.get("validation")
    if isinstance(fraction, (int, float)) and not isinstance(fraction, bool):
        training = dict(doc.get("training") or {})
        if "val_fraction" in training and training["val_fraction"] != fraction:
            raise ConfigError(f"{source}: [data] validation = {fraction!r} and [training] val_fraction = "
                              f"{training['val_fraction']!r} disagree: keep one")
        training["val_fraction"] = fraction
        del data["validation"]
        return {**doc, "data": data, "training": training}
    return {**doc, "data": data}


def load_experiment(path: str | os.PathLike) -> Experiment:
    """Read and validate an experiment TOML; errors name the file and key. Relative paths in it
    resolve against the file's directory, wherever the command runs."""
    path = Path(path)
    doc, _ = read_toml(path, "config file", ConfigError)
    exp = parse_experiment(doc, str(path), path.resolve().parent)
    path_component(f"{path}: [experiment] name", exp.experiment.name, ConfigError)
    return exp


def ship_overrides(exp: Experiment) -> dict[str, float]:
    """[mmg] overrides with canonical parameter names."""
    return {parameter_name(k): float(v) for k, v in exp.mmg.overrides.items()}


