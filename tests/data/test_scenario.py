"""The maneuver recogniser against independent truth: every processed FRT-DS-ESSO log is
recognised as the maneuver of the folder the experimenters filed it in, the paper's six test
files get the paper's scenario names (rudder angle of a turn, A/B of a zig-zag) from their
signals alone, and a user's copy (renamed columns, knots and degrees, another folder) gets
the same; an analytic straight run and a short log named by its folder."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sysid.config.experiment import load_experiment
from sysid.data.datasets import TEST_FILES
from sysid.data.recordings import Run, read_run
from sysid.data.scenario import Maneuver, recognise, scenario_of
from sysid.runs.lifecycle import training_runs
from own_logs import columns_table, write_own_log


@pytest.fixture(scope="module")
def every_log(dataset_dir):
    return {path: read_run(path) for path in sorted(dataset_dir.glob("*/*.csv"))}


def test_every_real_log_is_recognised_as_the_maneuver_of_its_folder(every_log):
    assert len(every_log) == 39
    folder_kind = {"berthing": Maneuver.BERTHING, "turning": Maneuver.TURNING, "zigzag": Maneuver.ZIGZAG,
                   "random": Maneuver.RANDOM}
    wrong = {p.name: recognise(r).name for p, r in every_log.items() if recognise(r).kind is not folder_kind[p.parent.name]}
    assert wrong == {}
    assert all(recognise(r).source == "signals" for r in every_log.values())


def test_the_paper_test_files_get_the_paper_scenario_names_from_their_signals(dataset_dir, every_log):
    names = {scenario: recognise(every_log[dataset_dir / file]).name for scenario, file in TEST_FILES.items()}
    assert names == {s: s for s in TEST_FILES}   # "Turning 20", "Zigzag 30/30", ...
    zigzag = recognise(every_log[dataset_dir / TEST_FILES["Zigzag 30/30"]])
    assert (zigzag.rudder_deg, zigzag.heading_deg) == (30.0, 30.0)


def test_the_same_at_the_files_own_10_hz(dataset_dir):
    for scenario, file in TEST_FILES.items():
        assert recognise(read_run(dataset_dir / file, rate=10.0)).name == scenario


def test_a_users_renamed_copy_in_knots_and_degrees_is_recognised_alike(dataset_dir, tmp_path):
    folder = tmp_path / "trials_2024"
    folder.mkdir()
    logs = {s: write_own_log(dataset_dir / f, folder / f"log_{i}.csv") for i, (s, f) in enumerate(TEST_FILES.items())}
    config = tmp_path / "exp.toml"
    config.write_text("[experiment]\nmodel = 'hybrid'\n[data]\ntrain = [" +
                      ", ".join(f"'{p}'" for p in logs.values()) + "]\n" + columns_table())
    runs = training_runs(load_experiment(config))
    assert {r.name: scenario_of(r) for r in runs} == {p.stem: s for s, p in logs.items()}


def _run(name: str, t: np.ndarray, psi: np.ndarray, delta: np.ndarray, n: np.ndarray, path: str) -> Run:
    states = np.zeros((len(t), 6))
    states[:, 1], states[:, 4] = 1.0, psi
    inputs = np.zeros((len(t), 4))
    inputs[:, 0], inputs[:, 1] = n, delta
    return Run(name, Path(path), t, states, inputs, np.zeros((len(t), 2)), 1.0)


def test_a_straight_run_and_a_short_log_named_by_its_folder():
    t = np.arange(600.0)
    straight = _run("a", t, np.radians(0.01 * t), np.radians(2.0 * np.sin(t / 30)), np.full_like(t, 10.0),
                    "/logs/a.csv")
    assert recognise(straight).kind is Maneuver.STRAIGHT and scenario_of(straight) == "Straight"
    short = _run("b", t[:20], np.zeros(20), np.zeros(20), np.full(20, 10.0), "/logs/zigzag/b.csv")
    assert recognise(short).kind is Maneuver.ZIGZAG and recognise(short).source == "folder"


def test_a_recorded_maneuver_in_no_named_folder_is_recognised_from_its_signals(dataset_dir, tmp_path):
    """`sysid maneuver` on a user's recorded runs named log_*.csv in a folder that names no
    maneuver: the turn and the zig-zag (with its 20/20 angles) come from the signals, as the
    paper names these test files."""
    from sysid.maneuvers.base import TurningCircle, ZigZag
    from sysid.maneuvers.recorded import recorded_maneuver

    zigzag = read_run(dataset_dir / TEST_FILES["Zigzag 20/20"])
    turn = read_run(dataset_dir / TEST_FILES["Turning 35"])
    moved = {"log_1": zigzag, "log_2": turn}
    runs = {n: Run(n, tmp_path / "trials" / f"{n}.csv", r.t, r.states, r.inputs, r.relative_wind, r.dt)
            for n, r in moved.items()}
    maneuver, _ = recorded_maneuver(runs["log_1"])
    assert isinstance(maneuver, ZigZag) and (maneuver.rudder_deg, maneuver.check_deg) == (20.0, 20.0)
    maneuver, _ = recorded_maneuver(runs["log_2"])
    assert isinstance(maneuver, TurningCircle) and maneuver.rudder_deg == 35.0
