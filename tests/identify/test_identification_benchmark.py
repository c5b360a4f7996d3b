"""The known-truth identification benchmark on a small case (the full case and its coverage
table: benchmarks/identification_kvlcc2.py)."""

import numpy as np
import pytest

from benchmark_scripts import load_benchmark
from sysid import load_ship



@pytest.fixture(scope="module")
def bench():
    return load_benchmark("identification_kvlcc2")


@pytest.mark.slow
def test_linear_derivatives_recovered_from_perturbed_starts(bench):
    ship = load_ship(bench.SHIP)
    names = ["Y_v", "Y_r", "N_v", "N_r"]
    records = bench.maneuvers(ship, {"turning35_stbd": 60, "zigzag10": 100}, "euler")
    for seed in (0, 1):
        case = bench.run_case(names, seed, window=10, records=records, method="euler")
        truth, start, est = case["truth"], case["start"], case["estimate"]
        sigma = case["sandwich"].std_error
        assert np.all(np.abs(start - truth) >= 0.2 * np.abs(truth) - 1e-12)  # really perturbed
        assert np.all(np.abs(est - truth) <= 3 * sigma), (est, truth, sigma)  # 2 sigma: the benchmark's table
        assert np.all(sigma < 0.1 * np.abs(truth))  # and sigma says these are well determined
        assert not case["sandwich"].undetermined.any()


def test_a_derivative_the_maneuvers_do_not_excite_is_flagged(bench):
    """A short zigzag at one speed hardly changes the speed: the surge derivatives X'vv and
    X'vvvv are not determined beside R'_0 -> flagged, with a weak direction."""
    ship = load_ship(bench.SHIP)
    records = bench.maneuvers(ship, {"zigzag10": 60}, "euler")
    case = bench.run_case(["R_0", "X_vv", "X_vvvv"], 0, window=10, records=records, method="euler")
    assert case["sandwich"].undetermined.any()
    assert case["sandwich"].weak_directions
