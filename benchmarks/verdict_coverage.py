"""How often the verdict's 95 % intervals hold a known truth on few windows.

A simulation with a known truth, through the rule itself (`sysid.evaluation.judgement.judge`):
each window's baseline RMSE is log-normal around 0.01 m/s (sigma 0.3), and the model's is the
baseline's times a log-normal ratio with median 0.8 (sigma 0.3 of the log). Two questions:

- cell: one log of n windows. The cell's change is the ratio of the pooled RMSEs, whose truth
  is sqrt(E[ratio^2]) = exp(mu + sigma^2) (the ratio independent of the baseline's level).
- overall: n logs of one window each. The overall change is the geometric mean of the cells'
  ratios, whose truth is the ratio's median exp(mu).

For each n = 3..20, `--repeats` draws (fixed seed), each judged with the plain percentile
interval (``VerdictRule(small_sample=False)``) and with the small-sample widening
(`sysid.evaluation.judgement.widening`, the default); the share of draws whose interval holds
the truth is its coverage (binomial sd about 1 % at 500 draws). The rule's resamples are
`--resamples` (the verdict's 2000 by default). Results: benchmarks/verdict_coverage.md.

    python benchmarks/verdict_coverage.py                 # the table
    python benchmarks/verdict_coverage.py --repeats 200   # quicker, noisier
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from sysid.evaluation.judgement import PairedCell, VerdictRule, judge

MU, SIGMA, LEVEL_SIGMA = math.log(0.8), 0.3, 0.3


def draw(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(model, baseline) per-window RMSE (n,) [m/s]."""
    baseline = 0.01 * np.exp(rng.normal(0.0, LEVEL_SIGMA, n))
    return baseline * np.exp(rng.normal(MU, SIGMA, n)), baseline


def coverage(n: int, repeats: int, rule: VerdictRule, seed: int) -> tuple[float, float]:
    """(cell coverage, overall coverage) of `rule`'s interval on `repeats` draws of n windows."""
    rng = np.random.default_rng(seed)
    cell_truth, overall_truth = math.exp(MU + SIGMA**2) - 1, math.exp(MU) - 1
    held_cell = held_overall = 0
    for _ in range(repeats):
        model, baseline = draw(rng, n)
        one = judge([PairedCell("log", "", 30.0, "u", model[None], baseline[None], 30.0 * np.arange(n))], rule)
        c = one.cells[0]
        held_cell += c.change_low <= cell_truth <= c.change_high
        model, baseline = draw(rng, n)
        logs = [PairedCell(f"log{i}", "", 30.0, "u", model[None, i:i + 1], baseline[None, i:i + 1], np.zeros(1))
                for i in range(n)]
        j = judge(logs, rule)
        held_overall += j.change_low <= overall_truth <= j.change_high
    return held_cell / repeats, held_overall / repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=500)
    parser.add_argument("--resamples", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"coverage of the stated 95 % interval, {args.repeats} draws per n, {args.resamples} resamples each")
    print("| n | cell, percentile | cell, widened | overall (n logs of 1 window), percentile | overall, widened |")
    print("|---|---|---|---|---|")
    for n in range(3, 21):
        plain = coverage(n, args.repeats, VerdictRule(resamples=args.resamples, small_sample=False), args.seed + n)
        wide = coverage(n, args.repeats, VerdictRule(resamples=args.resamples), args.seed + n)
        print(f"| {n} | {plain[0]:.3f} | {wide[0]:.3f} | {plain[1]:.3f} | {wide[1]:.3f} |", flush=True)


if __name__ == "__main__":
    main()
