"""Identification by Levenberg-Marquardt (`sysid.identify.levenberg_marquardt`), start states estimated
or with a prior, against a known truth: KVLCC2 maneuvers simulated by Euler at 1 Hz (the
identification model is then exactly right), hull derivatives from starts perturbed by 20-30 %."""

import numpy as np
import pytest
import torch

from benchmark_scripts import load_benchmark
from sysid import MMG, load_ship
from sysid.identify.levenberg_marquardt import (fit_uncertainty, identify_levenberg_marquardt, start_state_residuals,
                                       start_state_uncertainty)
from sysid.identify.uncertainty import multistep_residuals

NAMES = ["R_0", "Y_v", "Y_r", "N_v", "N_r"]


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("identification_kvlcc2")


@pytest.fixture(scope="module")
def records(bench):
    return bench.maneuvers(load_ship(bench.SHIP), {"turning35_stbd": 60, "zigzag10": 100}, "euler")


def _fit(bench, records, noise, seed):
    ship = load_ship(bench.SHIP)
    windows = bench.windows_from(records, 10, noise, seed)
    weights = torch.tensor([0.004, 0.003, 0.0008], dtype=torch.float64) ** -2
    start = bench.perturbed_start(ship, NAMES, seed)
    fit = identify_levenberg_marquardt(MMG(ship.with_overrides(start, "start")), windows, NAMES, weights, "euler")
    fitted = MMG(ship)
    fitted.coefficients.assign(fit.coefficients)
    truth = np.array([ship[n] for n in NAMES])
    return windows, weights, fit, fitted, truth, np.array([start[n] for n in NAMES])


def test_noise_free_windows_give_the_truth_and_the_true_start_states(bench, records):
    windows, _, fit, _, truth, start = _fit(bench, records, (0.0, 0.0, 0.0), 0)
    assert np.all(np.abs(start - truth) >= 0.2 * np.abs(truth) - 1e-12)  # really perturbed
    estimate = np.array([fit.coefficients[n] for n in NAMES])
    np.testing.assert_allclose(estimate, truth, rtol=1e-6)
    true_start = windows.states[0][:, [1, 3, 5]]
    assert float((fit.start - true_start).abs().max()) < 1e-8
    assert fit.cost < 1e-12


@pytest.mark.slow
def test_noisy_windows_cover_the_truth_and_the_start_states_move_towards_it(bench, records):
    noise = (0.004, 0.003, 0.0008)
    clean = bench.windows_from(records, 10, (0.0, 0.0, 0.0), 0).states[0][:, [1, 3, 5]]
    for seed in (0, 1):
        windows, weights, fit, fitted, truth, _ = _fit(bench, records, noise, seed)
        res = start_state_uncertainty(fitted, windows, NAMES, fit.start, weights, "euler")
        assert np.all(np.abs(res.estimate - truth) <= 3 * res.std_error), (res.estimate, truth, res.std_error)
        assert np.all(res.std_error < 0.05 * np.abs(truth))
        assert not res.undetermined.any()
        recorded = windows.states[0][:, [1, 3, 5]]
        # the fitted start is a better measurement of the true start than the recorded one
        # (mean square error ratio: u 0.17-0.19, v_m 0.27-0.34, r 0.84 for seeds 0, 1)
        ratio = (fit.start - clean).pow(2).mean(0) / (recorded - clean).pow(2).mean(0)
        assert np.all(ratio.numpy() < [0.5, 0.5, 0.95]), ratio


def test_profile_jacobian_equals_the_schur_complement(bench, records):
    """The profile information sum J~^T J~ is the Schur complement A - sum_w B_w D_w^-1 B_w^T
    of the full normal matrix; its inverse is the theta block of the full inverse."""
    windows, weights, fit, fitted, _, _ = _fit(bench, records, (0.004, 0.003, 0.0008), 2)
    res = start_state_uncertainty(fitted, windows, NAMES, fit.start, weights, "euler", covariance="gauss_newton")
    residuals, theta, _ = start_state_residuals(fitted, windows, NAMES, weights, "euler")
    W, p = fit.start.shape[0], len(NAMES)
    full = torch.func.jacfwd(lambda z: residuals(z[:p], z[p:].reshape(W, 3)))(
        torch.cat([theta, fit.start.reshape(-1)])).reshape(-1, p + 3 * W)
    e = residuals(theta, fit.start).detach().reshape(-1)
    s2 = float(e @ e) / (e.numel() - p - 3 * W)
    cov_full = s2 * torch.linalg.inv(full.T @ full)[:p, :p]
    np.testing.assert_allclose(res.std_error, np.sqrt(np.diag(cov_full.numpy())), rtol=1e-6)
    # and the Gauss-Newton step of the full problem is zero at the fit (converged)
    step = torch.linalg.lstsq(full, e).solution
    assert float((step[:p].abs() / theta.abs()).max()) < 1e-5


@pytest.mark.slow
def test_a_prior_pulls_the_estimate_and_its_information_enters_sigma(bench, records):
    """With prior_weight lambda the fit minimises data + lambda sum ((theta - prior)/|prior|)^2:
    its gradient is zero there; a huge lambda keeps the prior; and the Gauss-Newton sigma is
    s^2 (F + P)^-1 F (F + P)^-1 with F = J^T J, P = diag(lambda / prior^2)."""
    ship = load_ship(bench.SHIP)
    windows = bench.windows_from(records, 10, (0.004, 0.003, 0.0008), 3)
    weights = torch.tensor([0.004, 0.003, 0.0008], dtype=torch.float64) ** -2
    prior = bench.perturbed_start(ship, NAMES, 3)
    start = MMG(ship.with_overrides(prior, "start"))
    free = identify_levenberg_marquardt(start, windows, NAMES, weights, "euler", "recorded")
    held = identify_levenberg_marquardt(start, windows, NAMES, weights, "euler", "recorded", prior_weight=1e12)
    estimate = lambda fit: np.array([fit.coefficients[n] for n in NAMES])
    p = np.array([prior[n] for n in NAMES])
    np.testing.assert_allclose(estimate(held), p, rtol=1e-3)
    lam = 1e5  # comparable to the data: the estimate departs less from the prior than the free fit
    fit = identify_levenberg_marquardt(start, windows, NAMES, weights, "euler", "recorded", prior_weight=lam)
    assert fit.stopped == "converged"
    departure = lambda fit: float((((estimate(fit) - p) / p) ** 2).sum())
    assert 0.05 * departure(free) < departure(fit) < 0.95 * departure(free), (departure(fit), departure(free))
    fitted = MMG(ship)
    fitted.coefficients.assign(fit.coefficients)
    residuals, theta = multistep_residuals(fitted, windows, NAMES, weights, "euler")
    J = torch.func.jacfwd(residuals)(theta).reshape(-1, len(NAMES)).numpy()
    e = residuals(theta).detach().reshape(-1).numpy()
    P = np.diag(lam / p ** 2)
    gradient = J.T @ e + P @ (theta.numpy() - p)
    assert np.all(np.abs(gradient) <= 1e-5 * np.abs(J.T @ e).max() + 1e-9), gradient
    res = fit_uncertainty(fitted, windows, NAMES, fit, weights, "euler", "gauss_newton", prior, lam)
    F = J.T @ J
    inv = np.linalg.inv(F + P)
    s2 = e @ e / (e.size - len(NAMES))
    np.testing.assert_allclose(res.std_error, np.sqrt(np.diag(s2 * inv @ F @ inv)), rtol=1e-6)
    plain = fit_uncertainty(fitted, windows, NAMES, fit, weights, "euler", "gauss_newton")
    assert np.all(res.std_error < plain.std_error)
