"""Ship definitions: the bundled TOML, validation errors, overrides."""
import math

import pytest

from sysid.errors import ShipDefinitionError
from sysid.mmg.ship import load_ship, parse_overrides

ROOT_TOML = "configs/ships/esso_osaka.toml"


def test_esso_osaka_values_match_the_lab_spec():
    ship = load_ship("esso_osaka")
    # MMG_SPEC §1: 0.5 rho L^2 d = 903.31974 kg; m' = 0.27078 -> 244.601 kg (paper: 244.6 kg)
    q = 0.5 * ship["rho"] * ship["L_pp"] ** 2 * ship["d"]
    assert q == pytest.approx(903.31974, rel=1e-12)
    assert ship["m"] / q == pytest.approx(0.27078, rel=1e-12)
    assert ship["I_zz_J_zz"] / (q * ship["L_pp"] ** 2) == pytest.approx(0.0286, rel=1e-12)
    assert ship["X_vr"] == -0.0081 and ship["x_P"] == -0.517 and ship["B1"] == 3.5e-5
    assert math.dist(ship.sensors.gnss_fore, ship.sensors.gnss_aft) == pytest.approx(2.40)
    assert ship.sensors.anemometer_2 == (-0.60, 0.0)


def test_override_by_any_spelling_and_immutability():
    base = load_ship("esso_osaka")
    for key in ("Xvr", "X_vr", "X'vr"):
        assert load_ship("esso_osaka", {key: 0.4535})["X_vr"] == 0.4535
    assert parse_overrides(["Xvr=0.4535", "Y_v=-0.3"]) == {"X_vr": 0.4535, "Y_v": -0.3}
    with pytest.raises(TypeError):
        base.parameters["X_vr"] = 1.0  # read-only mapping
    assert base["X_vr"] == -0.0081


@pytest.mark.parametrize("overrides, message", [
    ({"Q": 1.0}, "unknown ship parameter 'Q'"),
    ({"t_P": 1.5}, "t_P = 1.5 is out of range"),
    ({"m": float("nan")}, "m: value must be finite"),
])
def test_bad_override_is_one_clear_error(overrides, message):
    with pytest.raises(ShipDefinitionError, match=message):
        load_ship("esso_osaka", overrides)


def test_unknown_ship_names_the_known_ones():
    with pytest.raises(ShipDefinitionError, match="unknown ship 'titanic'.*esso_osaka"):
        load_ship("titanic")


def _edited(tmp_path, old, new):
    text = open(load_ship("esso_osaka").source).read()
    assert old in text
    path = tmp_path / "ship.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_missing_key_names_file_section_and_key(tmp_path):
    path = _edited(tmp_path, "Y_r = 0.116", "")
    with pytest.raises(ShipDefinitionError, match=r"ship.toml: \[hull\] Y_r is missing"):
        load_ship(path)


def test_out_of_range_and_wrong_type(tmp_path):
    with pytest.raises(ShipDefinitionError, match=r"\[principal\] L_pp = -3.0 is out of range"):
        load_ship(_edited(tmp_path, "L_pp = 3.0", "L_pp = -3.0"))
    with pytest.raises(ShipDefinitionError, match=r"\[rudder\] A_R: expected a number"):
        load_ship(_edited(tmp_path, "A_R = 0.01063", 'A_R = "big"'))


def test_bad_sensor_geometry(tmp_path):
    with pytest.raises(ShipDefinitionError, match="gnss_baseline"):
        load_ship(_edited(tmp_path, "gnss_baseline = 2.40", "gnss_baseline = 3.40"))
