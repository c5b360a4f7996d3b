"""Wall time and CPU time of one ``sysid reproduce --seeds N`` (or any sysid command line),
with the machine's load beside them: on a shared machine the wall time depends on the other
jobs, the CPU time of the command's process tree (driver, Ray's processes and workers, the
ensemble and maneuver workers) much less.

CPU time is read from /proc every `--every` seconds for every process descending from the
command (utime + stime of the latest reading of each; children's times reported to their
parents are not added, they would count twice); a process living less than one interval,
or the last interval of one, is missed, so it is a lower bound within a few seconds. The load (``/proc/loadavg``, 1-min) is sampled alongside: its
minimum, mean and maximum are printed.

    python benchmarks/reproduce_seeds_time.py -- sysid reproduce --seeds 5 -o /tmp/repro5 --overwrite

prints the command's own output, then one block: wall min, CPU min, load; the scorecard is
in the command's output (and in OUT/summary.json).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

TICKS = os.sysconf("SC_CLK_TCK")


def _stat(pid: int) -> tuple[int, float] | None:
    """(parent pid, CPU seconds of the process itself) of `pid`."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            text = f.read()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()  # after "pid (comm) "
    ppid = int(fields[1])
    utime, stime = int(fields[11]), int(fields[12])
    return ppid, (utime + stime) / TICKS


def _kind(pid: int, root: int) -> str:
    """What a process of the tree is: the command itself (the driver), a Ray worker
    (trials, the inbox actor), Ray's own services, or a worker process of the driver's
    (multiprocessing: ensembles, recorded maneuvers)."""
    if pid == root:
        return "driver (the command's process)"
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            args = f.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return "other"
    if args.startswith("ray::"):
        return "ray workers (" + args.split()[0] + ")"
    if "multiprocessing" in args:
        return "driver's worker processes"
    if "/ray/" in args:
        return "ray services"
    return "other"


def _tree_cpu(root: int, seen: dict[int, float], kinds: dict[int, str] | None = None) -> None:
    """Update `seen` (pid -> latest CPU seconds) with every living descendant of `root`
    (and `kinds`, pid -> `_kind`, when given)."""
    stats = {}
    for name in os.listdir("/proc"):
        if name.isdigit() and (s := _stat(int(name))) is not None:
            stats[int(name)] = s
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in stats.items():
        children.setdefault(ppid, []).append(pid)
    todo = [root]
    while todo:
        pid = todo.pop()
        if pid in stats:
            seen[pid] = max(seen.get(pid, 0.0), stats[pid][1])
            if kinds is not None and not kinds.get(pid, "").startswith("ray workers"):
                kinds[pid] = _kind(pid, root)  # a Ray worker names itself ray::... once it started
        todo += children.get(pid, [])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=float, default=2.0, help="seconds between /proc readings")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the command, after --")
    args = parser.parse_args()
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("give the command to time after --")
    seen: dict[int, float] = {}
    kinds: dict[int, str] = {}
    loads = []
    started = time.perf_counter()
    proc = subprocess.Popen(command)
    while proc.poll() is None:
        _tree_cpu(proc.pid, seen, kinds)
        with open("/proc/loadavg") as f:
            loads.append(float(f.read().split()[0]))
        time.sleep(args.every)
    wall = time.perf_counter() - started
    own = os.times()   # the command itself, waited for: its CPU and its waited-for children's
    cpu = max(sum(seen.values()), own.children_user + own.children_system)
    print(f"\ncommand: {' '.join(command)}\nexit {proc.returncode}; wall {wall / 60:.1f} min ({wall:.0f} s); "
          f"CPU of the process tree {cpu / 60:.1f} min ({cpu:.0f} s, {cpu / wall:.2f} cores on average); "
          f"load (1-min) min {min(loads, default=0):.1f}, mean {sum(loads) / max(len(loads), 1):.1f}, "
          f"max {max(loads, default=0):.1f} on {os.cpu_count()} cores", flush=True)
    by_kind: dict[str, float] = {}
    for pid, seconds in seen.items():
        by_kind[kinds.get(pid, "other")] = by_kind.get(kinds.get(pid, "other"), 0.0) + seconds
    for kind, seconds in sorted(by_kind.items(), key=lambda kv: -kv[1]):
        print(f"  CPU {seconds:7.0f} s  {kind}")
    sys.exit(proc.returncode)


if __name__ == "__main__":
    main()
