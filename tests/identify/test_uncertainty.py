"""Standard errors of identified coefficients against cases with a known answer."""
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from sysid import MMG, integrate, load_ship
from sysid.identify.uncertainty import coefficient_uncertainty, multistep_residuals, rollout

NAMES = ["R_0", "Y_v", "Y_r", "N_v", "N_r"]


def _one_step_windows(ship, seed=0, count=60, noise=(0.003, 0.003, 0.003)):
    """Independent one-step windows (L = 2) from random states, white noise of std `noise`
    on the recorded (u, v_m, r) after the step: with Euler the residual is affine in the
    linear hull derivatives, so least squares is exact."""
    g = torch.Generator().manual_seed(seed)
    rand = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)
    x0 = torch.zeros(count, 6, dtype=torch.float64)
    x0[:, 1] = 0.8 + 0.5 * rand(count)
    x0[:, 3] = 0.15 * (rand(count) - 0.5)
    x0[:, 5] = 0.06 * (rand(count) - 0.5)
    inputs = torch.zeros(2, count, 4, dtype=torch.float64)
    inputs[..., 0] = 17.95
    inputs[..., 1] = 0.6 * (rand(count) - 0.5)
    states = integrate(MMG(ship), x0, inputs, 1.0, "euler")
    states[1, :, [1, 3, 5]] += torch.tensor(noise) * torch.randn(count, 3, generator=g, dtype=torch.float64)
    return SimpleNamespace(states=states, inputs=inputs, dt=1.0)


def _design(ship, windows, w):
    """d(residual)/d(R_0, Y_v, Y_r, N_v, N_r), written out from the equations of motion."""
    p = ship.parameters
    x0 = windows.states[0].numpy()
    u, v, r = x0[:, 1], x0[:, 3], x0[:, 5]
    U = np.hypot(u, v)
    L, q = p["L_pp"], 0.5 * p["rho"] * p["L_pp"] * p["d"]
    m, xG = p["m"], p["x_G"]
    A = np.array([[m + p["m_y"], xG * m], [xG * m, p["I_zz_J_zz"] + xG * xG * m]])
    Ainv = np.linalg.inv(A)
    dY = {"Y_v": q * v * U, "Y_r": q * r * L * U}
    dN = {"N_v": q * L * v * U, "N_r": q * L * r * L * U}
    rows_u, rows_v, rows_r = [], [], []
    for name in NAMES:
        Y, N = dY.get(name, 0 * u), dN.get(name, 0 * u)
        rows_u.append(-q * U * U / (m + p["m_x"]) if name == "R_0" else 0 * u)
        rows_v.append(Ainv[0, 0] * Y + Ainv[0, 1] * N)
        rows_r.append(Ainv[1, 0] * Y + Ainv[1, 1] * N)
    sw = np.sqrt(w)
    # residual order (W, 3): u, v, r per window
    X = np.stack([np.stack(rows_u, 1) * sw[0], np.stack(rows_v, 1) * sw[1], np.stack(rows_r, 1) * sw[2]], 1)
    return X.reshape(-1, len(NAMES))


def test_gauss_newton_errors_equal_least_squares_in_the_linear_case():
    ship = load_ship("kvlcc2_l7")
    windows = _one_step_windows(ship)
    w = np.array([1.0, 4.0, 100.0])
    model = MMG(ship)
    res = coefficient_uncertainty(model, windows, NAMES, weights=torch.tensor(w), covariance="gauss_newton")
    X = _design(ship, windows, w)
    residuals, theta = multistep_residuals(model, windows, NAMES, torch.tensor(w))
    r = residuals(theta).detach().numpy()[0].reshape(-1)
    s2 = r @ r / (r.size - len(NAMES))
    expected = np.sqrt(np.diag(s2 * np.linalg.inv(X.T @ X)))
    np.testing.assert_allclose(res.std_error, expected, rtol=1e-8)
    assert not res.undetermined.any()
    assert res.correlation.shape == (5, 5) and np.allclose(np.diag(res.correlation), 1.0)


@pytest.mark.parametrize("covariance, noise", [
    ("gauss_newton", (0.01, 0.02, 0.001)),  # weights 1/noise^2: white weighted residuals
    ("sandwich", (0.002, 0.005, 0.0003)),   # other weights: only the sandwich stays honest
])
@pytest.mark.slow
def test_sigma_is_honest_over_noise_seeds(covariance, noise):
    """Least squares from each seed's noisy windows: for every coefficient the spread of the
    estimates around the truth matches the predicted sigma, and +-2 sigma covers the truth
    about 95 % of the time."""
    ship = load_ship("kvlcc2_l7")
    truth = np.array([ship[n] for n in NAMES])
    w = torch.tensor([1e-4, 4e-4, 1e-6], dtype=torch.float64) ** -1
    z, covered = [], []
    for seed in range(60):
        windows = _one_step_windows(ship, seed=seed, count=40, noise=noise)
        model = MMG(ship)
        residuals, theta = multistep_residuals(model, windows, NAMES, w)
        J = torch.func.jacfwd(residuals)(theta).reshape(-1, len(NAMES))
        r = residuals(theta).detach().reshape(-1)
        estimate = theta - torch.linalg.lstsq(J, r).solution  # one Gauss-Newton step is exact here
        fitted = MMG(load_ship("kvlcc2_l7", dict(zip(NAMES, estimate.tolist()))))
        res = coefficient_uncertainty(fitted, windows, NAMES, weights=w, covariance=covariance)
        zs = (res.estimate - truth) / res.std_error
        z.append(zs)
        covered.append(np.abs(zs) <= 2.0)
    z, covered = np.array(z), np.array(covered)
    # 60 seeds: the sd of z is 1 within about +-0.2 (sampling), coverage 95 % within ~6 %
    assert np.all((z.std(0) > 0.75) & (z.std(0) < 1.3)), z.std(0)
    assert np.all(covered.mean(0) >= 0.85), covered.mean(0)


def test_straight_running_leaves_the_lateral_derivatives_undetermined():
    ship = load_ship("kvlcc2_l7")
    model = MMG(ship)
    W, T = 6, 20
    x0 = torch.tensor([[0.0, 1.17, 0.0, 0.0, 0.0, 0.0]] * W, dtype=torch.float64)
    inputs = torch.zeros(T + 1, W, 4, dtype=torch.float64)
    inputs[..., 0] = torch.linspace(14.0, 20.0, W)  # speed changes, no rudder
    states = integrate(model, x0, inputs, 1.0, "euler")
    g = torch.Generator().manual_seed(1)
    states[1:, :, 1] += 1e-3 * torch.randn(T, W, generator=g, dtype=torch.float64)
    res = coefficient_uncertainty(model, SimpleNamespace(states=states, inputs=inputs, dt=1.0), NAMES,
                                  weights=torch.ones(3, dtype=torch.float64))
    assert dict(zip(NAMES, res.undetermined.tolist())) == {"R_0": False, "Y_v": True, "Y_r": True,
                                                           "N_v": True, "N_r": True}
    assert res.std_error[0] < 0.05 * ship["R_0"]
    assert any(d["relative_sigma"] is None for d in res.weak_directions)  # singular directions
    summary = res.as_dict()
    assert summary["std_error"][1] is None and summary["names"] == NAMES
    assert "| R_0 | 0.022 |" in res.table()


def test_bounded_trainable_coefficients_are_reported_in_physical_units():
    ship = load_ship("kvlcc2_l7")
    windows = _one_step_windows(ship, count=30)
    w = torch.tensor([1.0, 4.0, 100.0], dtype=torch.float64)
    plain = coefficient_uncertainty(MMG(ship), windows, NAMES, weights=w)
    bounded = MMG(ship, trainable=["Y_v", "N_r"], bounds={"Y_v": (-1.0, 0.0)})
    res = coefficient_uncertainty(bounded, windows, NAMES, weights=w)
    np.testing.assert_allclose(res.estimate, plain.estimate, rtol=1e-12)
    np.testing.assert_allclose(res.std_error, plain.std_error, rtol=1e-9)


def test_unknown_covariance_is_refused():
    ship = load_ship("kvlcc2_l7")
    with pytest.raises(ValueError, match="covariance 'fisher'"):
        coefficient_uncertainty(MMG(ship), _one_step_windows(ship, count=4), NAMES, covariance="fisher")


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_rollout_is_the_integrators_scheme(method):
    model = MMG(load_ship("kvlcc2_l7"))
    x0 = torch.tensor([[0.0, 1.17, 0.0, 0.0, 0.0, 0.0], [0.0, 0.9, 0.0, 0.05, 0.2, 0.01]], dtype=torch.float64)
    inputs = torch.zeros(25, 2, 4, dtype=torch.float64)
    inputs[..., 0] = 17.95
    inputs[:, 0, 1] = torch.linspace(-0.6, 0.6, 25)  # the rudder moves every step
    inputs[:, 1, 1] = 0.3
    ours = rollout(model, x0, inputs, 1.0, method)
    ref = integrate(model, x0, inputs, 1.0, method)
    assert torch.allclose(ours, ref, rtol=1e-12, atol=1e-12)


def test_hybrid_model_with_a_silent_correction_gives_the_mmg_sigma():
    """The function takes any force model with `coefficients`: a hybrid whose FNN outputs
    zero (last layer zeroed, output mean 0) has exactly the MMG's uncertainty."""
    from sysid.hybrid.correction import ForceCorrection
    from sysid.hybrid.force_models import CorrectedModel
    ship = load_ship("kvlcc2_l7")
    windows = _one_step_windows(ship, count=30)
    w = torch.tensor([1.0, 4.0, 100.0], dtype=torch.float64)
    net = ForceCorrection([8, 8], torch.float64)
    with torch.no_grad():
        net.weights[-1].zero_()
        net.biases[-1].zero_()
    hybrid = CorrectedModel(MMG(ship, trainable=["Y_v"]), net)
    res = coefficient_uncertainty(hybrid, windows, NAMES, weights=w)
    plain = coefficient_uncertainty(MMG(ship), windows, NAMES, weights=w)
    np.testing.assert_allclose(res.std_error, plain.std_error, rtol=1e-10)


@pytest.mark.parametrize("ship_name", ["kvlcc2_l7", "esso_osaka"])
def test_float32_windows_with_bounded_coefficients_give_the_float64_errors(ship_name):
    """Training windows are float32 (the hybrid's dtype): bounded coefficients keep a float32
    Jacobian under jacfwd and give the float64 standard errors to float32 precision."""
    ship = load_ship(ship_name)
    windows = _one_step_windows(ship, count=30)
    w = torch.tensor([1.0, 4.0, 100.0], dtype=torch.float64)
    bounds = {"Y_v": (-1.0, 0.0), "N_r": (-0.3, 0.1), "Y_r": (-0.5, 0.5), "N_v": (-0.5, 0.1)}
    names = ["Y_v", "Y_r", "N_v", "N_r"]
    exact = coefficient_uncertainty(MMG(ship, trainable=names, bounds=bounds), windows, names, weights=w)
    single = SimpleNamespace(states=windows.states.float(), inputs=windows.inputs.float(), dt=windows.dt)
    res = coefficient_uncertainty(MMG(ship, trainable=names, bounds=bounds, dtype=torch.float32), single, names,
                                  weights=w.float())
    np.testing.assert_allclose(res.estimate, exact.estimate, rtol=1e-6)
    np.testing.assert_allclose(res.std_error, exact.std_error, rtol=2e-2)
    assert all(s > 0 for s in exact.std_error)
