"""Sweeps on a two-node Ray cluster whose worker node cannot see the driver's output or data
folders (its own mount namespace with empty tmpfs over them; `ray_cluster`): the runs
arrive complete in ``-o`` and load; a worker killed mid-sweep is replaced and its trial
resumes on the new node from its last epoch; a token-protected cluster without the token,
and a local sweep beside a running cluster, are one clear line each and leave nothing.

Needs root on Linux (unshare -m, mount): skipped with the reason elsewhere.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest

from own_sweep import SYSID, no_paper_data, own_sweep_project, validation_files
from ray_cluster import LocalCluster, namespaces_allowed
from sysid.config.choices import Method
from sysid.dynamics.integrators import Integrator
from sysid.sweep.inbox import read_journal
from tiny_experiment import tiny_experiment, tiny_test_file

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cluster(tmp_path_factory, dataset_dir):
    pytest.importorskip("ray.tune")
    why = namespaces_allowed()
    if why:
        pytest.skip(f"two-node cluster tests: {why}")
    work = tmp_path_factory.mktemp("cluster")
    nodes = LocalCluster([work, dataset_dir.parent])
    try:
        nodes.start_head()
        nodes.add_worker()
        yield nodes, work
    finally:
        nodes.stop()


def _sweep_file(work: Path, dataset_dir: Path, name: str, epochs: int) -> Path:
    tiny_experiment(work / f"{name}_base.toml", dataset_dir, seed=0, epochs=epochs, warm_start_epochs=1)
    path = work / f"{name}.toml"
    path.write_text(f"[sweep]\nbase = '{name}_base.toml'\nseeds = [0]\nmax_retries = 2\n"
                    "[vary]\n'training.learning_rate' = [1e-3, 3e-3]\n")
    return path


def _sysid(args, env, dataset_dir, **kwargs):
    env = {**env, "SYSID_DATA": str(dataset_dir.parent)}
    return subprocess.run([sys.executable, "-m", "sysid", *args], env=env, capture_output=True, text=True,
                          timeout=kwargs.pop("timeout", 1200), **kwargs)


def test_runs_trained_where_nothing_is_shared_arrive_complete(cluster, dataset_dir):
    from sysid.data.recordings import read_run
    from sysid.evaluation.evaluate import evaluate_model
    from sysid.runs.rundir import RunDir
    from sysid.runs.layout import load_model

    nodes, work = cluster
    worker, seen = nodes.worker_view([work, dataset_dir / "berthing", tiny_test_file(dataset_dir)])
    assert seen == [True, False, False]  # the tmpfs over the output folder exists, empty; no data
    path = _sweep_file(work, dataset_dir, "two", epochs=2)
    out = work / "two_out"
    proc = _sysid(["sweep", str(path), "-o", str(out), "--address", nodes.address], nodes.env, dataset_dir)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "2/2 trials complete" in proc.stdout
    events = read_journal(out)
    assert {e["node"].rsplit(":", 1)[1] for e in events} == {worker[:8]}  # trained on the worker node
    for run in sorted((out / "trials").glob("*/seed0")):
        RunDir.open(run)  # the manifest verified
        metrics = work / f"{run.parent.name}.csv"
        ev = _sysid(["evaluate", str(run), "--data", str(tiny_test_file(dataset_dir)), "--horizon", "30",
                     "-o", str(metrics)], nodes.env, dataset_dir)
        assert ev.returncode == 0, ev.stderr[-2000:]
        assert pd.read_csv(run / "metrics.csv").empty  # a sweep scores on no test file
        # the worker node's model, evaluated here, scores as the same model evaluated in this process
        _, model = load_model(run)
        recorded = evaluate_model(model, [read_run(tiny_test_file(dataset_dir))], [30.0], Integrator(Method.EULER),
                                  traces=False).metrics
        ours = pd.read_csv(metrics)
        for c in ("rmse_u", "rmse_v", "rmse_r"):
            assert ours[c].iloc[0] == pytest.approx(recorded[c].iloc[0], rel=1e-5)


def test_a_sweep_on_own_logs_known_only_to_the_driver(cluster, dataset_dir, tmp_path):
    """Issue 33: a user's logs (knots, deg/s, renamed columns, validation logs) that only the
    driver sees, no paper data set anywhere, started from a folder holding a ``sysid``
    folder that is not sysid: both trials train on the worker node, validated on the
    user's validation log shipped with the training logs."""
    nodes, work = cluster
    sweep = own_sweep_project(work / "own_project", dataset_dir)
    project = sweep.parent
    _, seen = nodes.worker_view([project / "my logs" / "harbour_check.csv", project / "sysid"])
    assert seen == [False, False]
    out = work / "own_out"
    env = no_paper_data(nodes.env, tmp_path / "nowhere")
    proc = subprocess.run([SYSID, "sweep", sweep.name, "-o", str(out), "--address", nodes.address], cwd=project,
                          env=env, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "2/2 trials complete" in proc.stdout
    worker, _ = nodes.worker_view([])
    assert {e["node"].rsplit(":", 1)[1] for e in read_journal(out)} == {worker[:8]}
    for run in sorted((out / "trials").glob("*/seed0")):
        assert validation_files(run) == ["harbour_check.csv"]


def test_without_the_token_the_cluster_is_one_line_and_nothing_is_written(cluster, dataset_dir):
    nodes, work = cluster
    path = _sweep_file(work, dataset_dir, "auth", epochs=2)
    for args, out in ((["sweep", str(path), "-o", str(work / "auth_out")], work / "auth_out"),
                      (["reproduce", "--seeds", "2", "--only", "hybrid_D1", "--no-report", "-o",
                        str(work / "auth_repro")], work / "auth_repro")):
        proc = _sysid([*args, "--address", nodes.address], nodes.base_env, dataset_dir, cwd=work)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr[-3000:]
        assert f"--address {nodes.address}: the cluster refused the connection" in lines[0]
        assert "RAY_AUTH_MODE=token" in lines[0] and "RAY_AUTH_TOKEN" in lines[0]
        assert not out.exists() and not list(work.glob(f".{out.name}*"))


def _gcs_sessions(tmp: Path) -> set[str]:
    found = set()
    for pid in os.listdir("/proc"):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        if cmd and cmd[0].endswith("gcs_server"):
            found |= {a.split("=", 1)[1] for a in cmd if a.startswith("--session-dir=") and str(tmp) in a}
    return found


def test_a_local_sweep_beside_a_running_cluster_uses_its_own_ray(cluster, dataset_dir):
    nodes, work = cluster
    path = _sweep_file(work, dataset_dir, "beside", epochs=2)
    before, alive = _gcs_sessions(nodes.tmp), nodes.alive_nodes()
    out = work / "beside_out"
    proc = _sysid(["sweep", str(path), "-o", str(out), "--workers", "1"], nodes.base_env, dataset_dir)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    note = [line for line in proc.stdout.splitlines() if "note: a Ray cluster runs" in line]
    assert len(note) == 1 and nodes.address.split(":")[1] in note[0]
    assert "2/2 trials complete" in proc.stdout
    assert _gcs_sessions(nodes.tmp) == before and nodes.alive_nodes() == alive  # its Ray gone, the cluster as it was


def test_a_node_lost_mid_sweep_is_replaced_and_no_trial_restarts(cluster, dataset_dir):
    from sysid.config.experiment import parse_experiment
    from sysid.data.recordings import read_run
    from sysid.runs.lifecycle import run_experiment
    from sysid.sweep import load_sweep
    from sysid.sweep.plan import sweep_trials

    nodes, work = cluster
    # 100 epochs (about 9 s on a quiet machine) leave the kill below well inside the first trial,
    # also when other tests load the machine (with 20, the trial once ended before the kill)
    path = _sweep_file(work, dataset_dir, "lost", epochs=100)
    out = work / "lost_out"
    env = {**nodes.env, "SYSID_DATA": str(dataset_dir.parent)}
    first_worker, _ = nodes.worker_view([])
    sweep = subprocess.Popen([sys.executable, "-m", "sysid", "sweep", str(path), "-o", str(out), "--address",
                              nodes.address], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.time() + 900
        while time.time() < deadline and not list((out / "trials").glob("*/.seed0.checkpoint.pt")):
            assert sweep.poll() is None, sweep.communicate()[0][-3000:]
            time.sleep(0.1)
        nodes.kill_worker(nodes.workers[0])   # mid-trial: its checkpoint is with the driver
        nodes.add_worker()
        log = sweep.communicate(timeout=1200)[0]
    finally:
        if sweep.poll() is None:
            sweep.kill()
    assert sweep.returncode == 0, log[-4000:]
    assert "2/2 trials complete" in log and "retrying" in log
    events = read_journal(out)
    by_trial = {}
    for e in events:
        by_trial.setdefault(e["trial"], []).append(e)
    assert len(by_trial) == 2
    for trial, trial_events in by_trial.items():
        kinds = [e["event"] for e in trial_events]
        assert kinds.count("started") == 1 and kinds.count("trained") == 1  # never from scratch twice
    resumed = [e for e in events if e["event"] == "resumed"]
    assert len(resumed) == 1 and resumed[0]["after_epochs"] >= 1
    started = next(e for e in by_trial[resumed[0]["trial"]] if e["event"] == "started")
    assert started["node"].endswith(first_worker[:8]) and not resumed[0]["node"].endswith(first_worker[:8])
    # the resumed trial's model is the one an uninterrupted training gives
    trial = next(t for t in sweep_trials(load_sweep(path)) if t.path == resumed[0]["trial"])
    exp = parse_experiment(tomllib.loads(trial.config), "test")
    alone = run_experiment(exp, work / "alone", [read_run(tiny_test_file(dataset_dir))], progress=False,
                           log=lambda m: None)
    delivered = json.loads((out / trial.path / "summary.json").read_text())
    assert delivered["val_loss_multistep"] == pytest.approx(alone.training.val_loss_multistep, rel=1e-9)
    assert delivered["epochs"] == alone.training.epochs

