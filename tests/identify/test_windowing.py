"""Every validation window keeps the log and time it was cut from (`cut_windows`,
`WindowOrigins`): checked on real logs against the logs themselves, for validation blocks of
training logs and for held-out validation logs."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from sysid.data.recordings import read_run
from sysid.identify.windowing import cut_windows, split_windows

BERTHING = ("berthing_12-Nov-2020_11_07_23.csv", "berthing_12-Nov-2020_11_14_47.csv",
            "berthing_12-Nov-2020_11_38_50.csv")


@pytest.fixture(scope="module")
def runs(dataset_dir):
    return [read_run(dataset_dir / "berthing" / name) for name in BERTHING]


def check_origins(cut, runs) -> None:
    """Each validation window's first state is its log's sample at its start time, the
    windows follow the files' order, and each log has the report's count."""
    by_name = {r.name: r for r in runs}
    o = cut.val_origins
    assert len(o) == len(cut.val)
    for w, (log, start) in enumerate(zip(o.logs, o.start_s)):
        run = by_name[log]
        i = int(np.flatnonzero(run.t == start)[0])
        np.testing.assert_array_equal(cut.val.states[:, w].numpy(), run.states[i:i + cut.val.states.shape[0]])
    counts = {f["file"]: f["val_windows"] for f in cut.report.files if f["val_windows"]}
    assert {log: idx.size for log, idx in o.by_log().items()} == counts
    assert list(o.by_log()) == list(counts)                          # the files' order
    for idx in o.by_log().values():
        assert np.all(np.diff(o.start_s[idx]) > 0)                   # each log's in time order


def test_validation_blocks_keep_their_training_log_and_time(runs):
    cut = cut_windows(runs, 10, 2.0, 0.3, True, torch.float64, 30.0, 0)
    check_origins(cut, runs)
    assert len(cut.val_origins.by_log()) == 3                       # every log has validation blocks
    # split_windows is the same cut, without the origins
    train, val, samples, report = split_windows(runs, 10, 2.0, 0.3, True, torch.float64, 30.0, 0)
    assert torch.equal(val.states, cut.val.states) and torch.equal(train.states, cut.train.states)
    assert report.files == cut.report.files


def test_held_out_logs_are_the_origins_of_their_windows(runs):
    cut = cut_windows(runs[:2], 29, 2.0, 0.3, True, torch.float64, 30.0, 0, validation_runs=runs[2:])
    check_origins(cut, runs)
    assert set(cut.val_origins.logs) == {runs[2].name}


@pytest.mark.parametrize("held_out", [False, True])
def test_the_verdicts_windows_are_each_logs_non_overlapping_ones(runs, held_out):
    """`WindowOrigins.non_overlapping` at 30 s on real validation windows slid by 2 s (training
    logs' blocks, or a held-out log's 30-s windows: 30 samples of 1 s, as a test window): kept
    starts lie at least 30 s apart, and every window left out starts within 30 s after a kept
    one (greedy from each log's first)."""
    if held_out:
        cut = cut_windows(runs[:2], 29, 2.0, 0.3, True, torch.float64, 30.0, 0, validation_runs=runs[2:])
    else:
        cut = cut_windows(runs, 10, 2.0, 0.3, True, torch.float64, 30.0, 0)
    o = cut.val_origins
    kept = o.non_overlapping(30.0)
    assert list(kept) == list(o.by_log())
    for log, index in o.by_log().items():
        starts, judged = o.start_s[index], o.start_s[kept[log]]
        assert judged[0] == starts.min() and np.all(np.diff(judged) >= 30.0 - 1e-6)
        assert set(judged) <= set(starts)
        for s in set(starts) - set(judged):
            assert np.any((judged <= s) & (s < judged + 30.0 - 1e-6)), (log, s)
    if held_out:   # one log, no gap: every 15th window, 30 s apart
        (log, index), = o.by_log().items()
        assert np.allclose(o.start_s[kept[log]], o.start_s[index][::15])
        assert kept[log].size == -(-index.size // 15)


def test_two_logs_of_one_name_are_refused_before_their_windows_merge(runs, dataset_dir, tmp_path):
    """Two different logs named "log" (a/log.csv, b/log.csv): their validation windows would
    be one log's in the verdict (one cell, the second's windows at the first's times dropped as
    overlapping). Refused with one line naming both files, whether read together or one held
    out for validation; the same file given twice is named as such."""
    import shutil

    from sysid.data.recordings import read_runs
    from sysid.errors import DataError

    for folder, name in zip("ab", BERTHING[:2]):
        (tmp_path / folder).mkdir()
        shutil.copy(dataset_dir / "berthing" / name, tmp_path / folder / "log.csv")
    a, b = tmp_path / "a" / "log.csv", tmp_path / "b" / "log.csv"
    with pytest.raises(DataError, match=rf"^{b}: the same name as {a}; sysid names a log by its file name "
                                        r"\('log'\): rename one of them$"):
        read_runs([a, b])
    with pytest.raises(DataError, match=rf"^{a}: given twice; .* give it once$"):
        read_runs([a, a])
    first, second = read_run(a), read_run(b)
    with pytest.raises(DataError, match=rf"^{b}: the same name as {a} among the training and validation logs"):
        cut_windows([first, runs[2]], 10, 2.0, 0.3, True, torch.float64, 30.0, 0, validation_runs=[second])


def test_one_log_for_training_and_validation_is_refused(runs, dataset_dir):
    """The same file read as a training log and as a held-out validation log: named as given
    twice (its validation windows would score what it trained)."""
    from sysid.errors import DataError

    again = read_run(dataset_dir / "berthing" / BERTHING[0])
    with pytest.raises(DataError, match=rf"{BERTHING[0]}: given twice among the training and validation logs"):
        cut_windows(runs[:2], 10, 2.0, 0.3, True, torch.float64, 30.0, 0, validation_runs=[again])


STANDARD = (("hull", "standard"), ("propeller", "standard"), ("rudder", "standard"))


def _astern_in(windows) -> np.ndarray:
    """(W,) True for the windows holding a sample with n_prop < 0 or u < 0, read off their tensors."""
    return ((windows.inputs[..., 0] < 0) | (windows.states[..., 1] < 0)).any(dim=0).numpy()


def test_astern_windows_under_a_one_quadrant_propeller_are_counted_and_left_out(runs):
    """The real berthing logs (astern revolutions) cut for a one-quadrant propeller: kept, the
    windows are those of a four-quadrant cut and the report counts exactly the windows whose
    own samples go astern; left out (the default), no training or validation window and no
    training sample goes astern, and every other window is kept."""
    from sysid.identify.windowing import AsternSamples
    plain = cut_windows(runs, 5, 2.0, 0.3, True, torch.float64, 30.0, 0)
    assert plain.report.astern_windows is None and "astern_samples" not in plain.report.files[0]
    kept = cut_windows(runs, 5, 2.0, 0.3, True, torch.float64, 30.0, 0, astern=AsternSamples(STANDARD, False))
    torch.testing.assert_close(kept.train.states, plain.train.states, rtol=0, atol=0)
    torch.testing.assert_close(kept.val.inputs, plain.val.inputs, rtol=0, atol=0)
    outside = int(_astern_in(plain.train).sum() + _astern_in(plain.val).sum())
    assert outside > 50 and kept.report.astern_windows == outside and kept.report.astern_excluded is False
    for entry, run in zip(kept.report.files, runs):
        assert entry["astern_samples"] == int(((run.inputs[:, 0] < 0) | (run.states[:, 1] < 0)).sum()) > 0
    assert sum(f["astern_windows"] for f in kept.report.files) == outside

    left = cut_windows(runs, 5, 2.0, 0.3, True, torch.float64, 30.0, 0, astern=AsternSamples(STANDARD))
    assert left.report.astern_windows == outside and left.report.astern_excluded is True
    assert not _astern_in(left.train).any() and not _astern_in(left.val).any()
    assert len(left.train) + len(left.val) == len(plain.train) + len(plain.val) - outside
    states, inputs = left.samples
    assert not ((inputs[:, 0] < 0) | (states[:, 1] < 0)).any() and len(states) < len(plain.samples[0])
