"""Ctrl-C and kill on the installed console script: exit 130 with one line saying what was
kept, no traceback, and nothing half-written that `evaluate` or `report` would accept."""
from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from cli_harness import Outcome, assert_refused, console_script, environment, leftovers, subprocess_run
from sysid.store.manifest import verify_manifest
from tiny_experiment import tiny_config


@pytest.fixture(scope="module")
def files(dataset_dir):
    berthing = dataset_dir / "berthing"
    return {"train": berthing / "berthing_12-Nov-2020_11_07_23.csv",
            "test": berthing / "berthing_12-Nov-2020_11_49_21.csv"}


def _foreground_signals() -> None:
    """In the child: Ctrl-C as a terminal's foreground job gets it. A test run started as a
    background job (``bash .ci/run &``) inherits SIGINT ignored, and Python keeps that."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(*args) -> subprocess.Popen:
    """The console script in its own session, as a terminal's foreground job."""
    return subprocess.Popen([console_script(), *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=environment(), start_new_session=True,
                            preexec_fn=_foreground_signals)


def wait_for(stream, text: str) -> list[str]:
    """Lines of `stream` up to the first holding `text` (fails if the stream ends first)."""
    seen = []
    for line in stream:
        seen.append(line)
        if text in line:
            return seen
    raise AssertionError(f"{text!r} never appeared; output:\n{''.join(seen)}")


def wait_for_each(stream, texts: list[tuple[str, str]]) -> list[str]:
    """Lines of `stream` up to where, for every pair of `texts`, one line has held both of its
    parts (fails if the stream ends first)."""
    seen, missing = [], list(texts)
    for line in stream:
        seen.append(line)
        missing = [pair for pair in missing if not all(part in line for part in pair)]
        if not missing:
            return seen
    raise AssertionError(f"{missing!r} never appeared; output:\n{''.join(seen)}")


def finish(proc: subprocess.Popen, before: list[str], sig: int) -> Outcome:
    os.killpg(proc.pid, sig)  # the whole job, as Ctrl-C in a terminal
    out, err = proc.communicate(timeout=120)
    return Outcome(proc.returncode, "".join(before) + out, err)


def long_training(files, folder):
    config = folder / "long.toml"
    config.write_text(tiny_config(files, training={"epochs": "100000", "warm_start_epochs": "5",
                                                   "patience": "100000", "max_minutes": "10.0"}))
    return config


@pytest.mark.slow
def test_ctrl_c_while_training_exits_130_and_leaves_nothing(files, tmp_path):
    out = tmp_path / "run"
    proc = start("train", long_training(files, tmp_path), "-o", out, "--test", files["test"])
    before = wait_for(proc.stdout, "epoch 10/")  # in the multi-step epochs, checkpointed
    outcome = finish(proc, before, signal.SIGINT)
    line = assert_refused(outcome, 130, "interrupted: nothing written to", str(out), "--resume")
    assert "KeyboardInterrupt" not in outcome.err, line
    assert not out.exists() and leftovers(tmp_path) == [".run.checkpoint.pt"]  # kept for --resume only
    assert_refused(subprocess_run("evaluate", out, "--data", files["test"], "-o", tmp_path / "m.csv"),
                   2, "run directory not found")
    assert_refused(subprocess_run("report", out, "-o", tmp_path / "report"), 2, "no such directory")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["ctrl-c", "kill"])
def test_interrupt_while_writing_the_run_leaves_nothing_evaluate_or_report_accept(files, tmp_path, sig):
    """Stopped right after the gate is fitted (evaluating and writing the run): whatever the
    moment, the run is either complete and verified, or absent; a half-written staging
    directory (a kill skips the clean-up) is refused by evaluate and report."""
    config = tmp_path / "tiny.toml"
    config.write_text(tiny_config(files, evaluation={"horizons": "[10.0, 20.0, 30.0, 50.0]"}))
    out = tmp_path / "run"
    proc = start("train", config, "-o", out, "--test", files["test"])
    before = wait_for(proc.stdout, "kNN gate:")
    outcome = finish(proc, before, sig)
    assert "Traceback" not in outcome.err
    if out.exists():  # finished before the signal arrived: complete
        verify_manifest(out, "run")
    else:
        assert outcome.code in (130, -signal.SIGKILL), outcome.err
    kept = (".run.checkpoint.pt", ".run.lock")  # a kill leaves the lock file, unlocked: the next run takes it
    for half in [tmp_path / name for name in leftovers(tmp_path) if name not in kept]:
        assert sig == signal.SIGKILL and ".staging-" in half.name  # Ctrl-C cleans up after itself
        assert_refused(subprocess_run("evaluate", half, "--data", files["test"], "-o", tmp_path / "m.csv"),
                       2, "incomplete run directory: no manifest.json")
        assert_refused(subprocess_run("report", half, "-o", tmp_path / "report"), 2, "no manifest.json")


def test_ctrl_c_in_a_parallel_preprocess_exits_130_without_worker_tracebacks(tmp_path):
    from preprocessing import synth
    from preprocessing.sensors import SensorLayout
    from analytic_runs import analytic_run

    raw = synth.synthesise(analytic_run(300.0), SensorLayout(), synth.SynthSettings(seed=7)).raw
    logs = []
    for i in range(8):
        logs.append(tmp_path / f"log{i}.csv")
        raw.to_csv(logs[-1], index=False)
    out = tmp_path / "processed"
    proc = start("preprocess", *logs, "-o", out, "--jobs", "2")
    before = wait_for(proc.stderr, "preprocess:")
    outcome = finish(proc, [], signal.SIGINT)
    outcome.err = "".join(before) + outcome.err
    assert_refused(outcome, 130, "interrupted: nothing written to", str(out), absent=(out,))


def test_console_script_exit_codes_for_bad_input_and_unwritable_output(files, tmp_path):
    assert_refused(subprocess_run("forces", tmp_path / "missing.csv", "-o", tmp_path / "f.csv"),
                   2, "missing.csv: file not found")
    assert_refused(subprocess_run("evaluate", "--data", files["test"], "--horizon", "30",
                                  "-o", "/proc/sysid-fuzz/m.csv"), 2, "/proc/sysid-fuzz")


def live_processes(group: int) -> list[str]:
    """Command lines of a process group's processes that are still running (zombies have
    ended)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[2]) == group and fields[0] != "Z":
                found.append((stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode())
        except OSError:  # ended while we looked
            continue
    return found


def group_ended(group: int, wait_s: float = 30.0) -> list[str]:
    """[] once no process of the group runs; else, after `wait_s`, the ones still running.
    (multiprocessing's resource tracker, a helper of the spawned workers, exits on its own
    when sysid has exited: a moment later.)"""
    deadline = time.monotonic() + wait_s
    while live_processes(group) and time.monotonic() < deadline:
        time.sleep(0.1)
    return live_processes(group)


# expected_cost orders them nn_D2, hybrid_D1, nn_D1: two workers take the first two, nn_D1 waits
QUEUED_BEHIND_TWO = ("nn_D2", "hybrid_D1", "nn_D1")


@pytest.mark.slow
@pytest.mark.parametrize("to_group", [True, False], ids=["ctrl-c to the job", "kill -INT to sysid alone"])
def test_ctrl_c_in_a_parallel_reproduce_ends_every_worker(dataset_dir, tmp_path, to_group):
    out = tmp_path / "reproduction"
    only = [arg for name in QUEUED_BEHIND_TWO for arg in ("--only", name)]
    proc = start("reproduce", "-o", out, *only, "--jobs", "2", "--no-report")
    # both workers are training: each has logged its training windows
    before = wait_for_each(proc.stdout, [(f"[{name}] ", " validation windows of ") for name in QUEUED_BEHIND_TWO[:2]])
    if to_group:
        outcome = finish(proc, before, signal.SIGINT)
    else:
        os.kill(proc.pid, signal.SIGINT)
        out_text, err = proc.communicate(timeout=120)
        outcome = Outcome(proc.returncode, "".join(before) + out_text, err)
    assert_refused(outcome, 130, f"interrupted: nothing written to {out}", absent=(out,))
    assert group_ended(proc.pid) == []  # the workers have ended with it
    assert "[nn_D1]" not in outcome.out  # the queued run never started
    assert leftovers(tmp_path) == []


@pytest.mark.slow
def test_ctrl_c_reaches_a_reproduction_started_with_sigint_ignored(dataset_dir, tmp_path):
    """A background job of a non-interactive shell inherits SIGINT ignored; a Ctrl-C that
    reaches sysid still ends it, and nothing is left behind."""
    out = tmp_path / "reproduction"
    proc = subprocess.Popen([console_script(), "reproduce", "-o", str(out), "--only", "mmg_paper", "--only", "nn_D1",
                             "--jobs", "1", "--no-report"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment(), start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    before = wait_for(proc.stdout, "epoch 10/")  # mmg_paper is done (in the staging directory), nn_D1 trains
    outcome = finish(proc, before, signal.SIGINT)
    assert_refused(outcome, 130, f"interrupted: nothing written to {out}", absent=(out,))
    assert group_ended(proc.pid) == [] and leftovers(tmp_path) == []
