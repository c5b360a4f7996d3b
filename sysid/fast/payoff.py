"""Which path runs a prediction or a maneuver: the compiled one only where it saves time.

A compiled package (`sysid.fast.compiled`) costs a cold start once per model, rule and
shape (compiling: 1-4 min on 2 quiet cores) and a warm one afterwards (loading it from the
disk cache: a fraction of a second to a few seconds); then its steps cost a fraction of the
eager ones. The rule (`choose_path`) reads the number of steps to run and the state of the
cache, never a clock, so the same inputs with the same cache take the same path:

- compiled, when every package the work needs is in the cache (a warm start);
- compiled, when the eager steps to run reach `repay_steps` per package still to compile
  (each cold package repays its compile with that many eager steps saved);
- otherwise eager.

Eager and compiled numbers agree to round-off, not bit for bit: a forced path
(``--compiled``/``--eager``) makes a result independent of the cache. The words of a choice
state what a cold and a warm start cost on this machine where the cache recorded them
(`sysid.fast.compiled.TIMINGS`): information only, never part of the decision.
"""
from __future__ import annotations

from dataclasses import dataclass

MANEUVER_REPAY_STEPS = 100_000  # eager closed-loop RK4 steps that take as long as compiling a maneuver loop
# (a hybrid's turning circle and zig-zag side by side: about 0.8-1 ms a step through the native MMG kernel
# and the anchored kNN gate, 2026-11-27; a cold compile of the loop 85-228 s)
PREDICTION_REPAY_STEPS = 100_000  # eager open-loop steps that take as long as compiling a prediction


@dataclass(frozen=True)
class PathChoice:
    """The path taken (compiled: True for the compiled one) and why, in one line."""

    compiled: bool
    reason: str


def choose_path(what: str, steps: int, cold: int, packages: int, repay_steps: int,
                asked: bool | None = None, label: str | None = None) -> PathChoice:
    """The path for `steps` eager steps of work (summed over models and predictions) that
    needs `packages` compiled packages, `cold` of them not in the cache.

    asked : True or False forces the compiled or the eager path; None applies the rule
        (module docstring): compiled when ``cold == 0`` or ``steps >= repay_steps * cold``.
    what : the words for the work ("loop", "prediction"); label : the cache label whose
        recorded cold and warm starts the reason quotes.
    """
    if asked is not None:
        return PathChoice(bool(asked), f"{'compiled' if asked else 'eager'} {what} (as asked)")
    from sysid.fast.compiled import enabled
    if not enabled():
        return PathChoice(False, f"eager {what} (compilation is off: SYSID_COMPILE=0)")
    costs = start_costs(label) if label is not None else ""
    if cold == 0:
        return PathChoice(True, f"compiled {what}: {packages} package(s) in the cache (a warm start{costs})")
    if steps >= repay_steps * cold:
        return PathChoice(True, f"compiled {what}: {steps} eager steps, at least the {repay_steps} per "
                                f"package that repay compiling {cold} package(s){costs}")
    return PathChoice(False, f"eager {what}: {steps} steps, fewer than the {repay_steps} per package that repay "
                             f"compiling {cold} package(s) not in the cache{costs}; --compiled compiles them for "
                             "later runs")


def start_costs(label: str) -> str:
    """"; a cold start took S s here, a warm one S s" from the cache's recorded times of
    `label` (the median of the last five), each part left out where none is recorded."""
    from sysid.fast.compiled import recorded_seconds
    cold, warm = recorded_seconds(label, "compile"), recorded_seconds(label, "load")
    parts = ([f"a cold start took {cold:.0f} s here"] if cold is not None else []) + (
        [f"a warm one {warm:.1f} s"] if warm is not None else [])
    return "; " + ", ".join(parts) if parts else ""
