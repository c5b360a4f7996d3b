"""The widening of the verdict's intervals on the real test logs: four MMGs whose N_r differs
from the ship file's (-0.045, -0.05, -0.06, -0.07) judged against the ship file's MMG on the
protocol's six test logs at 30 s and 100 s, with the plain percentile interval
(``VerdictRule(small_sample=False)``), with the overall interval widened by the deciding
windows (the rule before the logs' spread counted; rebuilt exactly from the same draws) and
with the rule's interval (the default): the outcomes, the overall intervals, the degrees of
freedom the overall interval rests on and the cells whose decision changes.
Results: benchmarks/verdict_coverage.md.

    python benchmarks/verdict_coverage_real.py     # the data found as sysid finds it (SYSID_DATA, ...)
"""
from sysid import MMG, load_ship
from sysid.evaluation.comparison import Contender, paired_cells, window_errors
from sysid.evaluation.judgement import (VerdictRule, _checked, _widened, _window_scores, deciding_windows,
                                        judge, widening)
from sysid.runs.lifecycle import cached_test_runs

runs = cached_test_runs()
ship = Contender("ship", (MMG(load_ship("esso_osaka")),))
others = [Contender(f"N_r{v}", (MMG(load_ship("esso_osaka", {"N_r": v})),)) for v in (-0.045, -0.05, -0.06, -0.07)]
errs = window_errors([ship, *others], runs, (30.0, 100.0))
for c in others:
    cells = paired_cells(errs, c.label, "ship")
    a, b = judge(cells, VerdictRule(small_sample=False)), judge(cells, VerdictRule())
    _, groups = _checked(cells)
    per_horizon: dict[float, int] = {}
    for (_log, h), group in groups.items():
        per_horizon[h] = per_horizon.get(h, 0) + group[0].n_windows
    deciding = max(per_horizon.values())
    horizon = min(h for h, n in per_horizon.items() if n == deciding)
    n = deciding_windows(_window_scores(groups, horizon))
    low, high = _widened(a.change + 1, a.change_low + 1, a.change_high + 1, widening(deciding, 0.95))
    print(f"{c.label}: {a.n_logs} logs, {a.n_windows} windows ({deciding} at {horizon:g} s, n = {n:.1f}); "
          f"percentile {a.outcome.name} [{a.change_low:+.4f}, {a.change_high:+.4f}], "
          f"by the windows [{low - 1:+.4f}, {high - 1:+.4f}] x{widening(deciding, 0.95):.3f}, "
          f"now {b.outcome.name} [{b.change_low:+.4f}, {b.change_high:+.4f}] x{widening(n, 0.95):.3f}; "
          f"{sum(x.decision != y.decision for x, y in zip(a.cells, b.cells))} of {len(a.cells)} cells change decision "
          f"from the percentile interval (cells are widened as before)")
    for x, y in zip(a.cells, b.cells):
        if x.decision != y.decision:
            print("   ", x.log[:22], x.horizon_s, x.channel, x.n_windows, x.decision.name, "->", y.decision.name)
