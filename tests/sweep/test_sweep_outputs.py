"""Where a sweep may write, checked before Ray starts (issue 36): a sweep name is one safe
path component; ``--storage`` follows the rules of ``-o`` (never the sweep's logs or their
folder) and a URI of no known scheme is one line; ``--address auto`` joins only a cluster
``ray start`` started, never another sweep's private Ray; a cluster whose head goes away
mid-sweep is one line, with no lock file left and nothing half-written."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from own_sweep import SYSID, no_paper_data, own_sweep_project
from sysid.errors import ConfigError, OutputError
from sysid.sweep import load_sweep
from sysid.sweep.connect import RayTarget, resolved
from tiny_experiment import tiny_experiment


@pytest.mark.parametrize("name", ["../escaped_sweep", "a/b", ".hidden", "..", "", "x\\\\y", "sweep\\u00e9"])
def test_a_sweep_name_that_is_not_one_safe_path_component_is_refused(tmp_path, dataset_dir, name):
    tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=1, warm_start_epochs=1)
    path = tmp_path / "s.toml"
    path.write_text(f"[sweep]\nname = \"{name}\"\nbase = 'base.toml'\n")
    with pytest.raises(ConfigError) as err:
        load_sweep(path)
    assert str(err.value).startswith(f"{path}: [sweep] name = ") and "\n" not in str(err.value)


def test_a_default_name_from_the_file_name_is_made_safe(tmp_path, dataset_dir):
    tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=1, warm_start_epochs=1)
    path = tmp_path / "my sweep (v2).toml"
    path.write_text("[sweep]\nbase = 'base.toml'\n")
    assert load_sweep(path).name == "my_sweep__v2_"


@pytest.fixture
def project(tmp_path, dataset_dir):
    return own_sweep_project(tmp_path / "project", dataset_dir, logs_folder="logs", name="logs")


def _refused(sweep: Path, out: Path, *options: str) -> str:
    """Run the sweep in this process; its error line (it must fail before Ray starts)."""
    import ray

    from sysid.cli import run
    from sysid.cli.outputs import release
    with pytest.raises((OutputError, ConfigError)) as err:
        run(["sweep", str(sweep), "-o", str(out), *options])
    release()
    assert not ray.is_initialized()
    assert not out.exists() and not (out.parent / f".{out.name}.lock").exists()
    return str(err.value)


def test_storage_onto_the_sweeps_own_logs_folder_is_refused(project):
    logs = project.parent / "logs"
    before = sorted(p.name for p in logs.iterdir())
    # Tune's experiment would be {storage}/{name} = the logs folder itself
    line = _refused(project, project.parent / "out", "--storage", str(project.parent))
    assert line.startswith(f"--storage {project.parent}: {logs}: is {logs}, an input of this command")
    # or a folder inside it
    line = _refused(project, project.parent / "out", "--storage", str(logs))
    assert line.startswith(f"--storage {logs}: {logs / 'logs'}: lies inside {logs}, an input")
    assert sorted(p.name for p in logs.iterdir()) == before


def test_storage_of_an_unknown_scheme_is_one_line_before_ray_starts(project):
    line = _refused(project, project.parent / "out", "--storage", "nosuch://bucket/dir")
    assert line.startswith("--storage 'nosuch://bucket/dir': not a folder or a storage URI") and "\n" not in line


def test_auto_resolves_only_to_a_cluster_ray_start_recorded(monkeypatch):
    import sysid.sweep.connect as connect
    monkeypatch.setattr(connect, "running_cluster", lambda: None)
    with pytest.raises(ConfigError, match=r"^--address auto: no Ray cluster started with `ray start` runs"):
        resolved(RayTarget("auto", "--address"))
    monkeypatch.setattr(connect, "running_cluster", lambda: "10.0.0.5:6379")
    assert resolved(RayTarget("auto", "RAY_ADDRESS")) == RayTarget("10.0.0.5:6379", "RAY_ADDRESS")
    assert resolved(RayTarget("10.0.0.6:6379", "--address")) == RayTarget("10.0.0.6:6379", "--address")


def _private_env(tmp: Path, base: dict) -> dict:
    """A Ray temporary directory and home of this test's own (no other Ray sees them)."""
    (tmp / "home").mkdir(parents=True, exist_ok=True)
    env = {**base, "RAY_TMPDIR": str(tmp), "HOME": str(tmp / "home"), "RAY_USAGE_STATS_ENABLED": "0",
           "OMP_NUM_THREADS": "1", "SYSID_COMPILE": "0"}
    env.pop("RAY_ADDRESS", None)
    return env


def _kill_group(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=60)


@pytest.mark.slow
def test_auto_never_joins_another_sweeps_private_ray(project, tmp_path):
    pytest.importorskip("ray.tune")
    tmp = Path(os.path.realpath("/tmp")) / f"sxa-{os.getpid()}"
    env = _private_env(tmp, no_paper_data(dict(os.environ), tmp_path / "nowhere"))
    private = subprocess.Popen(
        [sys.executable, "-c", "import time; from sysid.sweep.connect import start_ray; start_ray(1, None, print); "
                               "print('up', flush=True); time.sleep(600)"],
        env=env, cwd=tmp_path, start_new_session=True, stdout=subprocess.PIPE, text=True)
    try:
        assert private.stdout.readline().strip().endswith("up")
        out = tmp_path / "out"
        proc = subprocess.run([SYSID, "sweep", project.name, "-o", str(out), "--address", "auto"], cwd=project.parent,
                              env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and "--address auto: no Ray cluster started with `ray start` runs" in lines[0]
        assert not out.exists()
    finally:
        _kill_group(private)
        subprocess.run(["rm", "-rf", str(tmp)])


@pytest.mark.slow
def test_a_cluster_that_goes_away_mid_sweep_is_one_line_and_leaves_no_lock(tmp_path, dataset_dir):
    pytest.importorskip("ray.tune")
    from ray_cluster import RAY, free_port
    project = own_sweep_project(tmp_path / "project", dataset_dir, epochs=200)
    tmp = Path(os.path.realpath("/tmp")) / f"sxl-{os.getpid()}"
    env = _private_env(tmp, no_paper_data(dict(os.environ), tmp_path / "nowhere"))
    port = free_port()
    with open(tmp_path / "head.log", "w") as sink:
        head = subprocess.Popen([RAY, "start", "--head", "--block", f"--port={port}", "--num-cpus=1",
                                 "--include-dashboard=false", "--object-store-memory=80000000",
                                 "--disable-usage-stats"], env=env, start_new_session=True, stdout=sink,
                                stderr=subprocess.STDOUT)
    out = tmp_path / "out"
    sweep = None
    try:
        sweep = subprocess.Popen([SYSID, "sweep", project.name, "-o", str(out), "--address", f"127.0.0.1:{port}"],
                                 cwd=project.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True, start_new_session=True)
        deadline = time.time() + 300
        while time.time() < deadline and not (out / "trials.log").is_file() and sweep.poll() is None:
            time.sleep(1.0)
        assert (out / "trials.log").is_file(), f"no trial started: {sweep.poll()}"
        _kill_group(head)
        stdout, stderr = sweep.communicate(timeout=120)
        assert sweep.returncode == 2, stdout[-2000:] + stderr[-2000:]
        errors = [line for line in stderr.strip().splitlines() if line.startswith("error")]
        assert len(errors) == 1 and f"127.0.0.1:{port}: the Ray cluster went away while the sweep ran" in errors[0]
        assert "rerun with --resume" in errors[0]
        assert not (out.parent / f".{out.name}.lock").exists()
        assert (out / "manifest.json").is_file() and (out / "sweep.toml").is_file()   # a sealed, resumable sweep
        assert not list(out.glob("trials/**/*.arriving-*"))
    finally:
        if sweep is not None and sweep.poll() is None:
            _kill_group(sweep)
        _kill_group(head)
        subprocess.run(["rm", "-rf", str(tmp)])


def test_sweep_json_names_its_own_tune_folder_relative_to_itself(tmp_path):
    """Tune's experiment inside the sweep directory is recorded as ``tune`` and found in the
    moved folder; one elsewhere (``--storage``) by its absolute path, a URI as given."""
    from sysid.sweep.runner import TuneStorage
    from sysid.sweep.study import recorded_tune
    from sysid.sweep.summary import SweepSummary

    out = tmp_path / "project" / "out"
    out.mkdir(parents=True)
    own = recorded_tune(TuneStorage(str(out)), out)
    assert own == "tune"
    assert SweepSummary("s", tune=own).tune_at(tmp_path / "moved") == str(tmp_path / "moved" / "tune")
    store = tmp_path / "store"
    assert recorded_tune(TuneStorage(str(store), "own"), out) == str(store / "own")
    assert SweepSummary("s", tune=str(store / "own")).tune_at(tmp_path / "moved") == str(store / "own")
    assert recorded_tune(TuneStorage("s3://bucket/sweeps", "own"), out) == "s3://bucket/sweeps/own"
    assert SweepSummary("s", tune="s3://bucket/sweeps/own").tune_at(out) == "s3://bucket/sweeps/own"
