"""How often the verdict's 95 % intervals hold a known truth on few windows.

A simulation with a known truth, through the rule itself (`sysid.evaluation.judgement.judge`):
each window's baseline RMSE is log-normal around 0.01 m/s (sigma 0.3), and the model's is the
baseline's times a log-normal ratio with median 0.8 (sigma 0.3 of the log). Two questions:

- cell: one log of n windows. The cell's change is the ratio of the pooled RMSEs, whose truth
  is sqrt(E[ratio^2]) = exp(mu + sigma^2) (the ratio independent of the baseline's level).
- overall: n logs of one window each. The overall change is the geometric mean of the cells'
  ratios, whose truth is the ratio's median exp(mu).

A third question, logs that differ (`--clustered`): L logs of m windows each, log l's
log-ratio centred on mu + b_l with b_l normal of sd tau (the spread between logs) and the
windows' sigma 0.3 about it. The truth is the population's: the geometric mean over logs of
the cell's pooled-RMSE ratio, exp(mu + sigma^2) - 1 = -12.8 %. Judged with the percentile
interval, with the interval widened by `widening` of the deciding windows (the rule before the
intra-log correlation; rebuilt exactly from the same draws of the percentile interval) and
with the rule's interval (`widening` of `deciding_windows`: the Welch-Satterthwaite degrees
of freedom of the bootstrap's between-log and within-log spread).

For each n = 3..20, `--repeats` draws (fixed seed), each judged with the plain percentile
interval (``VerdictRule(small_sample=False)``) and with the small-sample widening
(`sysid.evaluation.judgement.widening`, the default); the share of draws whose interval holds
the truth is its coverage (binomial sd about 1 % at 500 draws). The rule's resamples are
`--resamples` (the verdict's 2000 by default). Results: benchmarks/verdict_coverage.md.

    python benchmarks/verdict_coverage.py                 # the table
    python benchmarks/verdict_coverage.py --repeats 200   # quicker, noisier
    python benchmarks/verdict_coverage.py --clustered --repeats 300 --resamples 500
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from sysid.evaluation.judgement import PairedCell, VerdictRule, _widened, judge, widening

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


def clustered_logs(rng: np.random.Generator, logs: int, windows: int, tau: float) -> list[PairedCell]:
    """`logs` cells of `windows` windows, each log's log-ratio centred on MU + b, b ~ N(0, tau)."""
    cells = []
    for i in range(logs):
        b = rng.normal(0.0, tau) if tau > 0 else 0.0
        baseline = 0.01 * np.exp(rng.normal(0.0, LEVEL_SIGMA, windows))
        model = baseline * np.exp(rng.normal(MU + b, SIGMA, windows))
        cells.append(PairedCell(f"log{i}", "", 30.0, "u", model[None], baseline[None], 30.0 * np.arange(windows)))
    return cells


def clustered_coverage(logs: int, windows: int, tau: float, repeats: int, resamples: int,
                       seed: int) -> tuple[float, ...]:
    """Coverage of the overall interval on `repeats` draws of clustered logs: (percentile,
    widened by the deciding windows, the rule's), then the median width in log-ratio of the
    latter two."""
    rng = np.random.default_rng(seed)
    truth = math.exp(MU + SIGMA**2) - 1
    plain_rule, rule = VerdictRule(resamples=resamples, small_sample=False), VerdictRule(resamples=resamples)
    held = np.zeros(3)
    widths: list[tuple[float, float]] = []
    for _ in range(repeats):
        cells = clustered_logs(rng, logs, windows, tau)
        plain, now = judge(cells, plain_rule), judge(cells, rule)
        low, high = _widened(plain.change + 1, plain.change_low + 1, plain.change_high + 1,
                             widening(logs * windows, 0.95))
        held += [plain.change_low <= truth <= plain.change_high, low - 1 <= truth <= high - 1,
                 now.change_low <= truth <= now.change_high]
        widths.append((math.log(high / low), math.log((now.change_high + 1) / (now.change_low + 1))))
    return (*(held / repeats), *(float(w) for w in np.median(widths, axis=0)))


def main_clustered(repeats: int, resamples: int, seed: int) -> None:
    print(f"coverage of the overall 95 % interval on clustered logs, {repeats} draws each, {resamples} resamples")
    print("| logs | windows a log | tau | percentile | widened by windows (before) | widened by the logs' spread (now) "
          "| median width before / now (log-ratio) |")
    print("|---|---|---|---|---|---|---|")
    for logs in (2, 3, 6):
        for windows in (3, 10):
            for tau in (0.0, 0.2, 0.5):
                cov = clustered_coverage(logs, windows, tau, repeats, resamples,
                                         seed + 100 * logs + 10 * windows + int(10 * tau))
                print(f"| {logs} | {windows} | {tau:g} | {cov[0]:.3f} | {cov[1]:.3f} | {cov[2]:.3f} | {cov[3]:.2f} / {cov[4]:.2f} |",
                      flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=500)
    parser.add_argument("--resamples", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--clustered", action="store_true", help="the logs-that-differ table alone")
    args = parser.parse_args()
    if args.clustered:
        main_clustered(args.repeats, args.resamples, args.seed)
        return
    print(f"coverage of the stated 95 % interval, {args.repeats} draws per n, {args.resamples} resamples each")
    print("| n | cell, percentile | cell, widened | overall (n logs of 1 window), percentile | overall, widened |")
    print("|---|---|---|---|---|")
    for n in range(3, 21):
        plain = coverage(n, args.repeats, VerdictRule(resamples=args.resamples, small_sample=False), args.seed + n)
        wide = coverage(n, args.repeats, VerdictRule(resamples=args.resamples), args.seed + n)
        print(f"| {n} | {plain[0]:.3f} | {wide[0]:.3f} | {plain[1]:.3f} | {wide[1]:.3f} |", flush=True)


if __name__ == "__main__":
    main()
