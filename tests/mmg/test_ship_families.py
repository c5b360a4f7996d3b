"""Force-model families in the ship file: choice, validation naming the family's keys,
a ship without wind, and the standard family's own analytic checks."""
import math

import pytest
import torch

from sysid import MMG, integrate, load_ship
from sysid.errors import ShipDefinitionError
from sysid.mmg.ship import ships_dir


def _kvlcc2_edited(tmp_path, old, new):
    text = (ships_dir() / "kvlcc2_l7.toml").read_text()
    assert old in text, old
    path = tmp_path / "myship.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_families_are_read_from_the_file():
    assert dict(load_ship("kvlcc2_l7").models) == {"hull": "standard", "propeller": "standard",
                                                   "rudder": "standard"}
    esso = load_ship("esso_osaka")
    assert esso.models["hull"] == "yoshimura_low_speed" and esso.has_wind
    assert not load_ship("kvlcc2_l7").has_wind


@pytest.mark.parametrize("old, new, message", [
    ("Y_vvr = 0.379\n", "", r"myship.toml: \[hull\] Y_vvr is missing \(needed by hull model 'standard'\)"),
    ("C_1 = 2.0", "C_1 = -2.0", r"\[propeller\] C_1 = -2.0 is out of range"),
    ("R_0 = 0.022", "R_0 = 0.022\nX_0F = -0.02", r"\[hull\] X_0F is not a parameter of hull model 'standard'"),
    ('[hull]\nmodel = "standard"', '[hull]\nmodel = "polynomial"',
     r"\[hull\] model = 'polynomial' is not known; choose one of 'standard', 'yoshimura_low_speed'"),
    ("kappa = 0.50", "kappa = \"half\"", r"\[rudder\] kappa: expected a number"),
    ('[rudder]\nmodel = "standard"', '[rudder]\nmodel = "four_quadrant"',
     r"\[rudder\] lambda_R is missing \(needed by rudder model 'four_quadrant'\)"),
])
def test_validation_names_file_section_key_and_family(tmp_path, old, new, message):
    with pytest.raises(ShipDefinitionError, match=message):
        load_ship(_kvlcc2_edited(tmp_path, old, new))


def test_override_must_belong_to_the_ships_families():
    with pytest.raises(ShipDefinitionError, match="X_0F is not a parameter of ship 'kvlcc2_l7'"):
        load_ship("kvlcc2_l7", {"X_0F": -0.02})
    with pytest.raises(ShipDefinitionError, match="trainable: Y_vvv is not a parameter of ship 'esso_osaka'"):
        MMG(load_ship("esso_osaka"), trainable=["Y_vvv"])
    assert load_ship("kvlcc2_l7", {"Yvvv": -1.5})["Y_vvv"] == -1.5
    with pytest.raises(ShipDefinitionError, match="quadrature 'simpson' applies to the yoshimura_low_speed hull"):
        MMG(load_ship("kvlcc2_l7"), quadrature="simpson")


def test_wind_needs_its_whole_section(tmp_path):
    wind = '\n[wind]\nmodel = "fujiwara"\nA_T = 1.0\n'
    path = _kvlcc2_edited(tmp_path, "[sensors]", wind + "[sensors]")
    with pytest.raises(ShipDefinitionError, match=r"\[principal\] rho_air is missing \(needed by wind model"):
        load_ship(path)


def test_no_wind_section_means_no_wind_force():
    model = MMG(load_ship("kvlcc2_l7"))
    state = torch.tensor([[0.0, 1.2, 0.0, 0.05, 0.3, 0.01]], dtype=torch.float64)
    inputs = torch.tensor([[17.95, 0.1, 10.0, 1.0]], dtype=torch.float64)  # a strong true wind
    f = model(state, inputs)
    assert torch.equal(f.wind, torch.zeros_like(f.wind))
    assert f.relative_wind[0, 0] > 5.0  # still reported (the FNN's input)


def test_standard_hull_in_straight_ahead_and_pure_yaw():
    """Analytic cases: v = r = 0 gives X_H = -R'_0 q U^2; v = 0 gives the r-polynomial."""
    ship = load_ship("kvlcc2_l7")
    model = MMG(ship)
    q = 0.5 * ship["rho"] * ship["L_pp"] * ship["d"]
    L = ship["L_pp"]
    u, r = 1.1, 0.02
    state = torch.tensor([[0.0, u, 0.0, 0.0, 0.0, 0.0], [0.0, u, 0.0, 0.0, 0.0, r]], dtype=torch.float64)
    f = model(state, torch.zeros(2, 4, dtype=torch.float64)).hull
    assert float(f[0, 0]) == pytest.approx(-ship["R_0"] * q * u * u, rel=1e-14)
    assert float(f[0, 1]) == 0.0 and float(f[0, 2]) == 0.0
    rp = r * L / u
    assert float(f[1, 0]) == pytest.approx(q * u * u * (-ship["R_0"] + ship["X_rr"] * rp ** 2), rel=1e-13)
    assert float(f[1, 1]) == pytest.approx(q * u * u * (ship["Y_r"] * rp + ship["Y_rrr"] * rp ** 3), rel=1e-13)
    assert float(f[1, 2]) == pytest.approx(q * L * u * u * (ship["N_r"] * rp + ship["N_rrr"] * rp ** 3), rel=1e-13)


def test_standard_model_is_differentiable_batched_and_float32():
    ship = load_ship("kvlcc2_l7")
    model = MMG(ship, trainable=["Y_v", "N_r", "N_vvr"])
    x0 = torch.tensor([[0.0, 1.17, 0.0, 0.0, 0.0, 0.0]] * 3, dtype=torch.float64)
    inputs = torch.zeros(20, 3, 4, dtype=torch.float64)
    inputs[..., 0] = 17.95
    inputs[:, :, 1] = torch.tensor([0.0, math.radians(20), math.radians(-35)])
    traj = integrate(model, x0, inputs, 1.0, "rk4")
    grads = torch.autograd.grad(traj[-1, :, 5].sum(), list(model.parameters()))
    assert all(torch.isfinite(g) and g != 0 for g in grads)
    assert traj[-1, 0, 5] == 0 and traj[-1, 1, 5] > 0 > traj[-1, 2, 5]  # no rudder, no turn
    # zero speed and zero revolutions: finite forces
    f = model(torch.zeros(1, 6, dtype=torch.float64), torch.zeros(1, 4, dtype=torch.float64))
    assert torch.isfinite(f.total).all()
    f32 = MMG(ship, dtype=torch.float32)(x0.float(), inputs[0].float()).total
    f64 = MMG(ship)(x0, inputs[0]).total
    assert torch.allclose(f32.double(), f64, rtol=1e-5, atol=1e-3)
