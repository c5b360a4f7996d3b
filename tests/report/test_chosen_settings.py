""""How the settings were chosen": each learned run's settings from its config.toml (with the
validation design, old runs without ``[training] validation`` reading as blocks), the shipped
configs' comments where the run uses the shipped value, and a sweep linked to the report
(``sysid report SOURCE --sweep DIR``) with its validation landscape."""
from __future__ import annotations

import json
import tomllib
from types import SimpleNamespace

import pandas as pd
import pytest

from sysid.package_data import bundled_dir
from sysid.config.experiment import load_experiment
from sysid.errors import CheckpointError
from sysid.report.chosen_settings import chosen_section, config_comments, run_reasons, settings_row
from sysid.report.figure_plan import figure_plan
from sysid.report.pdf import text_blocks
from sysid.report.source import read_source
from sysid.store.manifest import write_manifest

from synthetic_rundir import measured_runs, write_run

TOML = """# a file header, not a setting's
[network]
# chosen on validation loss
# (two lines)
hidden = [64, 64]        # 9-64-64-3

[training]
steps = 5
# a comment ended by a blank line

batch_size = 512         # per step
name = "a # inside a string"
"""


def test_comments_attach_to_the_key_below_them_and_after_their_value():
    assert config_comments(TOML) == {"network.hidden": "chosen on validation loss (two lines) 9-64-64-3",
                                     "training.batch_size": "per step"}


def _shipped(name: str) -> dict:
    """A run's resolved config as `sysid train` writes it from the shipped experiment."""
    return tomllib.loads(load_experiment(bundled_dir("experiments") / f"{name}.toml").to_toml())


def _run(name: str, model: str, config: dict):
    return SimpleNamespace(name=name, model=model, dataset=name.rsplit("_", 1)[1], config=config)


def test_settings_row_reads_the_runs_config_and_the_validation_design():
    config = _shipped("hybrid_D1")
    config["training"].pop("validation", None)           # a run written before the key existed
    config["training"].pop("objective_s", None)          # scored over its T steps
    config["training"].setdefault("block_s", 30.0)
    row = settings_row(_run("hybrid_D1", "hybrid", config))
    shipped = config
    assert row.network == "-".join(str(w) for w in shipped["network"]["hidden"])
    assert row.steps == str(shipped["training"]["steps"])
    assert row.lambda_F == f"{shipped['training']['lambda_F']:g}"
    assert row.gate == f"{shipped['gate']['space']}, {shipped['gate']['alpha']:g}, {shipped['gate']['k']}"
    assert row.validation == (f"blocks: {100 * shipped['training']['val_fraction']:.0f} % of each training log's "
                              f"{shipped['training']['block_s']:g}-s blocks")
    config["training"].update(validation="files", val_fraction=0.25, split_seed=3)
    config["network"].update(hidden=[32, 16], members=4)
    row = settings_row(_run("hybrid_D1", "hybrid", config))
    assert row.validation == "whole files: 25 % of each maneuver group's training logs held out (split seed 3)"
    assert row.network == "32-16, 4 members averaged"
    assert settings_row(_run("nn_D1", "nn", _shipped("nn_D1"))).gate.startswith("-")


def test_a_reason_is_shown_only_where_the_run_uses_the_shipped_value():
    config = _shipped("hybrid_D1")
    text = (bundled_dir("experiments") / "hybrid_D1.toml").read_text()
    comments = config_comments(text)
    assert "network.hidden" in comments      # the shipped config explains its width
    reasons = dict(run_reasons(_run("hybrid_D1", "hybrid", config)))
    assert reasons["network.hidden"] == comments["network.hidden"]
    config["network"]["hidden"] = [7, 7]
    assert "network.hidden" not in dict(run_reasons(_run("hybrid_D1", "hybrid", config)))
    assert run_reasons(_run("hybrid_D9", "hybrid", config)) == []   # no shipped config of that name


def _sweep(path, name="width"):
    path.mkdir()
    (path / "sweep.toml").write_text('[sweep]\nname = "width"\n')
    trials = pd.DataFrame({"point": ["p0", "p0", "p1", "p1"], "seed": [0, 1, 0, 1], "run": ["a", "b", "c", "d"],
                           "status": "complete", "network.hidden": ["[64, 64]"] * 2 + ["[128, 128]"] * 2,
                           "val_loss_multistep": [0.049, 0.050, 0.052, 0.051]})
    trials.to_csv(path / "results.csv", index=False)
    pd.DataFrame({"point": ["p0", "p1"], "val_loss_multistep_mean": [0.0495, 0.0515],
                  "val_loss_multistep_std": [0.0007, 0.0007], "complete": [2, 2], "seeds": [2, 2]}).to_csv(
        path / "points.csv", index=False)
    (path / "summary.json").write_text(json.dumps({"name": name, "search": "grid", "seeds": [0, 1],
                                                   "keys": ["network.hidden"], "trials": 4, "complete": 4}))
    return path


def test_a_linked_sweep_adds_its_landscape_and_the_settings_section(tmp_path):
    run_dir = write_run(tmp_path / "hybrid_D1", "hybrid_D1", measured_runs(scale=0.3), horizons=(30,))
    config = _shipped("hybrid_D1")
    (run_dir / "config.toml").write_text(load_experiment(bundled_dir("experiments") / "hybrid_D1.toml").to_toml())
    write_manifest(run_dir, "run")
    source = read_source(run_dir, [_sweep(tmp_path / "sweep")])
    plan = figure_plan(source, None)
    keys = [f.key for f in plan.figures]
    assert "sweep_width_keys" in keys and "sweep_width_seeds" in keys
    spec = next(f for f in plan.figures if f.key == "sweep_width_keys")
    assert spec.section == "Sweep width" and spec.factory().axes[0].get_ylabel() == "val_loss_multistep [-]"
    section = chosen_section(source)
    assert [r.label for r in section.rows] == ["Hybrid D1"]
    assert section.rows[0].network == "-".join(str(w) for w in config["network"]["hidden"])
    assert section.sweeps[0][0] == "width" and "--sweep" not in section.note
    blocks = text_blocks("t", [], [], [], [], [], chosen=section)
    assert ("h2", "How the settings were chosen") in blocks
    assert any(b[0] == "kv" and b[1] == "Hybrid D1" and f"T [steps]: {config['training']['steps']}" in b[2] for b in blocks)
    with pytest.raises(CheckpointError, match="not a sweep directory"):
        read_source(run_dir, [tmp_path])
