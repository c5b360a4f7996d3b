"""The experiment config's reference: every key with its type, default, unit and meaning.

Sections, keys, types and defaults are read from the typed config (`sysid.config.experiment`),
so they cannot drift from what the parser accepts; choices come from the enums and tuples the
parser checks against. Units and meanings are written here, one entry per key: a test checks
that every key of the typed config has one and that none is left over. `markdown` renders
the docs page (``docs/reference/config.md``, through the docs build's hook); `sysid init`
writes its commented experiment config from the same entries (`sysid.config.templates`).
"""
from __future__ import annotations

import dataclasses
import enum
import types
import typing
from dataclasses import dataclass, fields

from sysid.config import experiment as config
from sysid.config.choices import Choice

# section -> one sentence
SECTIONS: dict[str, str] = {
    "experiment": "What is trained: the model kind, the ship and the seed.",
    "data": "The processed logs to train on and how they are read.",
    "mmg": "Changes to the ship file's MMG coefficients for this experiment.",
    "network": "The FNN force correction (NN-only and hybrid models).",
    "training": "Windows, losses, optimiser and stopping of the multi-step training.",
    "gate": "The kNN out-of-distribution gate that switches the FNN off far from the training data.",
    "identify": "Identification of MMG coefficients from the data (MMG-only or hybrid).",
    "evaluation": "How the trained model is scored on the test files.",
    "ensemble": "A mean-of-seeds ensemble of trained runs (written by `sysid reproduce --seeds`).",
}


@dataclass(frozen=True)
class KeyDoc:
    """unit : physical unit ("" for none); meaning : what the key does, in one or two sentences."""

    unit: str
    meaning: str


# (section, key) -> unit and meaning
KEYS: dict[tuple[str, str], KeyDoc] = {
    ("experiment", "name"): KeyDoc("", "Name of the experiment, shown in logs, summary.json and reports."),
    ("experiment", "model"): KeyDoc("", "The model: `mmg` (the ship file's MMG, optionally identified), `nn` "
                                        "(an FNN alone, the paper's NN-only) or `hybrid` (MMG + FNN force correction)."),
    ("experiment", "dataset"): KeyDoc("", "The paper's FRT-DS-ESSO data set `D1` or `D2` (its training files, "
                                          "and the paper's six test files); for your own logs, list them under "
                                          "`[data]` instead."),
    ("experiment", "ship"): KeyDoc("", "A bundled ship by name (`esso_osaka`, `kvlcc2_l7`) or a ship file "
                                       "(`my_ship.toml`, relative to this config)."),
    ("experiment", "seed"): KeyDoc("", "Seed of every random choice (validation blocks, initial weights, "
                                       "minibatches): a run is a function of config, data and seed."),
    ("data", "files"): KeyDoc("", "Your processed logs to train on: files, directories (every .csv below) or "
                                  "glob patterns (`logs/*.csv`), relative to this config."),
    # the [data] keys of the own-logs issue (train / validation / test / columns replace files)
    ("data", "train"): KeyDoc("", "Your logs to train on: files, folders or glob patterns (`logs/*.csv`), "
                                  "relative to this config. Leave `[experiment] dataset` out with them."),
    ("data", "validation"): KeyDoc("", "Logs held back whole for validation (early stopping, the validation "
                                       "loss); empty: `[training] val_fraction` of the training logs' blocks "
                                       "(`validation = 0.3` sets that share)."),
    ("data", "test"): KeyDoc("", "Logs the model is scored on beside its physics baseline, read only by "
                                 "evaluation, never to train or to choose; a log in two of train, validation "
                                 "and test is an error."),
    ("data", "columns"): KeyDoc("per column", "Your logs' column names and units, per sysid channel (`t`, `x`, "
                                              "`u`, `y`, `v`, `psi`, `r`, `n_prop`, `delta_rudder`, "
                                              "`wind_velo_true`, `wind_dir_true`, ...), e.g. "
                                              "`u = { column = \"STW\", unit = \"knots\" }`; a channel "
                                              "without an entry reads the processed-log column."),
    ("data", "rate"): KeyDoc("Hz", "Sample rate the logs are read at (samples are taken, not averaged); "
                                   "the processed logs are 1 Hz."),
    ("data", "exclude_suspect"): KeyDoc("", "Leave out windows that touch a segment the preprocessing marked "
                                            "suspect (frozen GNSS)."),
    ("data", "exclude_astern"): KeyDoc("", "Under a one-quadrant propeller model (the ship file's `[propeller] "
                                           "model` other than `four_quadrant`): leave out of training and "
                                           "validation the windows that hold a sample with astern revolutions "
                                           "(`n_prop` < 0) or going astern (`u` < 0), where that model does not "
                                           "hold; `false` keeps them. Counted per log in the training log and "
                                           "summary.json either way; test windows are always kept and counted."),
    ("data", "rudder_sign_checked"): KeyDoc("", "Logs (file names without `.csv`) whose rudder sign you have "
                                                "checked yourself and which the rudder check still reads as "
                                                "reversed (strong wind or current, tugs, little rudder): they are "
                                                "read anyway, with a warning, and the run records the override beside "
                                                "each (summary.json `data.train[i].rudder_sign_checked`). Empty: "
                                                "every such log is refused."),
    ("mmg", "overrides"): KeyDoc("as in the ship file", "Ship-file coefficients replaced for this experiment, "
                                                        "e.g. `{ X_vr = 0.4535 }`; names as in the ship file."),
    ("network", "hidden"): KeyDoc("", "Widths of the FNN's hidden layers (tanh); 9 inputs and 3 outputs "
                                      "(X, Y, N) are added around them."),
    ("network", "members"): KeyDoc("", "Networks trained side by side from different initial weights and "
                                       "averaged (1: the paper's single FNN)."),
    ("training", "steps"): KeyDoc("steps", "T: integration steps of each training window's multi-step loss "
                                           "(T / rate seconds)."),
    ("training", "stride_s"): KeyDoc("s", "Training windows start this far apart."),
    ("training", "validation"): KeyDoc("", "What validation (early stopping, the validation loss, sweeps' "
                                            "choices) is: `blocks` (default), a `val_fraction` of every "
                                            "training file's `block_s` blocks (the same maneuvers as training); "
                                            "`files`, a `val_fraction` of the training files of each folder "
                                            "(maneuver type) held out whole, at least one of a folder with two "
                                            "or more and never all, so validation sees maneuvers the model did "
                                            "not train on. Not with `[data] validation`."),
    ("training", "val_fraction"): KeyDoc("", "Share held back for validation, in (0, 1): of each file's blocks "
                                              "(`validation = \"blocks\"`), or of each folder's training files "
                                              "(`validation = \"files\"`, rounded)."),
    ("training", "split_seed"): KeyDoc("", "Seed of the draw of the held-out files (`validation = \"files\"`), "
                                            "apart from `[experiment] seed` so that every configuration and seed "
                                            "of a sweep is judged on the same files."),
    ("training", "block_s"): KeyDoc("s", "Length of the blocks each file is cut into for the validation split; "
                                         "windows never straddle two blocks."),
    ("training", "batch_size"): KeyDoc("windows", "Training windows per optimiser step."),
    ("training", "epochs"): KeyDoc("", "Upper limit of training epochs; training ends earlier on early "
                                       "stopping (`patience`)."),
    ("training", "learning_rate"): KeyDoc("", "Adam's learning rate for the FNN (and MMG coefficients "
                                              "identified jointly)."),
    ("training", "lr_factor"): KeyDoc("", "The learning rate is multiplied by this after `lr_patience` epochs "
                                          "without a better validation loss; 1: constant."),
    ("training", "lr_patience"): KeyDoc("epochs", "Epochs without progress before the learning rate falls "
                                                  "(with `lr_factor` < 1)."),
    ("training", "lambda_v"): KeyDoc("", "Weight of the velocity loss: squared errors of u, v_m, r over the "
                                         "window, each channel divided by its variance."),
    ("training", "lambda_F"): KeyDoc("", "Weight of the output penalty that keeps the FNN's force small "
                                         "against the MMG's (hybrid only)."),
    ("training", "force_band"): KeyDoc("", "The output constraint's band (Eq. 17): the penalty is zero while every "
                                           "component of the FNN's force stays within this share of the MMG's; "
                                           "the paper's 0.2 (hybrid only)."),
    ("training", "lambda_L2"): KeyDoc("", "Weight of the squared norm of the FNN's weights."),
    ("training", "patience"): KeyDoc("epochs", "Early stopping: training ends after this many epochs without a "
                                               "better validation loss; the best epoch's weights are kept."),
    ("training", "max_minutes"): KeyDoc("min", "A safety limit on wall-clock time; when hit the run is written "
                                               "marked failed. 0: off."),
    ("training", "threads"): KeyDoc("", "torch CPU threads of this run; 0: one per core. One thread is as fast "
                                        "for these small networks and leaves cores to other jobs."),
    ("training", "warm_start_epochs"): KeyDoc("epochs", "Before the multi-step training, the FNN regresses the "
                                                        "force the MMG leaves unexplained, one step at a time; "
                                                        "0: no warm start."),
    ("training", "objective_s"): KeyDoc("s", "Horizon of the run's final validation loss (`val_loss_multistep` in "
                                             "summary.json, what sweeps rank on); 0: the `[evaluation] horizons`, "
                                             "the horizons the verdict judges (one definition of good)."),
    ("training", "dtype"): KeyDoc("", "Floating-point type of training: `float32` or `float64`."),
    ("training", "device"): KeyDoc("", "`auto` (CUDA when present, else CPU), `cpu`, `cuda` or `cuda:N`."),
    ("gate", "enabled"): KeyDoc("", "Use the kNN gate: the FNN's correction is switched off where the state is "
                                    "far from every training sample."),
    ("gate", "k"): KeyDoc("", "Neighbours whose mean distance decides the gate."),
    ("gate", "alpha"): KeyDoc("", "Quantile of the training samples' own kNN distances used as the threshold "
                                  "(0.9995: 0.05 % of the training data would be called out of distribution)."),
    ("gate", "space"): KeyDoc("", "Where distances are measured: `features` (the last hidden layer, the "
                                  "paper's choice) or `inputs` (the FNN's standardised inputs)."),
    ("identify", "parameters"): KeyDoc("", "Ship-file coefficients to identify from the data, e.g. "
                                           "`[\"Y_v\", \"Y_r\", \"N_v\", \"N_r\"]`; empty: none."),
    ("identify", "bounds"): KeyDoc("as in the ship file", "Optional `[low, high]` per identified coefficient, "
                                                          "e.g. `{ Y_v = [-1.0, 0.0] }`."),
    ("identify", "stage"): KeyDoc("", "`before`: identify the MMG first, then train the FNN on it; `joint`: "
                                      "coefficients and FNN together (needs solver `gradient`)."),
    ("identify", "epochs"): KeyDoc("", "Epoch limit of gradient identification (early stopping as in training)."),
    ("identify", "learning_rate"): KeyDoc("", "Adam's learning rate of gradient identification."),
    ("identify", "solver"): KeyDoc("", "`gradient` (Adam on the multi-step loss) or `levenberg_marquardt` "
                                       "(least squares on disjoint windows, with an honest standard error)."),
    ("identify", "start_states"): KeyDoc("", "`estimated`: each window's start (u, v_m, r) is fitted too; "
                                             "`recorded`: windows start from the recorded sample. Empty: "
                                             "estimated for levenberg_marquardt, recorded for gradient."),
    ("identify", "prior_weight"): KeyDoc("", "lambda >= 0 of a pull toward the ship file's values "
                                             "(levenberg_marquardt only); 0: none."),
    ("identify", "iterations"): KeyDoc("", "Iteration limit of levenberg_marquardt."),
    ("identify", "integrator"): KeyDoc("", "Integration rule of levenberg_marquardt over each sample interval: "
                                           "`euler` (as trained, the paper's) or `rk4` (coefficients nearer the "
                                           "physical ones on logs of 1 s steps; levenberg_marquardt only)."),
    ("evaluation", "horizons"): KeyDoc("s", "Prediction horizons that define a good model: the test scores (RMSE "
                                            "of u, v_m, r over consecutive windows of each test file) and the "
                                            "verdict are at them, and so is the validation loss sweeps rank on "
                                            "(unless `[training] objective_s` is set)."),
    ("evaluation", "integrator"): KeyDoc("", "Integration rule of the test predictions: `euler` (as trained, "
                                             "the paper's) or `rk4`."),
    ("ensemble", "members"): KeyDoc("", "Run directories (relative to this run's) whose models' forces are "
                                        "averaged; empty: not an ensemble."),
}

# options whose values the parser checks against a fixed set of strings without an enum; an
# option typed as a `sysid.config.choices.Choice` takes the members a config may name
_CHOICES: dict[tuple[str, str], tuple[str, ...]] = {
    ("experiment", "dataset"): ("D1", "D2"),
}


@dataclass(frozen=True)
class KeyReference:
    """One key of the experiment config, as the docs and `sysid init` show it."""

    section: str
    key: str
    type: str
    default: object
    unit: str
    meaning: str
    choices: tuple[str, ...] = ()

    @property
    def default_toml(self) -> str:
        """The default as written in a TOML file."""
        return toml_value(self.default)


def toml_value(value) -> str:
    """A config value (an enum member, a table object) as written in a TOML file; None (an
    optional choice left to its default) as the empty string."""
    if value is None:
        return '""'
    if isinstance(value, enum.Enum):
        value = value.value
    if hasattr(value, "as_table"):  # a table of its own, e.g. [data.columns]
        value = value.as_table()
    return config._toml_value(value)


def _optional_of(hint):
    """``X | None`` to X (an optional option), anything else as it is."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    return args[0] if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1 else hint


def _type_name(hint) -> str:
    hint = _optional_of(hint)
    origin = typing.get_origin(hint)
    if origin in (tuple, list):
        return f"list of {_type_name(typing.get_args(hint)[0])}"
    if origin is dict or hint is dict or hasattr(hint, "as_table"):
        return "table"
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return "string (choice)"
    return {str: "string", int: "integer", float: "number", bool: "boolean"}.get(hint, str(hint))


def _default(f: dataclasses.Field):
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory()  # type: ignore[operator]


def sections() -> list[tuple[str, type]]:
    """(name, options class) of every section of the experiment config, in file order."""
    hints = typing.get_type_hints(config.Experiment)
    return [(f.name, hints[f.name]) for f in fields(config.Experiment) if f.name != "source"]


def config_keys() -> list[KeyReference]:
    """Every key of the experiment config, section by section, with its documentation
    (unit and meaning empty where `KEYS` lacks an entry: the reference test catches that)."""
    out = []
    for section, options in sections():
        hints = typing.get_type_hints(options)
        for f in fields(options):
            hint = _optional_of(hints[f.name])
            doc = KEYS.get((section, f.name), KeyDoc("", ""))
            choices = tuple(m.value for m in hint.offered()) if isinstance(hint, type) and issubclass(hint, Choice) \
                else _CHOICES.get((section, f.name), ())
            out.append(KeyReference(section, f.name, _type_name(hint), _default(f), doc.unit, doc.meaning, choices))
    return out


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown() -> str:
    """The reference as Markdown: one table per section."""
    lines = ["Every key of an experiment config (`sysid train CONFIG`). Every key is optional except "
             "`[experiment] model`; a key the config does not name takes the default shown. Unknown "
             "keys are errors. Relative paths resolve against the config file's folder.", ""]
    by_section: dict[str, list[KeyReference]] = {}
    for ref in config_keys():
        by_section.setdefault(ref.section, []).append(ref)
    for section, refs in by_section.items():
        lines += [f"## `[{section}]`", "", SECTIONS.get(section, ""), "",
                  "| key | type | default | unit | meaning |", "|---|---|---|---|---|"]
        for ref in refs:
            meaning = ref.meaning + (f" One of: {', '.join(f'`{c}`' for c in ref.choices)}." if ref.choices else "")
            lines.append(f"| `{ref.key}` | {ref.type} | `{_cell(ref.default_toml)}` | {_cell(ref.unit) or '-'} "
                         f"| {_cell(meaning)} |")
        lines.append("")
    return "\n".join(lines)


MARKER = "<!-- generated: config-reference (python -m sysid.config.reference --write); edit above this line -->"


def generated_page(page: str, marker: str, generated: str) -> str:
    """A docs page whose part below its `marker` line is `generated`: the text above the
    marker kept as written, the marker, then the generated text (one newline at the end)."""
    if marker not in page:
        raise ValueError(f"the page has no line {marker!r}")
    return page[:page.index(marker) + len(marker)] + "\n\n" + generated.strip("\n") + "\n"


def regenerate(path, marker: str, generated: str, write: bool) -> bool:
    """Whether the page at `path` is what `generated_page` makes of it; with `write`, make
    it so."""
    from pathlib import Path

    path = Path(path)
    page = path.read_text()
    wanted = generated_page(page, marker, generated)
    if write and wanted != page:
        path.write_text(wanted)
    return wanted == page


PAGE = "docs/reference/config.md"   # relative to the repository's root


def page_command(argv, page: str, marker: str, generate) -> int:
    """A reference page's command line: print `generate()`; ``--write`` writes it into `page`
    (relative to the repository's root) below its `marker`; ``--check`` exits 1 when the
    page differs."""
    import sys
    from pathlib import Path

    args = sys.argv[1:] if argv is None else list(argv)
    if not {"--write", "--check"} & set(args):
        print(generate())
        return 0
    same = regenerate(Path(__file__).resolve().parents[2] / page, marker, generate(), "--write" in args)
    return 0 if same or "--write" in args else 1


def main(argv=None) -> int:
    """``python -m sysid.config.reference [--write | --check]`` (`page_command` of this page)."""
    return page_command(argv, PAGE, MARKER, markdown)


if __name__ == "__main__":
    raise SystemExit(main())
