"""Property: whatever numbers a user gives `evaluate`, `simulate`, `train` and `export` (NaN,
inf, negative, huge, fractional), sysid either refuses them with exit 2 and one error line
and writes nothing, or exits 0 with finite numbers in everything it wrote. Never a
traceback, never an internal error. Hypothesis draws the numbers (derandomized: the same
examples every run)."""
from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from cli_fixtures import sysid  # noqa: F401 (fixtures)
from cli_harness import leftovers
from tiny_experiment import tiny_config

PROPERTY = settings(max_examples=25, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])

# any float, and the ones that sit on the edges sysid draws: whole and fractional samples,
# the file's length (128 s at 1 Hz), the export step's bound
SECONDS = st.one_of(st.floats(), st.sampled_from([0.5, 1.0, 1.4, 2.5, 10.0, 30.0, 127.0, 128.0, 129.0, 1e9]))
COUNTS = st.one_of(st.integers(), st.integers(-2, 3))
_serial = itertools.count()


def fresh(tmp_path, name: str):
    """A new output path for each example (examples share one tmp_path)."""
    folder = tmp_path / f"example{next(_serial)}"
    folder.mkdir()
    return folder / name


def assert_clean(outcome, out) -> bool:
    """Refused cleanly (exit 2, one error line, nothing written) or done (exit 0, `out`
    exists); returns whether it was done."""
    text = outcome.out + outcome.err
    event(f"exit {outcome.code}: " + (outcome.error_lines[0][:70] if outcome.error_lines else ""))  # --hypothesis-show-statistics
    assert "Traceback" not in text and "internal error" not in text, text
    if outcome.code != 0:
        assert outcome.code == 2 and len(outcome.error_lines) == 1, text
        assert not out.exists() and leftovers(out.parent) == [], text
        return False
    assert out.exists(), text
    return True


def assert_finite_csv(path) -> None:
    """Every number finite, and no row diverged (``diverged_at_s`` is empty, NaN, exactly
    where a row did not diverge)."""
    frame = pd.read_csv(path)
    if "diverged" in frame:
        assert not frame.diverged.any() and frame.diverged_at_s.isna().all(), path
        frame = frame.drop(columns=["diverged", "diverged_at_s"])
    values = frame.select_dtypes("number").to_numpy(dtype=float)
    assert values.size and np.isfinite(values).all(), path


@PROPERTY
@given(horizons=st.lists(SECONDS, min_size=1, max_size=2))
def test_evaluate_numbers(sysid, files, tmp_path, horizons):  # noqa: F811
    out = fresh(tmp_path, "metrics.csv")
    options = [arg for h in horizons for arg in ("--horizon", repr(h))]
    if assert_clean(sysid("evaluate", "--data", files["test"], *options, "-o", out), out):
        assert_finite_csv(out)  # one file, every horizon has a window: no empty cell


@PROPERTY
@given(start=SECONDS, horizon=SECONDS, rate=st.one_of(SECONDS, st.sampled_from([1.0, 2.0, 10.0])))
def test_simulate_numbers(sysid, files, tmp_path, start, horizon, rate):  # noqa: F811
    out = fresh(tmp_path, "sim.csv")
    outcome = sysid("simulate", "--log", files["test"], "--start", repr(start), "--horizon", repr(horizon),
                    "--rate", repr(rate), "-o", out)
    if assert_clean(outcome, out):
        assert_finite_csv(out)


def or_valid(valid: list, strategy):
    """`strategy`, or (as often) one of the `valid` values: so that examples get past the
    first check and some train."""
    return st.one_of(st.sampled_from(valid), strategy)


@PROPERTY
@given(epochs=or_valid([0, 1], st.integers(max_value=1)),  # more epochs: only slower
       threads=or_valid([0, 1], COUNTS), horizon=or_valid([10.0, 30.0], SECONDS),
       stride=or_valid([2.0, 5.0], SECONDS), rate=or_valid([1.0], SECONDS))
def test_train_numbers(sysid, files, tmp_path, epochs, threads, horizon, stride, rate):  # noqa: F811
    config = fresh(tmp_path, "tiny.toml")
    config.write_text(tiny_config(files, evaluation={"horizons": f"[{horizon!r}]"},
                                  training={"stride_s": repr(stride)}, data={"rate": repr(rate)}))
    out = config.parent / "run"
    outcome = sysid("train", config, "-o", out, "--test", files["test"], "--epochs", epochs, "--threads", threads)
    if assert_clean(outcome, out):
        assert_finite_csv(out / "metrics.csv")


@settings(PROPERTY, max_examples=10)  # a valid example exports (seconds each)
@given(dt=SECONDS, batch=st.one_of(st.integers(max_value=0), st.integers(min_value=4097), st.integers(1, 3)))
# valid batches kept small: a batch of thousands is valid, only slow to export and time
@example(dt=1.0, batch=2)  # exported: its straight run stays finite
@example(dt=10.0, batch=1)  # within the bound, but the step runs off: refused
def test_export_numbers(sysid, trained, tmp_path, dt, batch):  # noqa: F811
    import torch
    from sysid.fast.export import load_step, straight_run

    out = fresh(tmp_path, "model.pt2")
    outcome = sysid("export", trained, "-o", out, "--portable", "--dt", repr(dt), "--batch", batch)
    if assert_clean(outcome, out):
        step = load_step(out)
        x0, inputs = straight_run(batch, getattr(torch, step.metadata["dtype"]))
        assert np.isfinite(step.predict(x0, inputs).numpy()).all()
