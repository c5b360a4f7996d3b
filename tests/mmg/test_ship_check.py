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


def _linearised_hull_is_unstable(ship) -> bool:
    """Independent of C': the eigenvalues of d(v_dot, r_dot)/d(v, r) of the hull force alone
    (rudder fixed at zero, no propeller side force) in the equations of motion, at 1 m/s ahead."""
    import torch

    from sysid.dynamics.equations import acceleration_channels
    from sysid.mmg import MMG

    mmg = MMG(ship)
    c, u = mmg.coefficients, torch.tensor(1.0, dtype=torch.float64)

    def sway_yaw(v, r):
        X, Y, N = mmg.families["hull"].force(u, v, r, c, "exact")
        return torch.stack(acceleration_channels(u, v, r, X, Y, N, c)[1:])

    zero = torch.tensor(0.0, dtype=torch.float64)
    jac = torch.stack(torch.autograd.functional.jacobian(sway_yaw, (zero, zero)), -1)  # (2, 2)
    return bool(torch.linalg.eigvals(jac).real.max() > 0)


@pytest.mark.parametrize("name, overrides", [("esso_osaka", {}), ("kvlcc2_l7", {}),
                                             ("esso_osaka", {"N_r": -0.2}), ("kvlcc2_l7", {"N_r": -0.2})])
def test_course_stability_verdict_agrees_with_the_linearised_hull(name, overrides):
    ship = load_ship(name, overrides)
    check = check_ship(ship)
    index = dict((label.split(" = ")[0], value) for label, value, _ in check.quantities)[
        "hull course-stability index C'"]
    unstable = _linearised_hull_is_unstable(ship)
    assert unstable == (index < 0)
    verdict = check.verdicts[0]
    assert ("course-unstable" in verdict) == unstable and ("course-stable" in verdict) != unstable
    assert f"{index:.3g}" in verdict
    if unstable:  # never "no warnings" after an unstable hull
        assert "no warnings" not in check.text() and any("course-unstable" in w for w in check.warnings)


def test_esso_osaka_course_stability_index_from_its_published_non_dimensional_values():
    # m' 0.27078, m'_x 0.0467, x'_G 0.03119 and Y'v, Y'r, N'v, N'r of the ship file's comments
    expected = -0.3728 * (-0.04849 - 0.27078 * 0.03119) - (-0.1458) * (0.116 - 0.27078 - 0.0467)
    check = check_ship(load_ship("esso_osaka"))
    index = [v for label, v, _ in check.quantities if label.startswith("hull course-stability index")][0]
    assert index == pytest.approx(expected, rel=1e-3)
    assert check.verdicts == [f"course stability: C' = {expected:.3g} < 0: the bare hull is course-unstable"]
