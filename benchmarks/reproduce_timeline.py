"""The trial timeline of a finished ``sysid reproduce --seeds N`` (or sweep) output, read from
its ``trials.log`` (the inbox's journal: one line per trial started and trained): each Tune
trial's start, end and wall time (a group of seeds side by side is one trial), the busy
workers over time, the idle worker-seconds between the first start and the last end, and
what the same trials would take on `--workers` slots in other orders (a list schedule: each
trial starts on the first free slot, in the given order, with its measured wall time).

    python benchmarks/reproduce_timeline.py OUT [--workers 2]

The measured wall times depend on the load the trials ran under (another trial beside each,
other jobs): the simulated orders compare schedules of the same durations, not machines.
"""
from __future__ import annotations

import argparse
import heapq
import json
from dataclasses import dataclass
from pathlib import Path, PurePosixPath


@dataclass
class Trial:
    name: str          # the run's name (runs/NAME/seedK)
    seeds: list[str]
    start: float       # s, epoch
    end: float
    done: bool = True  # every seed trained (else: still running, or stopped)

    @property
    def wall(self) -> float:
        return self.end - self.start

    @property
    def label(self) -> str:
        return self.name + ("/" + ",".join(self.seeds) if len(self.seeds) > 1 else f"/{self.seeds[0]}")


def read_trials(out: Path) -> list[Trial]:
    """The Tune trials of `out`'s journal: seeds of one run started in one group (one
    ``side_by_side`` count at the same moment) form one trial, ending with its last seed."""
    starts: dict[str, tuple[float, int]] = {}
    ends: dict[str, float] = {}
    for line in (out / "trials.log").read_text().splitlines():
        event = json.loads(line)
        if event["event"] in ("started", "resumed"):
            starts[event["trial"]] = (event["time"], int(event.get("side_by_side", 1)))
        elif event["event"] == "trained":
            ends[event["trial"]] = event["time"]
    trials: dict[tuple[str, float], Trial] = {}
    for path, (start, together) in starts.items():
        run = PurePosixPath(path)
        key = (run.parent.name, round(start, 0)) if together > 1 else (path, start)
        trial = trials.setdefault(key, Trial(run.parent.name, [], start, start))
        trial.seeds.append(run.name)
        trial.start = min(trial.start, start)
        trial.end = max(trial.end, ends.get(path, start))
        trial.done = trial.done and path in ends
    return sorted(trials.values(), key=lambda t: t.start)


def list_schedule(durations: list[float], workers: int) -> float:
    """Makespan of `durations` started in order, each on the first free of `workers` slots."""
    free = [0.0] * workers
    for d in durations:
        heapq.heappush(free, heapq.heappop(free) + d)
    return max(free)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="the reproduction's (or sweep's) output directory")
    parser.add_argument("--workers", type=int, default=2, help="trial slots (default 2: this machine's cores)")
    args = parser.parse_args()
    trials = read_trials(args.out)
    t0 = trials[0].start
    last = max(t.end for t in trials)
    print(f"{len(trials)} trials, first start to last end {last - t0:.0f} s\n")
    print(f"{'trial':<44} {'start':>7} {'end':>7} {'wall':>7}   [s from the first start]")
    for t in trials:
        print(f"{t.label:<44} {t.start - t0:7.0f} {t.end - t0:7.0f} {t.wall:7.0f}" + ("" if t.done else "  not trained"))
    busy = sum(t.wall for t in trials)
    span = last - t0
    print(f"\nbusy trial-seconds {busy:.0f}; idle worker-seconds {args.workers * span - busy:.0f} of "
          f"{args.workers * span:.0f} ({1 - busy / (args.workers * span):.0%})")
    # when the trial slots fall below `workers` for good: the tail one slot idles through
    edges = sorted(t.end for t in trials)
    tail = last - edges[-args.workers] if len(edges) >= args.workers else 0.0
    print(f"the last {tail:.0f} s: fewer than {args.workers} trials running (no trial left to start)")
    walls = [t.wall for t in trials]
    print(f"\nlist schedules of these wall times on {args.workers} slots:")
    print(f"  as run (start order)        {list_schedule(walls, args.workers):7.0f} s")
    print(f"  longest first (LPT)         {list_schedule(sorted(walls, reverse=True), args.workers):7.0f} s")
    print(f"  lower bound max(longest, sum / slots) {max(max(walls), busy / args.workers):7.0f} s")


if __name__ == "__main__":
    main()
