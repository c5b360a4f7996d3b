"""A standard-MMG ship written from scratch, checked by ``sysid ship check``."""
import pytest

from sysid.cli import run
from sysid.errors import ShipDefinitionError
from sysid.mmg.ship import load_ship
from sysid.mmg.ship_check import check_ship

from scratch_ship import SCRATCH



def test_check_prints_derived_quantities_and_catches_a_fractional_x_R(tmp_path, capsys):
    path = tmp_path / "scratch_tanker.toml"
    path.write_text(SCRATCH)
    run(["ship", "check", str(path)])
    text = capsys.readouterr().out
    q = 0.5 * 1000.0 * 4.0 ** 2 * 0.26  # 2080 kg
    check = check_ship(load_ship(path))
    values = {label: value for label, value, _ in check.quantities}
    assert values["m'"] == pytest.approx(600.0 / q, rel=1e-12)
    assert values["block coefficient C_b = m / (rho L B d)"] == pytest.approx(600.0 / (1000 * 4.0 * 0.72 * 0.26))
    assert values["eta = D / H_R"] == pytest.approx(0.12 / 0.19)
    # K_T(J_0) = 0 at the printed advance ratio
    J0 = values["advance ratio of zero thrust J_0"]
    assert 0.2931 - 0.2753 * J0 - 0.1385 * J0 ** 2 == pytest.approx(0.0, abs=1e-12)
    assert "models: hull 'standard', propeller 'standard', rudder 'standard' (no wind)" in text
    assert "x_R = -0.5 m is not near the stern" in text  # the user wrote x'_R, not metres
    assert "no [wind] section" in text


def test_check_bad_file_is_one_clear_error(tmp_path):
    path = tmp_path / "scratch_tanker.toml"
    path.write_text(SCRATCH.replace("kappa = 0.5\n", ""))
    with pytest.raises(ShipDefinitionError, match=r"scratch_tanker.toml: \[rudder\] kappa is missing"):
        run(["ship", "check", str(path)])
