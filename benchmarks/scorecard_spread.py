"""How much the 5-seed scorecard of `sysid reproduce --seeds N` moves with the seeds drawn.

The scorecard (cells of Tables 7/8 where the hybrid's seed mean beats the paper's hybrid, the
mean 30-s cut against MMG-only, cells where the hybrid's seed mean beats NN-only's) is a count
over 36 cells per data set of seed means. This script rebuilds it from a reproduction's
per-seed metrics (``runs/<name>/seed<k>/metrics.csv``) for every subset of the seeds of a
given size (default: all leave-one-seed-out subsets), with the protocol's own functions
(`sysid.protocol.seeds.seed_metrics`, `sysid.protocol.paper.comparison_table`,
`sysid.protocol.reproduce.scorecard`), so a change of a cell or two can be read against the
spread the seeds themselves make. The full set of seeds gives the reproduction's own scorecard
back (checked). It reads only the reproduction's outputs: it chooses nothing.

    python benchmarks/scorecard_spread.py OUT            # OUT: a `sysid reproduce --seeds 5` output
    python benchmarks/scorecard_spread.py OUT --size 3   # every 3 of the 5 seeds
"""
from __future__ import annotations

import argparse
import itertools
import json
import statistics
from pathlib import Path

import pandas as pd

from sysid.protocol.paper import comparison_table
from sysid.protocol.reproduce import hybrid_baseline, scorecard
from sysid.protocol.seeds import seed_metrics

PROTOCOL_SEEDED = ("nn_D1", "nn_D2", "hybrid_D1", "hybrid_D2")


def _kind_dataset(run: Path) -> tuple[str, str]:
    summary = json.loads((run / "summary.json").read_text())
    return summary["model"], summary.get("dataset") or "-"


def _results(out: Path, seeds: tuple[int, ...]) -> list:
    """(name, kind, dataset, metrics) of the MMGs as defined and the seeded NN-only and hybrid
    runs, the latter averaged over `seeds`."""
    runs = out / "runs"
    results = []
    for name in ("mmg_paper", "mmg_lab"):
        results.append((name, "mmg", "-", pd.read_csv(runs / name / "metrics.csv")))
    for name in PROTOCOL_SEEDED:
        frames = [pd.read_csv(runs / name / f"seed{k}" / "metrics.csv") for k in seeds]
        kind, dataset = _kind_dataset(runs / name / f"seed{seeds[0]}")
        results.append((name, kind, dataset, seed_metrics(frames)))
    return results


def _card(out: Path, seeds: tuple[int, ...]) -> dict:
    table = comparison_table(_results(out, seeds))
    card = scorecard(table, hybrid_baseline()[1])
    d1, d2 = card.D1, card.D2
    assert d1 is not None and d2 is not None
    return {"seeds": seeds, "cells_beating_paper": d1.cells_beating_paper_hybrid + d2.cells_beating_paper_hybrid,
            "D1_cells": d1.cells_beating_paper_hybrid, "D2_cells": d2.cells_beating_paper_hybrid,
            "cut_D1": d1.reduction_vs_mmg_30s_mean, "cut_D2": d2.reduction_vs_mmg_30s_mean,
            "beats_nn_D1": d1.cells_beating_nn, "beats_nn_D2": d2.cells_beating_nn}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="a `sysid reproduce --seeds N` output directory")
    parser.add_argument("--size", type=int, default=None, help="seeds per subset (default: N - 1)")
    args = parser.parse_args()
    recorded = json.loads((args.out / "reproduction.json").read_text())
    n = int(recorded["seeds"])
    size = n - 1 if args.size is None else args.size
    if not 1 <= size <= n:
        raise SystemExit(f"--size: between 1 and the reproduction's {n} seeds")
    every = tuple(range(n))
    whole = _card(args.out, every)
    sc = recorded["scorecard"]
    own = sc["D1"]["cells_beating_paper_hybrid"] + sc["D2"]["cells_beating_paper_hybrid"]
    if whole["cells_beating_paper"] != own or whole["beats_nn_D2"] != sc["D2"]["cells_beating_nn"]:
        raise SystemExit(f"rebuilt scorecard {whole} differs from {args.out / 'reproduction.json'}'s")

    def line(c: dict) -> str:
        return (f"{','.join(map(str, c['seeds'])):>10}  {c['cells_beating_paper']:>2}/72 "
                f"(D1 {c['D1_cells']:>2}, D2 {c['D2_cells']:>2})  cut {100 * c['cut_D1']:.0f} % / "
                f"{100 * c['cut_D2']:.0f} %  beats NN {c['beats_nn_D1']} / {c['beats_nn_D2']}")

    print(f"{args.out}: {n} seeds; every {size} of them (seed means), then all {n}")
    print(f"{'seeds':>10}  cells beating the paper's hybrid  mean 30-s cut D1 / D2  hybrid beats NN-only D1 / D2")
    cards = [_card(args.out, s) for s in itertools.combinations(every, size)]
    for c in cards:
        print(line(c))
    print(line(whole) + "   <- the reproduction's scorecard")
    for key, label in (("cells_beating_paper", "cells beating the paper's hybrid (of 72)"),
                       ("beats_nn_D1", "D1 cells beating NN-only (of 36)"),
                       ("beats_nn_D2", "D2 cells beating NN-only (of 36)")):
        values = [c[key] for c in cards]
        print(f"{label}: {min(values)}-{max(values)} over the {len(cards)} subsets "
              f"(mean {statistics.mean(values):.1f}); all {n} seeds: {whole[key]}")


if __name__ == "__main__":
    main()
