"""The maneuver recogniser against independent truth: every processed FRT-DS-ESSO log is
recognised as the maneuver of the folder the experimenters filed it in, the paper's six test
files get the paper's scenario names (rudder angle of a turn, A/B of a zig-zag) from their
signals alone, and a user's copy (renamed columns, knots and degrees, another folder) gets
the same; an analytic straight run and a short log named by its folder."""
from __future__ import annotations

import math
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


def _nomoto(delta_deg: np.ndarray, k_per_s: float = 0.2, t_s: float = 10.0) -> np.ndarray:
    """Heading [rad] (N,) at 1 Hz of the first-order Nomoto ship T r' + r = K delta under the
    rudder `delta_deg` [deg] (N,), from rest on course 0 (explicit Euler, dt = 1 s)."""
    r, psi = 0.0, [0.0]
    for d in np.radians(delta_deg[:-1]):
        r += (k_per_s * d - r) / t_s
        psi.append(psi[-1] + r)
    return np.asarray(psi)


def _zigzag_rudder(amplitude_deg: float, seconds: int, k_per_s: float = 0.2, t_s: float = 10.0) -> np.ndarray:
    """The closed-loop zig-zag A/A rudder [deg] of the `_nomoto` ship: reversed when the heading
    passes A on the side the rudder turns to, moved at most 5 deg per second."""
    delta, side, r, psi, rudder = 0.0, 1.0, 0.0, 0.0, []
    for _ in range(seconds):
        if side * math.degrees(psi) >= amplitude_deg:
            side = -side
        delta += float(np.clip(side * amplitude_deg - delta, -5.0, 5.0))
        rudder.append(delta)
        r += (k_per_s * math.radians(delta) - r) / t_s
        psi += r
    return np.asarray(rudder)


def test_a_meandering_run_that_turns_through_270_deg_or_swings_side_to_side_is_random():
    """A rudder drawn at random every 5-15 s from +-30 deg (a meandering run) neither holds its
    angle nor keeps to one side: random, though the Nomoto ship it steers turns through more
    than 270 deg net in one run and swings side to side in the other. The same ship on a
    held 35 deg rudder is a 35 deg turn, on a closed-loop 20/20 zig-zag a 20/20 zig-zag."""
    t = np.arange(600.0)
    n = np.full_like(t, 10.0)
    found = {}
    for seed in range(12):
        rng = np.random.default_rng(seed)
        plan = np.concatenate([[rng.uniform(-30, 30)] * int(rng.integers(5, 15)) for _ in range(120)])[:600]
        psi = _nomoto(plan)
        turned = abs(math.degrees(psi[-1]))
        run = _run("meander", t, psi, np.radians(plan), n, "/logs/meander.csv")
        found.setdefault("turns" if turned >= 270 else "keeps course" if turned < 90 else "other",
                         []).append(recognise(run).kind)
    assert len(found["turns"]) >= 1 and len(found["keeps course"]) >= 1
    assert set(found["turns"]) | set(found["keeps course"]) == {Maneuver.RANDOM}

    held = np.minimum(5.0 * t, 35.0)                 # 35 deg to starboard at 5 deg/s, held
    turn = recognise(_run("turn", t, _nomoto(held), np.radians(held), n, "/logs/turn.csv"))
    assert (turn.kind, turn.rudder_deg) == (Maneuver.TURNING, 35.0)
    rudder = _zigzag_rudder(20.0, 600)
    zigzag = recognise(_run("zz", t, _nomoto(rudder), np.radians(rudder), n, "/logs/zz.csv"))
    assert (zigzag.kind, zigzag.rudder_deg, zigzag.heading_deg) == (Maneuver.ZIGZAG, 20.0, 20.0)
