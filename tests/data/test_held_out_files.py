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
from sysid.data.splits import PAPER_TEST_STEMS, hold_out_files, maneuver_group


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
