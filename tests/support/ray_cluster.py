"""A Ray cluster of this host's processes for the cluster tests: a head with no CPUs and
worker nodes of one CPU, each worker in a mount namespace of its own (``unshare -m``) with
empty tmpfs mounts over the folders it must not see (the driver's output and data), so
that it shares nothing with the driver but the network, as a cloud VM would.

Every process tree is started in a session of its own and killed by its process group;
the cluster's temporary directory (``RAY_TMPDIR``) and home (``HOME``: Ray's token file)
are private to the test, so no other Ray on the machine sees or is seen by it.
"""
from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RAY = str(Path(sys.executable).with_name("ray"))


def namespaces_allowed() -> str | None:
    """Why worker namespaces cannot be made here (None: they can)."""
    if sys.platform != "linux" or os.geteuid() != 0:
        return "needs root on Linux (unshare -m and tmpfs mounts)"
    if shutil.which("unshare") is None:
        return "needs unshare (util-linux)"
    probe = subprocess.run(["unshare", "-m", "sh", "-c", "mount -t tmpfs none /mnt"], capture_output=True, text=True)
    if probe.returncode != 0:
        return f"unshare -m / mount not allowed here ({probe.stderr.strip()[:120]})"
    return None


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("", 0))
        return sock.getsockname()[1]


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def kill_group(proc: subprocess.Popen, wait_s: float = 20.0) -> None:
    """SIGKILL the process group `proc` leads and wait until none of it is left (the
    leader reaped here, the rest by init)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=wait_s)
    deadline = time.time() + wait_s
    while group_alive(proc.pid) and time.time() < deadline:
        time.sleep(0.2)


class LocalCluster:
    """Head (0 CPUs) plus worker nodes; `env` is what a driver needs to join it (token,
    temporary directory, home)."""

    def __init__(self, hidden: list[Path], token: bool = True):
        self.hidden = [Path(p) for p in hidden]
        self.tmp = Path(tempfile.mkdtemp(prefix="sxr-", dir="/tmp"))  # short: Ray's socket paths
        (self.tmp / "home").mkdir()
        self.port = free_port()
        self.groups: list[subprocess.Popen] = []
        self.workers: list[subprocess.Popen] = []
        self.token = secrets.token_hex(16)
        self.base_env = {**os.environ, "RAY_TMPDIR": str(self.tmp), "HOME": str(self.tmp / "home"),
                         "PYTHONPATH": str(ROOT), "SYSID_COMPILE": "0", "OMP_NUM_THREADS": "1",
                         "RAY_USAGE_STATS_ENABLED": "0"}
        self.base_env.pop("RAY_ADDRESS", None)
        self.env = dict(self.base_env)  # a driver with the token
        if token:
            self.env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=self.token)
        self.address = None

    def _start(self, argv: list[str], env: dict, log: str) -> subprocess.Popen:
        with open(self.tmp / log, "w") as sink:  # the child keeps its own descriptor
            proc = subprocess.Popen(argv, env=env, start_new_session=True, stdout=sink, stderr=subprocess.STDOUT)
        self.groups.append(proc)
        return proc

    def start_head(self) -> str:
        env = {**self.env, "RAY_health_check_initial_delay_ms": "1000", "RAY_health_check_period_ms": "1000",
               "RAY_health_check_timeout_ms": "1000", "RAY_health_check_failure_threshold": "3"}
        self._start([RAY, "start", "--head", "--block", f"--port={self.port}", "--num-cpus=0",
                     "--include-dashboard=false", "--object-store-memory=80000000", "--disable-usage-stats"],
                    env, "head.log")
        self.address = f"{socket.gethostbyname(socket.gethostname())}:{self.port}"
        self._wait_nodes(1)
        return self.address

    def add_worker(self) -> subprocess.Popen:
        """A worker node of one CPU that cannot see the hidden folders."""
        mounts = " && ".join(f"mount -t tmpfs none '{p}'" for p in self.hidden)
        command = (f"{mounts} && exec '{RAY}' start --block --address={self.address} --num-cpus=1 "
                   "--object-store-memory=80000000 --disable-usage-stats")
        before = self.alive_nodes()
        proc = self._start(["unshare", "-m", "sh", "-c", command], self.env, f"worker{len(self.workers)}.log")
        self.workers.append(proc)
        self._wait_nodes(before + 1)
        return proc

    def kill_worker(self, proc: subprocess.Popen, timeout: float = 180.0) -> None:
        """Kill a worker node and wait until the cluster has declared it dead."""
        before = self.alive_nodes()
        kill_group(proc)
        deadline = time.time() + timeout
        while self.alive_nodes() >= before and time.time() < deadline:
            time.sleep(1.0)

    def alive_nodes(self) -> int:
        probe = ("import ray, logging; ray.init(address=%r, logging_level=logging.ERROR, log_to_driver=False); "
                 "print(sum(n['Alive'] for n in ray.nodes()))") % self.address
        out = subprocess.run([sys.executable, "-c", probe], env=self.env, capture_output=True, text=True, timeout=120)
        lines = out.stdout.strip().splitlines()
        return int(lines[-1]) if lines and lines[-1].isdigit() else 0

    def worker_view(self, paths: list[Path]) -> tuple[str, list[bool]]:
        """(node id, whether each path exists) as a task on a worker node sees it."""
        probe = ("import json, os, ray, logging; ray.init(address=%r, logging_level=logging.ERROR, log_to_driver=False)\n"
                 "@ray.remote(num_cpus=1)\n"
                 "def look(paths):\n"
                 "    return ray.get_runtime_context().get_node_id(), [os.path.exists(p) for p in paths]\n"
                 "print(json.dumps(ray.get(look.remote(%r))))") % (self.address, [str(p) for p in paths])
        out = subprocess.run([sys.executable, "-c", probe], env=self.env, capture_output=True, text=True, timeout=300)
        node, seen = json.loads(out.stdout.strip().splitlines()[-1])
        return node, seen

    def _wait_nodes(self, count: int, timeout: float = 180.0) -> None:
        deadline = time.time() + timeout
        while time.time() < deadline:
            if self.alive_nodes() >= count:
                return
            time.sleep(1.0)
        raise RuntimeError(f"the test cluster did not reach {count} nodes; see {self.tmp}/*.log")

    def stop(self) -> None:
        for proc in reversed(self.groups):
            kill_group(proc)
        shutil.rmtree(self.tmp, ignore_errors=True)
