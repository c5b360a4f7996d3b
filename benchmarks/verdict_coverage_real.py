"""The widening of the verdict's intervals on the real test logs: three MMGs whose N_r differs
from the ship file's (-0.05, -0.06, -0.07) judged against the ship file's MMG on the
protocol's six test logs at 30 s and 100 s, with the plain percentile interval
(``VerdictRule(small_sample=False)``) and the widened one (the default): the outcomes, the
overall intervals and the cells whose decision changes. Results: benchmarks/verdict_coverage.md.

    python benchmarks/verdict_coverage_real.py     # the data found as sysid finds it (SYSID_DATA, ...)
"""
from sysid import MMG, load_ship
from sysid.runs.lifecycle import cached_test_runs
from sysid.evaluation.comparison import Contender, window_errors, paired_cells
from sysid.evaluation.judgement import judge, VerdictRule
runs = cached_test_runs()
ship = Contender("ship", (MMG(load_ship("esso_osaka")),))
others = [Contender(f"N_r{v}", (MMG(load_ship("esso_osaka", {"N_r": v})),)) for v in (-0.05, -0.06, -0.07)]
errs = window_errors([ship, *others], runs, (30.0, 100.0))
for c in others:
    cells = paired_cells(errs, c.label, "ship")
    a, b = judge(cells, VerdictRule(small_sample=False)), judge(cells, VerdictRule())
    print(f"{c.label}: {a.n_logs} logs, {a.n_windows} windows; percentile {a.outcome.name} "
          f"[{a.change_low:+.4f}, {a.change_high:+.4f}], widened {b.outcome.name} [{b.change_low:+.4f}, {b.change_high:+.4f}]; "
          f"{sum(x.decision != y.decision for x, y in zip(a.cells, b.cells))} of {len(a.cells)} cells change decision")
    for x, y in zip(a.cells, b.cells):
        if x.decision != y.decision:
            print("   ", x.log[:22], x.horizon_s, x.channel, x.n_windows, x.decision.name, "->", y.decision.name)
