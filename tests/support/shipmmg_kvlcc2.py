"""KVLCC2 L7 as shipmmg sees it, for the tests that run shipmmg as an independent simulator:
the ship file with shipmmg's conventions and shipmmg's parameter objects for it
(tests/mmg/test_shipmmg_kvlcc2.py documents the conventions)."""
from __future__ import annotations

from sysid.mmg.ship import load_ship, ships_dir

U0, NPS = 2.29 * 0.512, 17.95  # shipmmg's example operating point: u0 [m/s], propeller [rps]


def ship_like_shipmmg(tmp_path, x_G: float):
    """kvlcc2_l7 with shipmmg's wake form and x'_P, and the given x_G [m]."""
    text = (ships_dir() / "kvlcc2_l7.toml").read_text()
    for old, new in [('model = "standard"  # differs', 'model = "standard_gaussian_wake"  # differs'),
                     ("x_P = -0.48 ", "x_P = -0.650 "), ("x_G = 0.25 ", f"x_G = {x_G!r} ")]:
        assert old in text, old
        text = text.replace(old, new, 1)
    text = "\n".join(line for line in text.splitlines() if not line.startswith(("C_1 ", "C_2_")))
    path = tmp_path / f"kvlcc2_shipmmg_xg{x_G}.toml"
    path.write_text(text)
    return load_ship(path)


def shipmmg_params(ship):
    """shipmmg's (basic, maneuvering) parameter objects of a ship of the standard families."""
    from shipmmg import mmg_3dof

    p = ship.parameters
    basic = mmg_3dof.Mmg3DofBasicParams(
        L_pp=p["L_pp"], B=p["B"], d=p["d"], x_G=p["x_G"], D_p=p["D"], m=p["m"],
        I_zG=p["I_zz_J_zz"], J_z=0.0,  # only their sum enters the equations of motion
        A_R=p["A_R"], η=p["D"] / p["H_R"], m_x=p["m_x"], m_y=p["m_y"], f_α=p["f_alpha"],
        ϵ=p["epsilon"], t_R=p["t_R"], x_R=p["x_R"], a_H=p["a_H"], x_H=p["x_H"],
        γ_R_minus=p["gamma_R_minus"], γ_R_plus=p["gamma_R_plus"], l_R=p["l_R"] / p["L_pp"],
        κ=p["kappa"], t_P=p["t_P"], w_P0=p["w_P0"], x_P=p["x_P"])
    names = ["R_0", "X_vv", "X_vr", "X_rr", "X_vvvv", "Y_v", "Y_r", "Y_vvv", "Y_vvr", "Y_vrr",
             "Y_rrr", "N_v", "N_r", "N_vvv", "N_vvr", "N_vrr", "N_rrr"]
    maneuvering = mmg_3dof.Mmg3DofManeuveringParams(
        k_0=p["k0"], k_1=p["k1"], k_2=p["k2"], **{f"{n}_dash": p[n] for n in names})
    return basic, maneuvering
