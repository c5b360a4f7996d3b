"""Training and sweeps open none of the paper's six test files; evaluation does.

Every file a child process opens is seen by an audit hook on Python's "open" event,
installed by a ``sitecustomize`` module on the child's PYTHONPATH, so it also runs in the
Ray worker processes of a sweep. It records each opened path whose stem is a test file's
(`sysid.data.datasets.TEST_FILES`). The shipped hybrid config is trained with few epochs by
``sysid train``, the shipped gate-space sweep runs two trials beside it, and ``sysid evaluate`` of
the trained run on the test files must show up in its record (else the hook saw nothing).
"""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from sysid.config.experiment import load_experiment
from sysid.data.datasets import TEST_FILES
from sysid.data.splits import PAPER_TEST_STEMS
from tests.support.cli_harness import console_script, environment

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "sysid" / "configs"

HOOK = '''
import os, sys
_STEMS = frozenset(os.environ["SYSID_TEST_STEMS"].split(","))
_RECORD = os.environ["SYSID_OPENED_RECORD"]

def _record(event, args):
    if event != "open" or not args or not isinstance(args[0], (str, bytes, os.PathLike)):
        return
    path = os.fsdecode(args[0])
    stem = os.path.splitext(os.path.basename(path))[0]
    if stem in _STEMS:
        with open(_RECORD, "a") as fh:
            fh.write(f"{os.getpid()} {path}\\n")

sys.addaudithook(_record)
'''


def _child_env(tmp_path: Path, record: Path) -> dict[str, str]:
    hook_dir = tmp_path / "hook"
    hook_dir.mkdir(exist_ok=True)
    (hook_dir / "sitecustomize.py").write_text(HOOK)
    env = environment()
    env["PYTHONPATH"] = os.pathsep.join([str(hook_dir), str(ROOT)] + [p for p in [env.get("PYTHONPATH")] if p])
    env["SYSID_TEST_STEMS"] = ",".join(sorted(PAPER_TEST_STEMS))
    env["SYSID_OPENED_RECORD"] = str(record)
    return env


def _start(env, *args, cwd) -> subprocess.Popen:
    return subprocess.Popen([console_script(), *map(str, args)], env=env, cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _finish(proc: subprocess.Popen) -> str:
    """`proc`'s output, once it has exited with 0."""
    out, err = proc.communicate(timeout=1800)
    assert proc.returncode == 0, f"{' '.join(proc.args)} failed:\n{out}\n{err}"
    return out + err


def _sysid(env, *args, cwd) -> str:
    return _finish(_start(env, *args, cwd=cwd))


def _opened(record: Path) -> set[str]:
    return {Path(line.split(" ", 1)[1]).stem for line in record.read_text().splitlines()} if record.is_file() else set()


@pytest.mark.slow
def test_training_and_sweeps_open_no_test_file_and_evaluation_does(tmp_path, dataset_dir):
    assert len(PAPER_TEST_STEMS) == len(TEST_FILES) == 6
    # the shipped hybrid D2 config, fewer epochs: its data and validation as shipped
    quick = load_experiment(SHIPPED / "experiments" / "hybrid_D2.toml").replace(
        training={"epochs": 1, "warm_start_epochs": 1, "threads": 1})
    base = tmp_path / "hybrid_D2_quick.toml"
    base.write_text(quick.to_toml())
    # the shipped gate-space sweep on that base: two trials (both spaces, one alpha, one seed)
    sweep = (SHIPPED / "sweeps" / "gate_space_D2.toml").read_text()
    for old, new in (('base = "../experiments/hybrid_D2.toml"', f'base = "{base}"'),
                     ("seeds = [0, 1]", "seeds = [0]"),
                     ('"gate.alpha" = [0.999, 0.9995, 0.9999]', '"gate.alpha" = [0.9995]')):
        assert old in sweep
        sweep = sweep.replace(old, new)
    spec = tmp_path / "gate_space_quick.toml"
    spec.write_text(sweep)
    # training and the sweep side by side, each recording what it opens in a file of its own
    records = {what: tmp_path / f"opened_{what}.txt" for what in ("train", "sweep", "evaluate")}
    envs = {what: {**_child_env(tmp_path, record), "SYSID_DATA": str(dataset_dir.parent)}
            for what, record in records.items()}
    sweeping = _start(envs["sweep"], "sweep", spec, "-o", tmp_path / "sweep", "--workers", "1", cwd=tmp_path)
    try:
        _sysid(envs["train"], "train", base, "-o", tmp_path / "run", cwd=tmp_path)
        done = _finish(sweeping)
    finally:
        if sweeping.poll() is None:
            sweeping.kill()
    for what in ("train", "sweep"):
        assert _opened(records[what]) == set(), f"sysid {what} opened test files:\n{records[what].read_text()}"
    results = (tmp_path / "sweep" / "results.csv").read_text()
    assert results.count("complete") == 2, done
    # the trials were validated on held-out training files, named in their summaries
    import json
    summary = json.loads(next((tmp_path / "sweep" / "trials").glob("*/seed0/summary.json")).read_text())
    held = summary["data"]["held_out"]["groups"]
    assert set(held) == {"berthing", "turning", "zigzag", "random"}
    assert not {n for names in held.values() for n in names} & PAPER_TEST_STEMS

    # sanity: the hook sees evaluation open every test file
    tests = [dataset_dir / f for f in TEST_FILES.values()]
    _sysid(envs["evaluate"], "evaluate", tmp_path / "run", "--data", *tests, "--horizon", "30", "-o",
           tmp_path / "m.csv", cwd=tmp_path)
    assert _opened(records["evaluate"]) == PAPER_TEST_STEMS
