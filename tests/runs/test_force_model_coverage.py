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


def test_a_run_counts_astern_samples_and_windows_per_log(tmp_path, capsys):
    """Logs of the standard-MMG scratch tanker (one-quadrant propeller) with a known astern
    stretch written in: training log zigzag.csv holds n_prop < 0 at t = 50..69 s (20
    samples), the test log random.csv at t = 50..69 s too. A one-epoch hybrid run says the
    count per log in its training output and records it in summary.json: training.split per
    training log (20 and 0 samples, the windows left out by default), data.test per test log
    with its 30-s protocol windows holding one: the windows at 30 s and 60 s (2), not 0 s or 90 s."""
    from sysid.cli import run as sysid
    from scratch_ship import SCRATCH, simulated_logs
    ship_path = tmp_path / "scratch_tanker.toml"
    ship_path.write_text(SCRATCH)
    turn, zigzag, random = simulated_logs(ship_path, tmp_path, {}, seconds=150.0)
    for path in (zigzag, random):
        frame = pd.read_csv(path)
        frame.loc[(frame["t [s]"] >= 50) & (frame["t [s]"] <= 69), "n_prop [rps]"] = -4.0
        frame.to_csv(path, index=False)
    config = tmp_path / "astern.toml"
    config.write_text(
        f"[experiment]\nname = 'astern'\nmodel = 'hybrid'\nship = {json.dumps(str(ship_path))}\nseed = 0\n"
        f"[data]\ntrain = {json.dumps([str(turn), str(zigzag)])}\ntest = {json.dumps([str(random)])}\n"
        "[training]\nepochs = 1\nwarm_start_epochs = 1\nbatch_size = 64\n[evaluation]\nhorizons = [30.0]\n")
    sysid(["train", str(config), "-o", str(tmp_path / "run"), "--threads", "1"])
    said = capsys.readouterr()
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    split = summary["training"]["split"]
    files = {f["file"]: f for f in split["files"]}
    assert files["zigzag"]["astern_samples"] == 20 and files["turn"]["astern_samples"] == 0
    assert files["turn"]["astern_windows"] == 0 and files["zigzag"]["astern_windows"] > 0
    assert split["astern_excluded"] is True and split["astern_windows"] == files["zigzag"]["astern_windows"]
    assert (f"WARNING: {split['astern_windows']} windows hold samples with astern revolutions or going astern, "
            "outside the ship file's one-quadrant propeller model: left out; per log: zigzag "
            f"{files['zigzag']['astern_windows']} windows, 20 samples") in said.out + said.err
    test = summary["data"]["test"][0]
    assert test["astern_samples"] == 20 and test["astern_windows"] == {"30": 2}
    assert "random 2 of the 30-s windows" in said.out + said.err
    train = {f["file"].rsplit("/", 1)[-1]: f for f in summary["data"]["train"]}
    assert train["zigzag.csv"]["astern_samples"] == 20 and train["turn.csv"]["astern_samples"] == 0
    # `sysid evaluate` of the run on the same test log says it too
    sysid(["evaluate", str(tmp_path / "run"), "--data", str(random), "--horizon", "30", "-o",
           str(tmp_path / "metrics.csv")])
    said = capsys.readouterr()
    assert "model of the model's ship file, are scored as they are: random 20 samples, 2 of the 30-s windows" \
        in said.err
