"""Where trials run: ``--address``, else ``RAY_ADDRESS``, else a local Ray of the sweep's own;
an address nobody answers at is one clear line (exit 2) within 30 s, with nothing written."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from sysid.errors import ConfigError
from sysid.sweep.connect import RayTarget, check_reachable, join_error, ray_target
from tiny_experiment import tiny_experiment

ROOT = Path(__file__).resolve().parents[2]


def test_the_address_comes_from_the_option_then_ray_address(monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert ray_target(None) == RayTarget(None)
    assert ray_target("local") == RayTarget(None)
    monkeypatch.setenv("RAY_ADDRESS", "10.0.0.5:6379")
    assert ray_target(None) == RayTarget("10.0.0.5:6379", "RAY_ADDRESS")
    assert ray_target("auto") == RayTarget("auto", "--address")
    for bad in ("", "10.0.0.5", "10.0.0.5:port", "host:70000"):
        with pytest.raises(ConfigError, match="expected HOST:PORT"):
            ray_target(bad)


def test_an_authentication_failure_says_what_to_set():
    cause = RuntimeError("ray.exceptions.AuthenticationError: RPC error: InvalidAuthToken: token is missing")
    error = ConnectionError("Failed to connect to Ray cluster at 10.0.0.5:6379")
    error.__cause__ = cause
    text = str(join_error(RayTarget("10.0.0.5:6379", "--address"), error))
    assert text.startswith("--address 10.0.0.5:6379: the cluster refused") and "RAY_AUTH_MODE=token" in text
    assert "RAY_AUTH_TOKEN" in text and "\n" not in text


def test_a_closed_port_is_refused_by_the_probe():
    with pytest.raises(ConfigError, match=r"127.0.0.1:1: no Ray cluster reachable there \(Connection refused\)"):
        check_reachable(RayTarget("127.0.0.1:1", "--address"))


@pytest.mark.parametrize("address", ["127.0.0.1:1", "nosuchhost.invalid:6379"])
@pytest.mark.parametrize("command", ["sweep", "reproduce"])
def test_an_unreachable_address_is_one_line_within_30_s(tmp_path, dataset_dir, command, address):
    pytest.importorskip("ray.tune")
    out = tmp_path / "out"
    if command == "sweep":
        tiny_experiment(tmp_path / "base.toml", dataset_dir, seed=0, epochs=2, warm_start_epochs=1)
        (tmp_path / "sweep.toml").write_text("[sweep]\nbase = 'base.toml'\nseeds = [0]\n"
                                             "[vary]\n'training.learning_rate' = [1e-3, 3e-3]\n")
        args = ["sweep", str(tmp_path / "sweep.toml"), "-o", str(out), "--address", address]
    else:
        args = ["reproduce", "--seeds", "2", "--only", "hybrid_D1", "--no-report", "-o", str(out), "--address", address]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SYSID_DATA": str(dataset_dir.parent)}
    env.pop("RAY_ADDRESS", None)
    proc = subprocess.run([sys.executable, "-m", "sysid", *args], capture_output=True, text=True, timeout=30,
                          env=env, cwd=tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert len(lines) == 1 and f"--address {address}:" in lines[0], lines
    assert ("not found" if "invalid" in address else "Connection refused") in lines[0]
    assert not out.exists() and not list(tmp_path.glob(".out*"))


def test_a_folders_sysid_running_in_place_of_the_installed_one_is_named(tmp_path):
    """`python -m sysid` in a folder holding another sysid (a clone) runs that one: the
    folder is named; from a folder with no sysid, or with the installed one, nothing."""
    import shutil

    import sysid
    from sysid.sweep.connect import installed_package_dir, shadowing_folder

    installed = installed_package_dir()
    assert installed == Path(sysid.__file__).resolve().parent and shadowing_folder() is None
    clone = tmp_path / "clone"
    shutil.copytree(installed, clone / "sysid", ignore=shutil.ignore_patterns("__pycache__"))
    probe = ("from sysid.sweep.connect import installed_package_dir, note_shadowing, shadowing_folder; "
             "print(shadowing_folder()); print(installed_package_dir()); note_shadowing(print)")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([sys.executable, "-c", probe], cwd=clone, env=env, capture_output=True, text=True,
                         timeout=120)
    folder, found, note = out.stdout.strip().splitlines()
    assert (folder, found) == (str(clone), str(installed)), out.stderr[-2000:]
    assert note.startswith(f"note: {clone}: its folder sysid is running, not the installed sysid ({installed})")
    elsewhere = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True,
                               timeout=120)
    assert elsewhere.stdout.strip().splitlines() == ["None", str(installed)]
