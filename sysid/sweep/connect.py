"""Connecting to Ray the way Ray does, with one clear line when it cannot be done.

Where trials run: ``--address`` (``HOST:PORT`` of a cluster's head, ``auto`` for the
cluster ``ray start`` started on this machine), else ``RAY_ADDRESS``, else a fresh local
Ray of this process's own (``ray.init(address="local")``): a local sweep never joins, or
collides with, a cluster that happens to run on the machine.

Failures before anything runs, each one line naming the address and what to do: Ray not
installed; a host that does not resolve or a port where nothing listens (found in seconds
by a TCP probe, instead of Ray's retries); a cluster that uses token authentication when
no token is set (Ray's ``InvalidAuthToken``); no cluster for ``auto``.
"""
from __future__ import annotations

import logging
import os
import socket
import sys
import tempfile
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from sysid.errors import ConfigError

INSTALL_HINT = "Ray is needed for sweeps and seed studies: pip install \"sysid[sweep]\" (ray[tune], optuna)"
PROBE_TIMEOUT_S = 5.0    # TCP connect to the cluster's head before Ray is asked to join it
WATCH_PERIOD_S = 2.0     # how often a running sweep checks that the cluster's head answers
WATCH_MISSES = 3         # unanswered checks in a row: the cluster is gone
JOIN_RETRIES = 10        # Ray's attempts (about 1 s each) to reach the head's GCS
AUTH_HINT = ("the cluster uses token authentication: set RAY_AUTH_MODE=token and the cluster's token in "
             "RAY_AUTH_TOKEN (or RAY_AUTH_TOKEN_PATH naming a file holding it; default ~/.ray/auth_token)")


def import_ray():
    """Ray and Ray Tune, quiet, or a clear error when they are not installed."""
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    os.environ.setdefault("TUNE_WARN_EXCESSIVE_EXPERIMENT_CHECKPOINT_SYNC_THRESHOLD_S", "600")
    try:
        import ray
        from ray import tune
    except ImportError:
        raise ConfigError(INSTALL_HINT) from None
    return ray, tune


@dataclass(frozen=True)
class RayTarget:
    """Where trials run: ``address`` None means a local Ray started by this process."""

    address: str | None
    source: str = "local"        # "--address" | "RAY_ADDRESS" | "local"

    def describe(self) -> str:
        return "a local Ray" if self.address is None else f"the Ray cluster at {self.address} ({self.source})"


def ray_target(address: str | None) -> RayTarget:
    """``--address``, else ``RAY_ADDRESS``, else local; refuses an empty or malformed one."""
    if address is not None:
        source = "--address"
    elif os.environ.get("RAY_ADDRESS"):
        address, source = os.environ["RAY_ADDRESS"], "RAY_ADDRESS"
    else:
        return RayTarget(None)
    address = address.strip()
    if address == "local":
        return RayTarget(None)
    if not address or (address != "auto" and "://" not in address and _host_port(address) is None):
        raise ConfigError(f"{source} {address!r}: expected HOST:PORT of a Ray cluster's head (e.g. "
                          "10.0.0.5:6379), auto (the cluster `ray start` started on this machine) or local")
    return RayTarget(address, source)


def _host_port(address: str) -> tuple[str, int] | None:
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        return None
    return host.strip("[]"), int(port)


def resolved(target: RayTarget) -> RayTarget:
    """``auto`` as the address of the cluster ``ray start`` started on this machine (the one
    Ray records in its temporary directory), never a Ray that a process started for itself
    (another sweep's private local Ray): one line when there is none."""
    if target.address != "auto":
        return target
    address = running_cluster()
    if address is None:
        raise ConfigError(f"{target.source} auto: no Ray cluster started with `ray start` runs on this machine "
                          "(the private Ray of another sweep is never joined); start one with `ray start --head`, "
                          "give its HOST:PORT, or leave --address out for a local Ray of this sweep's own")
    return RayTarget(address, target.source)


def check_reachable(target: RayTarget, timeout: float = PROBE_TIMEOUT_S) -> None:
    """Refuse (one line, within `timeout` s) a HOST:PORT whose host does not resolve or
    where nothing accepts a connection. ``auto`` and URIs (``ray://``) are left to Ray."""
    target = resolved(target)
    if target.address is None or "://" in target.address:
        return
    host, port = _host_port(target.address)
    where = f"{target.source} {target.address}"
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise ConfigError(f"{where}: host {host!r} not found ({getattr(exc, 'strerror', None) or exc}); "
                          "check the address of the cluster's head") from None
    reason = "no answer"
    for family, kind, proto, _, sockaddr in infos:
        try:
            with socket.socket(family, kind, proto) as sock:
                sock.settimeout(timeout)
                sock.connect(sockaddr)
                return
        except socket.timeout:
            reason = f"no answer within {timeout:g} s"
        except OSError as exc:
            reason = exc.strerror or str(exc)
    raise ConfigError(f"{where}: no Ray cluster reachable there ({reason}); start one with "
                      f"`ray start --head --port {port}` on {host}, or check the address")


@contextmanager
def _quiet_stderr() -> Iterator[list[str]]:
    """Send this process's stderr (Ray's C++ log lines) to a buffer; yields a list that
    holds the captured text afterwards."""
    captured: list[str] = []
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect
        yield captured
        return
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield captured
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            captured.append(sink.read().decode(errors="replace"))


@contextmanager
def _env(**values: str) -> Iterator[None]:
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in old.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _chain_text(exc: BaseException) -> str:
    parts = []
    while exc is not None and len(parts) < 8:
        parts.append(f"{type(exc).__name__}: {exc}")
        exc = exc.__cause__ or exc.__context__
    return "\n".join(parts)


def join_error(target: RayTarget, exc: BaseException, log_text: str = "") -> ConfigError:
    """One line for a failed ``ray.init`` of `target`."""
    text = _chain_text(exc) + "\n" + log_text
    where = f"{target.source} {target.address}"
    if "AuthenticationError" in text or "InvalidAuthToken" in text or "Unauthenticated" in text:
        return ConfigError(f"{where}: the cluster refused the connection: {AUTH_HINT}")
    if "Could not find any running Ray instance" in text:
        return ConfigError(f"{where}: no Ray cluster runs on this machine (start one with `ray start --head`, "
                           "or give its HOST:PORT)")
    last = (str(exc).strip().splitlines() or [type(exc).__name__])[-1][:200]
    return ConfigError(f"{where}: cannot join the Ray cluster ({last})")


def package_dir() -> Path:
    """The folder of the sysid package this process runs (this module's grandparent)."""
    return Path(__file__).resolve().parents[1]


def installed_package_dir() -> Path | None:
    """Where ``import sysid`` leads without the working directory and the script's folder
    on the path: the installed package (None: none is installed)."""
    from importlib.machinery import PathFinder

    script = Path(os.path.realpath(sys.argv[0])).parent if sys.argv and sys.argv[0] else None
    local = {Path.cwd().resolve(), script}
    path = [p for p in sys.path if p and Path(p).resolve() not in local]
    spec = PathFinder.find_spec("sysid", path)
    finders = [f for f in sys.meta_path if f is not PathFinder and hasattr(f, "find_spec")]
    for finder in finders:
        if spec is not None and spec.origin:
            break
        try:
            spec = finder.find_spec("sysid", None)
        except Exception:  # another package's finder: not ours to judge
            spec = None
    return Path(spec.origin).resolve().parent if spec is not None and spec.origin else None


def shadowing_folder() -> Path | None:
    """The folder whose ``sysid`` this process runs in place of the installed one (started
    from a folder holding one, e.g. ``python -m sysid`` in a clone), else None."""
    installed = installed_package_dir()
    return package_dir().parent if installed is not None and installed != package_dir() else None


def note_shadowing(log: Callable[[str], None]) -> None:
    """One line when this process runs another sysid than the installed one (`shadowing_folder`)."""
    folder = shadowing_folder()
    if folder is not None:
        log(f"note: {folder}: its folder sysid is running, not the installed sysid ({installed_package_dir()}); "
            "a cluster's nodes run their installed sysid: start sysid from another folder to run that one")


@contextmanager
def _code_directory() -> Iterator[None]:
    """This process's working directory set, while Ray starts, to the folder that holds the
    sysid package it runs: Ray puts the driver's working directory first on every worker's
    ``sys.path``, so a folder named ``sysid`` where the command was started (a clone, a
    project folder) would otherwise be what the trials import."""
    here = os.getcwd()
    os.chdir(package_dir().parent)
    try:
        yield
    finally:
        os.chdir(here)


def head_answers(address: str, timeout: float = PROBE_TIMEOUT_S) -> bool:
    """Whether something accepts a TCP connection at a ``HOST:PORT`` address."""
    host_port = _host_port(address)
    if host_port is None:
        return True   # a URI (ray://): Ray's own client reports its loss
    try:
        with socket.create_connection(host_port, timeout=timeout):
            return True
    except OSError:
        return False


_LOST_CLEANUPS: list[Callable[[], None]] = []


def on_cluster_lost(cleanup: Callable[[], None]) -> None:
    """Run `cleanup` (e.g. release the output's lock) if the cluster goes away mid-run and
    the process must end at once (`watch_head`); later registrations run first."""
    _LOST_CLEANUPS.append(cleanup)


def lost_line(target: RayTarget, note: str) -> str:
    return (f"{target.source} {target.address}: the Ray cluster went away while the sweep ran (its head no "
            f"longer answers); {note}")


@contextmanager
def watch_head(target: RayTarget, note: Callable[[], str], cleanup: Callable[[], None] = lambda: None,
               period: float = WATCH_PERIOD_S, misses: int = WATCH_MISSES) -> Iterator[None]:
    """While the block runs, check every `period` s that the cluster's head answers; after
    `misses` failures in a row, run `cleanup` and the `on_cluster_lost` cleanups, print one line (`note`:
    what was kept) and end the process with exit code 2, before Ray's own loss of the
    head ends it without a word. Nothing is watched for a local Ray."""
    target = resolved(target)
    if target.address is None or _host_port(target.address) is None:
        yield
        return
    stop = threading.Event()

    def watch() -> None:
        failed = 0
        while not stop.wait(period):
            failed = 0 if head_answers(target.address, min(period, PROBE_TIMEOUT_S)) else failed + 1
            if failed >= misses and not stop.is_set():
                for step in [cleanup, *reversed(_LOST_CLEANUPS)]:
                    try:
                        step()
                    except Exception:  # the line and the exit come first
                        pass
                os.write(2, f"error: {lost_line(target, note())}\n".encode())
                os._exit(2)

    thread = threading.Thread(target=watch, name="sysid-watch-head", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()


def running_cluster() -> str | None:
    """The address of a Ray cluster `ray start` left running on this machine, if any."""
    try:
        from ray._private import services
        address = services.find_bootstrap_address(None)
        return address if address and address in services.find_gcs_addresses() else None
    except Exception:  # a private API: no note rather than an error
        return None


def start_ray(workers: int, address: str | None, log: Callable[[str], None] = print) -> bool:
    """Join the cluster `ray_target(address)` names, or start a local Ray with `workers`
    CPUs; True if this call started or joined (the caller shuts it down)."""
    ray, _ = import_ray()
    target = ray_target(address)
    note_shadowing(log)
    # trial failures are reported by the progress lines and the results table, not tracebacks
    for name in ("ray", "ray.tune", "ray.air", "ray.train"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if ray.is_initialized():
        return False
    if target.address is None:
        other = running_cluster()
        if other:
            log(f"note: a Ray cluster runs on this machine ({other}); this run starts a local Ray of its own "
                "(--address auto joins that cluster)")
        with _code_directory():
            ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False,
                     logging_level=logging.ERROR, object_store_memory=200 * 1024**2, configure_logging=True)
        return True
    target = resolved(target)
    check_reachable(target)
    with _env(RAY_gcs_server_port_wait_time_s=str(JOIN_RETRIES)), _quiet_stderr() as captured, _code_directory():
        try:
            ray.init(address=target.address, log_to_driver=False, logging_level=logging.ERROR)
        except Exception as exc:  # Ray's ConnectionError/RuntimeError/AuthenticationError
            failure = exc
        else:
            failure = None
    if failure is not None:
        if ray.is_initialized():
            ray.shutdown()
        raise join_error(target, failure, "".join(captured)) from None
    return True
