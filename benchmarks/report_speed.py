"""Wall and CPU time of `build_report` on one reproduction (or run) directory, drawn in this
process alone (`workers=1`) and with the HTML's figures in worker processes (`workers=N`),
side by side in one run, alternating; then whether the two ways wrote the same files:
report.html equal but for its "built" minute, report.pdf equal but for its creation date.

    python benchmarks/report_speed.py /tmp/repro5-s16 --workers 2 --repeats 1

The reports are written under a temporary directory (`--out` to keep them), never into the
source directory.
"""
from __future__ import annotations

import argparse
import re
import resource
import tempfile
import time
from pathlib import Path


def _cpu() -> float:
    """CPU seconds of this process and its reaped children (the worker processes)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _load() -> float:
    return float(Path("/proc/loadavg").read_text().split()[0])


def _html(path: Path) -> str:
    return re.sub(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", "BUILT", path.read_text())


def _pdf(path: Path) -> bytes:
    return re.sub(rb"/CreationDate \(D:[^)]*\)", b"/CreationDate ()", path.read_bytes())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("source", type=Path, help="reproduction or run directory")
    parser.add_argument("--workers", type=int, default=2, help="workers of the parallel way [2]")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None, help="where the reports go [a temporary directory]")
    args = parser.parse_args()
    from sysid.report import build_report

    root = args.out or Path(tempfile.mkdtemp(prefix="report_speed_"))
    times: dict[int, list[tuple[float, float, float]]] = {1: [], args.workers: []}
    for repeat in range(args.repeats):
        for workers in (1, args.workers):
            out = root / f"w{workers}"
            out.mkdir(parents=True, exist_ok=True)
            load, cpu, wall = _load(), _cpu(), time.perf_counter()
            build_report(args.source, out, workers=workers)
            times[workers].append((time.perf_counter() - wall, _cpu() - cpu, load))
            print(f"repeat {repeat + 1}, workers {workers}: {times[workers][-1][0]:.1f} s wall, "
                  f"{times[workers][-1][1]:.1f} s CPU (load {load:.1f})", flush=True)
    for workers, rows in times.items():
        wall = sorted(r[0] for r in rows)[len(rows) // 2]
        cpu = sorted(r[1] for r in rows)[len(rows) // 2]
        print(f"workers {workers}: median {wall:.1f} s wall, {cpu:.1f} s CPU")
    one, many = root / "w1", root / f"w{args.workers}"
    print(f"ratio (wall): {sorted(r[0] for r in times[1])[args.repeats // 2] / sorted(r[0] for r in times[args.workers])[args.repeats // 2]:.2f}x")
    print("report.html equal (but its built minute):", _html(one / "report.html") == _html(many / "report.html"))
    print("report.pdf equal (but its creation date):", _pdf(one / "report.pdf") == _pdf(many / "report.pdf"))


if __name__ == "__main__":
    main()
