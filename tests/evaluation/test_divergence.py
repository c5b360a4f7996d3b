"""Divergence is a named outcome: the rule on constructed predictions, and the issue's diverging
identified MMG (N_r and Y_r at a learning rate of 3 for 3 epochs, two test logs) trained on the
real logs: its rows stay in metrics.csv marked ``diverged`` with the time, the verdict is
DIVERGED on the test logs (never "there is no test set") and names log, horizon and time."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd

from cli_harness import in_process
from sysid.evaluation.divergence import PhysicalRange, diverged_windows
from sysid.evaluation.judgement import Outcome
from sysid.evaluation.verdict import SHIP_FILE_MMG, BaselineVerdict

TRAIN = ("berthing/berthing_12-Nov-2020_13_37_05.csv", "berthing/berthing_12-Nov-2020_13_09_11.csv")
TESTS = ("zigzag/zigzag_31-Jul-2020_13_57_45.csv", "turning/turn_14-Oct-2020_14_56_07.csv")


def states(H: int, W: int, u=0.5, r=0.01) -> np.ndarray:
    x = np.zeros((H, W, 6))
    x[..., 1], x[..., 5] = u, r
    return x


def test_the_rule_names_the_first_non_finite_or_far_out_state():
    t = 100.0 + np.arange(10)[:, None] + 10.0 * np.arange(3)[None, :]     # (H, W) log time [s]
    limits = PhysicalRange(speed=1.0, yaw_rate=0.05)
    pred = states(10, 3)
    flags, where = diverged_windows(pred, t, "log", 30.0, limits, states(10, 3))
    assert not flags.any() and where is None
    pred[6, 2, 3] = np.nan                      # v_m of window 2 at t = 126 s
    pred[7, 1, 5] = 0.16                        # r of window 1 at t = 117 s: beyond 3 x 0.05
    flags, where = diverged_windows(pred, t, "log", 30.0, limits, states(10, 3))
    assert flags.tolist() == [False, True, True]
    assert (where.log, where.horizon_s, where.time_s, where.channel) == ("log", 30.0, 117.0, "r")
    assert "|r| 0.16 rad/s, beyond 3 x" in where.reason and "0.05 rad/s" in where.reason
    # a record as fast as the prediction widens the range: 0.16 rad/s recorded is no divergence
    flags, where = diverged_windows(pred, t, "log", 30.0, limits, states(10, 3, r=0.16))
    assert flags.tolist() == [False, False, True] and where.time_s == 126.0 and where.reason == "non-finite"
    # no training range (an MMG used as defined): only non-finite states count
    pred[:, 0, 1] = 40.0
    assert diverged_windows(pred, t, "log", 30.0, None)[0].tolist() == [False, False, True]
    assert diverged_windows(pred, t, "log", 30.0, limits)[0].tolist() == [True, True, True]


def test_the_diverging_identified_mmg_is_named_and_kept(dataset_dir, tmp_path, capsys):
    config = tmp_path / "diverging.toml"
    config.write_text(
        "[experiment]\nname = 'diverging'\nmodel = 'mmg'\nseed = 0\nship = 'esso_osaka'\n"
        f"[data]\ntrain = {json.dumps([str(dataset_dir / f) for f in TRAIN])}\n"
        f"test = {json.dumps([str(dataset_dir / f) for f in TESTS])}\n"
        "[identify]\nparameters = ['N_r', 'Y_r']\nbounds = { N_r = [-1.0, 5.0], Y_r = [-1.0, 5.0] }\n"
        "epochs = 3\nlearning_rate = 3.0\n[evaluation]\nhorizons = [30.0]\n")
    run = tmp_path / "run"
    trained = in_process(capsys, "train", config, "-o", run)
    assert trained.code == 0, trained.err
    metrics = pd.read_csv(run / "metrics.csv")
    assert len(metrics) == 2 and metrics["diverged"].all()          # both rows kept, both marked
    assert metrics["rmse_u"].isna().all() and (metrics["n_windows"] == [3, 10]).all()
    assert (metrics["diverged_at_s"] > 0).all()
    summary = json.loads((run / "summary.json").read_text())
    assert summary["beats_baseline"] is False and summary["verdict"]["outcome"] == "diverged"
    verdict = BaselineVerdict.from_dict(summary["verdict"])
    assert verdict.decided_on == "test" and verdict.outcome is Outcome.DIVERGED
    judgement = verdict.judgements[SHIP_FILE_MMG]
    assert (judgement.n_logs, judgement.n_windows) == (2, 13)
    assert {d.log for d in judgement.divergences} == {"zigzag_31-Jul-2020_13_57_45", "turn_14-Oct-2020_14_56_07"}
    first = {d.log: d.time_s for d in judgement.divergences}
    assert first == dict(zip(metrics["file"], metrics["diverged_at_s"]))
    warning = trained.err.strip().splitlines()[-1]
    assert warning.startswith("WARNING: The identified MMG DIVERGED")
    for d in judgement.divergences:
        assert f"{d.log} at 30 s, t = {d.time_s:g} s" in warning
    assert "no test" not in warning and "Decided on the test logs at 30 s." in warning
    assert (trained.out + trained.err).count("WARNING: the prediction diverged on") == 2   # as it happens
    # the run keeps its training range; sysid evaluate RUN judges divergence against it
    from sysid.data.recordings import read_runs
    from sysid.records.summary import RunSummary
    kept = PhysicalRange.of_summary(RunSummary.from_json(summary, "summary.json"))
    assert kept == PhysicalRange.of_runs(read_runs([dataset_dir / f for f in TRAIN], 1.0))
    evaluated = in_process(capsys, "evaluate", run, "-o", tmp_path / "again.csv")
    assert evaluated.code == 0, evaluated.err
    assert (f"divergence: a non-finite state, or speed or |r| beyond 3 x the run's training range "
            f"({kept.speed:.3g} m/s, {kept.yaw_rate:.3g} rad/s") in evaluated.out
    assert evaluated.err.count("WARNING: the prediction diverged on") == 2
    assert pd.read_csv(tmp_path / "again.csv")["diverged"].all()


def test_a_summary_without_a_training_range_gives_none():
    from sysid.records.summary import RunSummary
    assert PhysicalRange.of_summary(RunSummary.from_json({"name": "old"}, "summary.json")) is None
    kept = RunSummary.from_json({"name": "new", "training_range": PhysicalRange(1.5, 0.02).to_dict()}, "summary.json")
    assert PhysicalRange.of_summary(kept) == PhysicalRange(1.5, 0.02)
