"""Training logs outside what the ship file's force models cover warn with the share of
samples: the real berthing logs' astern revolutions under the one-quadrant standard
propeller (kvlcc2_l7), none under Esso Osaka's four-quadrant models."""
from __future__ import annotations

import json
import logging

import numpy as np
import pandas as pd

from sysid.config.experiment import load_experiment
from sysid.runs.lifecycle import training_runs, warn_outside_force_models

BERTHING = ("berthing_12-Nov-2020_11_07_23.csv", "berthing_12-Nov-2020_13_21_03.csv")


def _experiment(tmp_path, dataset_dir, ship):
    files = [str(dataset_dir / "berthing" / name) for name in BERTHING]
    config = tmp_path / f"{ship}.toml"
    config.write_text(f"[experiment]\nname = 'c'\nmodel = 'hybrid'\nship = '{ship}'\n"
                      f"[data]\nfiles = {json.dumps(files)}\n")
    return load_experiment(config), files


def test_astern_revolutions_under_a_one_quadrant_propeller_warn(tmp_path, dataset_dir, caplog):
    exp, files = _experiment(tmp_path, dataset_dir, "kvlcc2_l7")
    runs = training_runs(exp)
    # the share counted independently, from the files' 1-Hz samples (t = 0, 1, 2 s)
    n = np.concatenate([pd.read_csv(f).dropna()["n_prop [rps]"].to_numpy()[::10] for f in files])
    delta = np.concatenate([pd.read_csv(f).dropna()["delta_rudder [rad]"].to_numpy()[::10] for f in files])
    astern = 100 * np.mean(n < 0)
    beyond = 100 * np.mean(np.abs(delta) > np.radians(35.0) + 1e-9)
    assert 5.0 < astern < 50.0  # the issue: 11-36 % astern in the berthing logs
    with caplog.at_level(logging.WARNING, logger="sysid.runs.lifecycle"):
        found = warn_outside_force_models(exp, runs)
    assert found[0].startswith(f"{astern:.1f} % of the samples have astern revolutions (n_prop < 0)")
    assert "'standard'" in found[0] and "four_quadrant" in found[0]
    if beyond > 0:
        assert any(line.startswith(f"{beyond:.1f} % of the samples have |delta_rudder| beyond 35 deg")
                   for line in found)
    assert [r.getMessage() for r in caplog.records] == [f"training logs: {line} ({exp_ship(exp)})"
                                                        for line in found]


def exp_ship(exp):
    from sysid.hybrid.force_models import build_mmg
    ship = build_mmg(exp).ship
    return ship.source or ship.name


def test_four_quadrant_models_cover_the_same_logs(tmp_path, dataset_dir):
    exp, _ = _experiment(tmp_path, dataset_dir, "esso_osaka")
    assert warn_outside_force_models(exp, training_runs(exp)) == []
