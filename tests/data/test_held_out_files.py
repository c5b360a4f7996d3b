"""``[training] validation = "files"``: whole training logs held out per folder (maneuver
type), `sysid.data.splits.hold_out_files`, on the paper's data sets and on synthetic logs
whose groups and copies are known."""
from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from sysid.data.datasets import training_files
from sysid.data.recordings import Run, read_run
from sysid.data.splits import (PAPER_TEST_STEMS, SHARED_ROWS, TEST, TRAINING, VALIDATION, check_disjoint_runs,
                              hold_out_files, maneuver_group, shared_rows)
from sysid.errors import DataError


def _log(folder: str, name: str, n: int = 50, seed: int = 0, of: Run | None = None) -> Run:
    """A synthetic log of n samples in `folder`; `of`: the first n samples of that log (a copy)."""
    rng = np.random.default_rng(seed)
    states = of.states[:n] if of is not None else rng.normal(size=(n, 6))
    inputs = of.inputs[:n] if of is not None else rng.normal(size=(n, 4))
    return Run(name, Path("/logs") / folder / f"{name}.csv", np.arange(n, dtype=float), states, inputs,
               np.zeros((n, 2)), 1.0)


@pytest.fixture(scope="module")
def paper_runs(dataset_dir):
    return {ds: [read_run(p) for p in training_files(ds, dataset_dir)] for ds in ("D1", "D2")}


def test_each_folder_holds_out_its_share_of_whole_logs_and_copies_follow_their_original(paper_runs):
    runs = paper_runs["D2"]
    split = hold_out_files(runs, 0.3, 0)
    names = {r.name for r in runs}
    train, val = {r.name for r in split.train}, {r.name for r in split.validation}
    assert train | val == names and not train & val and not (names & PAPER_TEST_STEMS)
    originals = {"berthing": 7, "turning": 12, "zigzag": 6, "random": 7}  # turn_cut_..._15_58_08 is a copy
    for group, n in originals.items():
        held = [r for r in split.validation if maneuver_group(r) == group and not r.name.startswith("turn_cut")]
        assert len(held) == round(0.3 * n), group       # 2, 4, 2, 2 of 7, 12, 6, 7
        assert any(maneuver_group(r) == group for r in split.train)
    # the copy of the start of turn_14-Sep-2020_15_58_08 is on its original's side
    side = {r.name: r in split.validation for r in runs}
    assert side["turn_cut_14-Sep-2020_15_58_08"] == side["turn_14-Sep-2020_15_58_08"]
    assert split.groups == {g: sorted(r.name for r in split.validation if maneuver_group(r) == g)
                            for g in originals}


def test_the_draw_depends_on_split_seed_only(paper_runs):
    d1, d2 = paper_runs["D1"], paper_runs["D2"]
    first = hold_out_files(d2, 0.3, 0)
    shuffled = list(d2)
    random.Random(3).shuffle(shuffled)
    assert hold_out_files(shuffled, 0.3, 0).groups == first.groups
    # D1 is D2 without its random logs: the same berthing, turning and zigzag logs held out
    assert hold_out_files(d1, 0.3, 0).groups == {g: v for g, v in first.groups.items() if g != "random"}
    assert hold_out_files(d2, 0.3, 1).groups != first.groups
    # the training part keeps the order of the logs given
    assert [r.name for r in first.train] == [r.name for r in d2 if r in first.train]


def test_small_groups_never_go_to_validation_whole():
    alone = _log("alone", "a0", seed=1)
    pair = [_log("pair", f"p{i}", seed=10 + i) for i in range(2)]
    many = [_log("many", f"m{i}", seed=20 + i) for i in range(10)]
    copy = _log("many", "m_cut", n=30, of=many[4])
    for fraction in (0.05, 0.3, 0.95):
        split = hold_out_files([alone, *pair, *many, copy], fraction, 7)
        held = split.groups
        assert "alone" not in held                       # one log: stays training
        assert len(held["pair"]) == 1                    # at least one, never both
        expected = min(9, max(1, int(np.floor(fraction * 10 + 0.5))))
        assert len([n for n in held["many"] if n != "m_cut"]) == expected
        assert ("m_cut" in held["many"]) == ("m4" in held["many"])


def _piece(of: Run, name: str, rows: slice, scale: float = 1.0) -> Run:
    """Rows `rows` of `of` as a log of its own (`scale`: its values in another unit and back)."""
    return Run(name, Path("/logs/cut") / f"{name}.csv", of.t[rows], of.states[rows] * scale / scale,
               of.inputs[rows] * scale / scale, of.relative_wind[rows], of.dt)


@pytest.mark.parametrize("rows, at", [(slice(300, None), (0, 300, 200)), (slice(120, 180), (0, 120, 60)),
                                      (slice(480, 495), (0, 480, 15))])
def test_a_log_cut_from_another_shares_exactly_its_rows(rows, at):
    whole = _log("many", "whole", n=500, seed=3)
    cut = _piece(whole, "cut", rows, scale=0.514444)   # through knots and back: rounding at 1e-16
    assert shared_rows(cut, whole) == at
    assert shared_rows(whole, cut) == (at[1], at[0], at[2])
    with pytest.raises(DataError, match=rf"cut\.csv \(test\) holds the samples of rows {at[1] + 1}-{at[1] + at[2]} "
                                        r"of /logs/many/whole\.csv \(training\)"):
        check_disjoint_runs({TRAINING: [_log("many", "other", n=400, seed=4), whole], TEST: [cut]})


def test_logs_that_share_a_stretch_are_refused_and_recordings_that_do_not_pass():
    a, b = _log("many", "a", n=400, seed=5), _log("many", "b", n=400, seed=6)
    # b's rows 100-159 recorded again in the middle of another log: 60 samples in common
    spliced = Run("spliced", Path("/logs/cut/spliced.csv"), np.arange(300.0),
                  np.concatenate([a.states[:120], b.states[100:160], a.states[200:320]]),
                  np.concatenate([a.inputs[:120], b.inputs[100:160], a.inputs[200:320]]), np.zeros((300, 2)), 1.0)
    assert shared_rows(spliced, b) == (120, 100, 60)
    with pytest.raises(DataError, match=r"spliced\.csv \(validation\) holds in its rows 121-180 the samples of rows "
                                        r"101-160 of /logs/many/b\.csv \(training\)"):
        check_disjoint_runs({TRAINING: [b], VALIDATION: [spliced]})
    # fewer rows in common than SHARED_ROWS, neither log whole: two recordings, not one
    short = Run("short", Path("/logs/cut/short.csv"), np.arange(200.0),
                np.concatenate([a.states[:100], b.states[:SHARED_ROWS - 1], a.states[300:371]]),
                np.concatenate([a.inputs[:100], b.inputs[:SHARED_ROWS - 1], a.inputs[300:371]]), np.zeros((200, 2)), 1.0)
    assert shared_rows(short, b) is None
    check_disjoint_runs({TRAINING: [a, b], TEST: [_log("many", "c", n=400, seed=7)]})
    check_disjoint_runs({TRAINING: [a, a], TEST: [b]})  # one part may hold a log twice (its copies drop out later)
