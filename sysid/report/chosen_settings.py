"""The report's "How the settings were chosen": the settings of every learned run that decide
its accuracy (network, multi-step horizon T, lambda_F, batch and learning rate, kNN gate,
validation design), read from the run's config.toml, and the reasons the shipped experiment
configs give for them (their comments, `sysid/configs/experiments/`), shown only where the run
uses the shipped value."""
from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from sysid.config.choices import ModelKind
from sysid.package_data import bundled_dir
from sysid.config.experiment import Experiment
from sysid.protocol.paper import run_label
from sysid.report.source import ReportSource, RunRecord

_SECTION = re.compile(r"^\s*\[([A-Za-z0-9_.]+)\]\s*(#.*)?$")
_KEY = re.compile(r"^\s*([A-Za-z0-9_]+)\s*=\s*(.*)$")
SETTINGS_HEADER = ["Run", "Network (hidden)", "T [steps]", "lambda_F", "Batch, learning rate",
                   "kNN gate (space, alpha, k)", "Validation (chooses epochs and settings)"]


@dataclass(frozen=True)
class SettingsRow:
    """One learned run's chosen settings as text cells in the order of `SETTINGS_HEADER`."""

    label: str
    network: str
    steps: str
    lambda_F: str
    batch_lr: str
    gate: str
    validation: str

    @property
    def cells(self) -> list[str]:
        return [self.label, self.network, self.steps, self.lambda_F, self.batch_lr, self.gate, self.validation]


@dataclass(frozen=True)
class Reason:
    """A shipped config's comment on one setting (``section.key``), for the runs using its value."""

    setting: str
    runs: str
    text: str


def _setting(run: RunRecord, section: str, key: str):
    """The run's config.toml value, else sysid's default (a key a run's sysid did not write:
    ``[training] validation`` of runs before it existed reads as its default), else None."""
    values = run.config.get(section)
    if isinstance(values, dict) and key in values:
        return values[key]
    default = getattr(getattr(Experiment(), section, None), key, None)
    return getattr(default, "value", default)


def validation_text(run: RunRecord) -> str:
    """How the run's validation windows were drawn, from ``[data] validation`` and
    ``[training] validation`` ("blocks", the default, or "files")."""
    named = _setting(run, "data", "validation") or []
    if named:
        return f"{len(named)} named validation log{'s' if len(named) != 1 else ''} ([data] validation)"
    fraction = float(_setting(run, "training", "val_fraction") or 0.0)
    design = str(_setting(run, "training", "validation") or "blocks")
    if design == "files":
        seed = _setting(run, "training", "split_seed")
        return (f"whole files: {100 * fraction:.0f} % of each maneuver group's training logs held out"
                + (f" (split seed {seed})" if seed is not None else ""))
    block = float(_setting(run, "training", "block_s") or 0.0)
    return f"blocks: {100 * fraction:.0f} % of each training log's {block:g}-s blocks"


def settings_row(run: RunRecord) -> SettingsRow:
    """The settings of one learned run (`SETTINGS_HEADER`)."""
    hidden = _setting(run, "network", "hidden") or []
    members = int(_setting(run, "network", "members") or 1)
    network = "-".join(str(int(w)) for w in hidden) + (f", {members} members averaged" if members > 1 else "")
    if run.model != ModelKind.HYBRID:
        gate = "- (no MMG to fall back to)"
    elif not _setting(run, "gate", "enabled"):
        gate = "off"
    else:
        gate = f"{_setting(run, 'gate', 'space')}, {float(_setting(run, 'gate', 'alpha')):g}, {_setting(run, 'gate', 'k')}"
    objective = float(_setting(run, "training", "objective_s") or 0.0)
    lr = float(_setting(run, "training", "learning_rate"))
    factor = float(_setting(run, "training", "lr_factor") or 1.0)
    schedule = f" (x {factor:g} after {_setting(run, 'training', 'lr_patience')} epochs without progress)" \
        if factor != 1.0 else ""
    steps = f"{_setting(run, 'training', 'steps')}" + (f"; objective {objective:g} s" if objective > 0 else "")
    return SettingsRow(run_label(run.name, run.model, run.dataset), network, steps,
                       f"{float(_setting(run, 'training', 'lambda_F')):g}",
                       f"{_setting(run, 'training', 'batch_size')}, {lr:g}{schedule}", gate, validation_text(run))


def config_comments(text: str) -> dict[str, str]:
    """``section.key`` -> its comment in a TOML text: the comment lines right above the key
    (a blank line or a section header ends a block) and the comment after its value."""
    out: dict[str, str] = {}
    section, block = "", []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped:
            block = []
            continue
        if stripped.startswith("#"):
            block.append(stripped.lstrip("#").strip())
            continue
        header = _SECTION.match(line)
        if header:
            section, block = header.group(1), []
            continue
        key = _KEY.match(line)
        if key:
            inline = key.group(2).split("#", 1)[1].strip() if "#" in key.group(2) and '"' not in key.group(2) else ""
            text_ = " ".join(block + ([inline] if inline else []))
            if text_:
                out[f"{section}.{key.group(1)}"] = text_
        block = []
    return out


def shipped_config(run: RunRecord) -> Path | None:
    """The shipped experiment config the run was made from (by the run's name), or None."""
    path = bundled_dir("experiments") / f"{run.name}.toml"
    return path if path.is_file() else None


def run_reasons(run: RunRecord) -> list[tuple[str, str]]:
    """(section.key, comment) of the run's shipped config where the run uses its value."""
    path = shipped_config(run)
    if path is None:
        return []
    text = path.read_text()
    shipped = tomllib.loads(text)
    out = []
    for setting, comment in config_comments(text).items():
        section, key = setting.rsplit(".", 1)
        value = (shipped.get(section) or {}).get(key)
        if value is not None and _same(value, _setting(run, section, key)):
            out.append((setting, comment))
    return out


def _same(shipped, used) -> bool:
    """The shipped config's value equals the run's (numbers by value, lists element-wise)."""
    if isinstance(shipped, (list, tuple)) and isinstance(used, (list, tuple)):
        return len(shipped) == len(used) and all(_same(a, b) for a, b in zip(shipped, used))
    if isinstance(shipped, (int, float)) and isinstance(used, (int, float)) and not isinstance(shipped, bool):
        return float(shipped) == float(used)
    return shipped == used


def learned_runs(source: ReportSource) -> list[RunRecord]:
    """The runs with a trained network (NN-only and hybrids), ensembles of seeds left out."""
    return [r for r in source.runs if r.model in (ModelKind.NN, ModelKind.HYBRID)
            and not (r.config.get("ensemble") or {}).get("members")]


def chosen_settings(source: ReportSource) -> tuple[list[SettingsRow], list[Reason]]:
    """The settings table of the learned runs and the shipped configs' reasons, one reason
    per distinct (setting, comment) with the runs it applies to."""
    runs = learned_runs(source)
    rows = [settings_row(r) for r in runs]
    grouped: dict[tuple[str, str], list[str]] = {}
    for run in runs:
        for setting, comment in run_reasons(run):
            grouped.setdefault((setting, comment), []).append(run_label(run.name, run.model, run.dataset))
    reasons = [Reason(setting, ", ".join(labels), comment) for (setting, comment), labels in grouped.items()]
    return rows, sorted(reasons, key=lambda r: (r.setting.split(".")[0] != "network", r.setting))


@dataclass(frozen=True)
class ChosenSection:
    """The section's content: the settings table (`SETTINGS_HEADER`, one row per learned run),
    the shipped configs' reasons, and per linked sweep (name, directory, summary lines)."""

    header: list[str]
    rows: list[SettingsRow]
    reasons: list[Reason]
    sweeps: list[tuple[str, str, list[tuple[str, str]]]]
    note: str


def chosen_section(source: ReportSource) -> ChosenSection | None:
    """"How the settings were chosen" for a source with learned runs or linked sweeps, else None."""
    from sysid.report.methods import sweep_record_items

    rows, reasons = chosen_settings(source)
    sweeps = [(s.summary.name, str(s.path), sweep_record_items(s)) for s in source.linked_sweeps]
    if not rows and not sweeps:
        return None
    note = ("Every choice is made on the validation windows (the validation design in the last column), never "
            "on the test files. The reasons are the comments of the shipped experiment configs "
            "(configs/experiments/), shown where the run uses the shipped value. ")
    note += ("The validation landscapes of the linked sweeps follow as figures." if sweeps else
             "A sweep's validation landscape (`sysid sweep`) is added to this report by "
             "`sysid report SOURCE --sweep SWEEP_DIR` (repeatable).")
    return ChosenSection(SETTINGS_HEADER, rows, reasons, sweeps, note)
