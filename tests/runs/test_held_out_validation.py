"""A run validated on held-out training logs (``[training] validation = "files"``): the
trainer validates on whole held-out logs only, and the run directory names them and
reloads to the same draw."""
from __future__ import annotations

import json

from sysid.config.experiment import load_experiment
from sysid.data.recordings import read_run
from sysid.data.splits import data_split, hold_out_files
from sysid.device import compute_threads
from sysid.identify.trainer import Trainer
from sysid.runs.lifecycle import run_experiment
from tiny_experiment import tiny_experiment

BERTHING = ("berthing_12-Nov-2020_11_07_23.csv", "berthing_12-Nov-2020_11_14_47.csv",
            "berthing_12-Nov-2020_11_21_46.csv", "berthing_12-Nov-2020_11_38_50.csv")


def test_held_out_logs_are_validation_whole_and_the_run_names_them(dataset_dir, tmp_path):
    exp = load_experiment(tiny_experiment(tmp_path / "tiny.toml", dataset_dir, seed=0, epochs=1, warm_start_epochs=2))
    exp = exp.replace(data={"train": tuple(str(dataset_dir / "berthing" / f) for f in BERTHING)},
                      training={"validation": "files", "split_seed": 5})
    runs = [read_run(p) for p in data_split(exp).train]
    held = hold_out_files(runs, 0.3, 5)
    held_names = {r.name for r in held.validation}
    assert len(held_names) == 1                          # round(0.3 * 4) of one folder's 4 logs

    with compute_threads(exp.training.threads):  # as run_experiment trains
        trainer = Trainer(exp, progress=False, log=lambda m: None).fit(runs)
    rows = {f["file"]: f for f in trainer.summary_.split.files}
    assert set(rows) == {r.name for r in runs}
    for name, row in rows.items():  # a held-out log has validation windows only, the others training only
        assert (row["train_windows"] == 0 and row["val_windows"] > 0) if name in held_names else \
            (row["val_windows"] == 0 and row["train_windows"] > 0)
    assert trainer.summary_.n_val_windows == sum(rows[n]["val_windows"] for n in held_names)

    result = run_experiment(exp, tmp_path / "run", [], progress=False, log=lambda m: None)
    summary = json.loads((result.path / "summary.json").read_text())
    assert summary["data"]["held_out"] == {"val_fraction": 0.3, "split_seed": 5, "groups": {"berthing": sorted(held_names)}}
    assert {f["file"] for f in summary["data"]["validation"]} == {str(r.path) for r in held.validation}
    assert summary["val_loss_multistep"] == trainer.summary_.val_loss_multistep   # the same training, twice
    # the report's methods name them
    from sysid.report.methods import methods_paragraphs
    from sysid.report.source import read_source
    (held_name,) = held_names
    assert any(f"validated on 1 training log held out whole (berthing: {held_name}; split_seed 5)" in p
               for p in methods_paragraphs(read_source(result.path)))
    # the run's config.toml lists every training log and draws the same validation logs again
    again = load_experiment(result.path / "config.toml")
    assert again.training.validation == "files" and again.data.validation == ()
    assert sorted(again.data.train) == sorted(str(r.path) for r in runs)
    assert {r.name for r in hold_out_files([read_run(p) for p in data_split(again).train], 0.3, 5).validation} \
        == held_names
