"""`sysid.workers.in_workers`: Ctrl-C or an error in one worker ends every worker before the
call returns, and work not yet started never starts."""
from __future__ import annotations

import functools
import os
import signal
import threading
import time
from pathlib import Path

import pytest

from sysid.workers import in_workers


def _started(folder: Path, item: str) -> str:
    """Work that says it started (a file named by its pid), then waits far longer than a test."""
    (folder / f"{item}.{os.getpid()}").touch()
    if item == "fails":
        while not list(folder.glob("sleeps.*")):  # fail only once the other one works
            time.sleep(0.05)
        raise ValueError("bad item")
    time.sleep(600)
    return item


def _ended(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:  # exited and reaped
        return True
    return False


def _when(condition, then) -> threading.Thread:
    def watch():
        while not condition():
            time.sleep(0.05)
        then()
    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def test_ctrl_c_ends_every_worker_and_starts_no_more_work(tmp_path):
    work = functools.partial(_started, tmp_path)
    before = signal.getsignal(signal.SIGINT)
    _when(lambda: len(list(tmp_path.iterdir())) == 2, lambda: os.kill(os.getpid(), signal.SIGINT))
    with pytest.raises(KeyboardInterrupt):
        in_workers(work, ["a", "b", "c"], 2)
    started = sorted(tmp_path.iterdir())
    assert [p.name.split(".")[0] for p in started] == ["a", "b"]  # c was waiting: it never ran
    assert all(_ended(int(p.suffix[1:])) for p in started)
    assert signal.getsignal(signal.SIGINT) is before  # put back


def test_an_error_in_one_worker_ends_the_others(tmp_path):
    work = functools.partial(_started, tmp_path)
    with pytest.raises(ValueError, match="bad item"):
        in_workers(work, ["sleeps", "fails"], 2)
    sleeper = [p for p in tmp_path.iterdir() if p.name.startswith("sleeps.")]
    assert len(sleeper) == 1 and all(_ended(int(p.suffix[1:])) for p in sleeper)


def test_results_arrive_each_once(tmp_path):
    seen = []
    assert sorted(in_workers(abs, [-3, 1, -2], 2, on_result=seen.append)) == [1, 2, 3]
    assert sorted(seen) == [1, 2, 3]


def _after(folder: Path, item: str) -> str:
    """Work that leaves a file named by its item, then returns it in capitals."""
    (folder / item).touch()
    return item.upper()


def test_overlap_starts_work_only_on_allowed_slots_and_takes_follow_ups(tmp_path):
    from sysid.workers import Overlap

    work = functools.partial(_after, tmp_path)
    with Overlap(work, 2, on_result=lambda key, result: key == "a" and pool.add("a2", "a2")) as pool:
        pool.add("a", "a")
        pool.add("b", "b")
        time.sleep(0.5)
        pool.poll()
        assert not list(tmp_path.iterdir()) and not pool.running  # no slot allowed: nothing started
        pool.allow(1)
        assert len(pool.running) == 1 and pool.queued == [("b", "b", False)]
        pool.allow(2)
        while not all(f.done() for f in pool.running):
            time.sleep(0.05)
        pool.poll()  # a and b collected in one poll, a's result adding a2 on the way
        results = pool.finish()
    assert results == {"a": "A", "b": "B", "a2": "A2"}  # a2 added when a's result came
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "a2", "b"]


def test_overlap_items_queued_first_start_first_in_their_order(tmp_path):
    from sysid.workers import Overlap

    with Overlap(functools.partial(_after, tmp_path), 1) as pool:
        for key, first in (("a", False), ("b", False), ("c", True), ("d", True), ("e", False)):
            pool.add(key, key, first=first)
        assert [q[0] for q in pool.queued] == ["c", "d", "a", "b", "e"]
        pool.allow(1)
        assert list(pool.running.values()) == ["c"] and not (tmp_path / "a").exists()
        assert pool.finish() == {k: k.upper() for k in "abcde"}


def test_overlap_error_ends_every_worker(tmp_path):
    from sysid.workers import Overlap

    work = functools.partial(_started, tmp_path)
    with pytest.raises(ValueError, match="bad item"):
        with Overlap(work, 2) as pool:
            pool.add("sleeps", "sleeps")
            pool.add("fails", "fails")
            pool.add("never", "never")
            pool.finish()
    started = sorted(p.name.split(".")[0] for p in tmp_path.iterdir())
    assert started == ["fails", "sleeps"]  # the third was queued behind them: it never ran
    assert all(_ended(int(p.suffix[1:])) for p in tmp_path.iterdir())
