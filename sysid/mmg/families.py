"""Force-model families a ship file chooses from (``[hull] model = "standard"`` ...).

Each family is one module of `sysid.mmg` behind one interface per component:

* hull: ``force(u, v, r, c, quadrature) -> (X, Y, N)``
* propeller: ``inflow(u, v, r, n, c) -> PropellerState`` (read by every rudder family) and
  ``force(u, v, r, n, c, inflow) -> (X, Y, N)``
* rudder: ``force(u, v, r, n, delta, c, propeller_inflow) -> (X, Y, N)``
* wind (optional section): ``force(U_A, gamma_A, c) -> (X, Y, N)``

and the same on one forward's shared `sysid.mmg.motion.Motion` (what `MMG` calls: speed and
drift angle computed once, forces as one (..., 3) tensor): ``forces(motion, c[, quadrature |
inflow]) -> (..., 3)`` and, for propellers, ``inflow_of(motion, c) -> PropellerState``
(wind: ``forces(U_A, gamma_A, c) -> (..., 3)``),

and a table ``parameters``: name -> (section of the ship file, low, high), the keys the
family needs. Units: u, v [m/s], r [rad/s], n [rps], delta [rad]; X, Y [N], N [N m].

The tables live here and the force functions are imported on first use, so that ship files
(and experiment configs naming their keys) are read and checked without torch.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Callable, Mapping

COMPONENTS = ("hull", "propeller", "rudder", "wind")
OPTIONAL_COMPONENTS = ("wind",)

# the families of the Esso Osaka, used when a section names no model (files before issue 12)
DEFAULT_MODELS = {"hull": "yoshimura_low_speed", "propeller": "four_quadrant",
                  "rudder": "four_quadrant", "wind": "fujiwara"}

Table = Mapping[str, tuple[str, float, float]]  # name -> (section, low, high)

# Yoshimura's low-speed hull (`sysid.mmg.hull`)
YOSHIMURA_HULL: Table = {
    "X_0F": ("hull", -1.0, 0.0),   # -, resistance coefficient, ahead
    "X_0A": ("hull", -1.0, 0.0),   # -, resistance coefficient, astern
    "X_vr": ("hull", -2.0, 2.0),
    "Y_v": ("hull", -5.0, 5.0),
    "Y_r": ("hull", -5.0, 5.0),
    "N_v": ("hull", -5.0, 5.0),
    "N_r": ("hull", -5.0, 5.0),
    "C_D": ("hull", 0.0, 5.0),     # -, cross-flow drag coefficient
    "C_rY": ("hull", 0.0, 10.0),   # -, cross-flow correction, force
    "C_rN": ("hull", 0.0, 10.0),   # -, cross-flow correction, moment
}

# standard MMG hull (`sysid.mmg.hull_standard`); dimensionless derivatives (the prime is dropped)
STANDARD_HULL: Table = {
    "R_0": ("hull", 0.0, 1.0),
    **{name: ("hull", -20.0, 20.0) for name in (
        "X_vv", "X_vr", "X_rr", "X_vvvv",
        "Y_v", "Y_r", "Y_vvv", "Y_vvr", "Y_vrr", "Y_rrr",
        "N_v", "N_r", "N_vvv", "N_vvr", "N_vrr", "N_rrr")},
}

# four-quadrant propeller (`sysid.mmg.propeller`)
FOUR_QUADRANT_PROPELLER: Table = {
    "D": ("propeller", 1e-3, 20.0),     # m, diameter
    "P": ("propeller", 1e-3, 40.0),     # m, pitch
    "t_P": ("propeller", 0.0, 0.99),
    "w_P0": ("propeller", 0.0, 0.99),
    "tau": ("propeller", -10.0, 10.0),
    "C_P": ("propeller", -10.0, 10.0),
    "x_P": ("propeller", -1.0, 1.0),    # -, x'_P = x_P / L_pp
    "k0": ("propeller", -5.0, 5.0),
    "k1": ("propeller", -5.0, 5.0),
    "k2": ("propeller", -5.0, 5.0),
    **{f"A{i}": ("propeller", -1.0, 1.0) for i in range(1, 9)},
    **{f"B{i}": ("propeller", -1.0, 1.0) for i in range(1, 9)},
    "C3": ("propeller", -5.0, 5.0),
    "C6": ("propeller", -5.0, 5.0),
    "C7": ("propeller", -5.0, 5.0),
    "C10": ("propeller", -10.0, 10.0),
}

# standard MMG propeller (`sysid.mmg.propeller_standard`)
STANDARD_PROPELLER: Table = {
    "D": ("propeller", 1e-3, 20.0),      # m, diameter
    "t_P": ("propeller", 0.0, 0.99),     # -, thrust deduction
    "w_P0": ("propeller", 0.0, 0.99),    # -, wake fraction in straight motion
    "x_P": ("propeller", -1.0, 1.0),     # -, x'_P = x_P / L_pp (negative: aft)
    "k0": ("propeller", -5.0, 5.0),      # -, K_T polynomial
    "k1": ("propeller", -5.0, 5.0),
    "k2": ("propeller", -5.0, 5.0),
}
# the wake's drift correction of the standard propeller (Yasukawa's C_1, C_2)
STANDARD_WAKE: Table = {
    "C_1": ("propeller", 0.0, 100.0),       # -, wake change rate with |beta_P|
    "C_2_plus": ("propeller", 0.0, 10.0),   # -, asymptotic (1-w_P)/(1-w_P0), beta_P > 0
    "C_2_minus": ("propeller", 0.0, 10.0),  # -, same for beta_P <= 0
}

# four-quadrant (low-speed) rudder (`sysid.mmg.rudder`)
FOUR_QUADRANT_RUDDER: Table = {
    "A_R": ("rudder", 1e-6, 1e3),       # m^2
    "lambda_R": ("rudder", 0.1, 10.0),  # -, aspect ratio
    "epsilon": ("rudder", 0.1, 5.0),
    "k_x": ("rudder", 0.0, 5.0),
    "k_xPR": ("rudder", 0.0, 5.0),
    "C_PR": ("rudder", -5.0, 5.0),
    "x_R": ("rudder", -1e3, 0.0),       # m
    "l_R": ("rudder", -1e3, 1e3),       # m
    "gamma_P": ("rudder", 0.0, 5.0),
    "gamma_N": ("rudder", 0.0, 5.0),
    "t_R": ("rudder", 0.0, 0.99),
    "a_H": ("rudder", -1.0, 5.0),
    "x_H": ("rudder", -1e3, 1e3),       # m
}

# standard MMG rudder (`sysid.mmg.rudder_standard`)
STANDARD_RUDDER: Table = {
    "A_R": ("rudder", 1e-6, 1e3),            # m^2, rudder area
    "H_R": ("rudder", 1e-4, 1e2),            # m, rudder span (eta = D / H_R)
    "f_alpha": ("rudder", 0.0, 10.0),        # -, normal-force gradient
    "epsilon": ("rudder", 0.1, 5.0),         # -, wake ratio rudder / propeller
    "kappa": ("rudder", 0.0, 5.0),           # -, propeller-race factor
    "x_R": ("rudder", -1e3, 0.0),            # m, rudder position (aft: negative)
    "l_R": ("rudder", -1e3, 1e3),            # m, effective lever in beta_R (l'_R L_pp)
    "gamma_R_minus": ("rudder", 0.0, 5.0),   # -, flow straightening, beta_R < 0
    "gamma_R_plus": ("rudder", 0.0, 5.0),    # -, flow straightening, beta_R >= 0
    "t_R": ("rudder", 0.0, 0.99),            # -, steering resistance deduction
    "a_H": ("rudder", -1.0, 5.0),            # -, rudder force increase factor
    "x_H": ("rudder", -1e3, 1e3),            # m, acting point of a_H F_N
}

# Fujiwara's wind regression (`sysid.mmg.wind`); rho_air sits in [principal]
FUJIWARA_WIND: Table = {
    "rho_air": ("principal", 0.5, 2.0),  # kg/m^3
    "A_T": ("wind", 0.0, 1e5),           # m^2, transverse projected area
    "A_L": ("wind", 0.0, 1e6),           # m^2, lateral projected area
    "L_wind": ("wind", 1e-3, 1e3),       # m, moment lever
    **{k: ("wind", -10.0, 10.0) for k in ("X0", "X1", "X3", "X5", "Y1", "Y3", "Y5", "N1", "N2", "N3")},
}

Functions = tuple[Callable, "Callable | None", Callable, "Callable | None"]  # (force, inflow, forces, inflow_of)


@dataclass(frozen=True)
class ForceFamily:
    """One force model of one component.

    component : "hull", "propeller", "rudder" or "wind".
    name : the value of ``model = ...`` in the ship file.
    parameters : name -> (section, low, high) of every key it needs.
    summary : one line for messages and ``sysid ship check``.
    functions : imports the family's module (torch) and gives (force, inflow, forces,
        inflow_of); called on first use of any of them.
    force : the force function (signature by component, see the module docstring).
    inflow : the propeller's inflow function (propeller families only, else None).
    forces, inflow_of : the same on a `Motion`, forces as (..., 3).
    """

    component: str
    name: str
    parameters: Table
    summary: str
    functions: Callable[[], Functions] = field(repr=False, compare=False)

    @functools.cached_property
    def force(self) -> Callable:
        return self.functions()[0]

    @functools.cached_property
    def inflow(self) -> Callable | None:
        return self.functions()[1]

    @functools.cached_property
    def forces(self) -> Callable:
        return self.functions()[2]

    @functools.cached_property
    def inflow_of(self) -> Callable | None:
        return self.functions()[3]


def _yoshimura_hull() -> Functions:
    from sysid.mmg import hull
    return hull.hull_force, None, hull.hull_forces, None


def _standard_hull() -> Functions:
    from sysid.mmg import hull_standard

    def force(u, v, r, c, quadrature="exact"):  # no cross-flow integral: quadrature unused
        return hull_standard.hull_force_standard(u, v, r, c)

    def forces(motion, c, quadrature="exact"):
        return hull_standard.hull_forces_standard(motion, c)
    return force, None, forces, None


def _four_quadrant_propeller() -> Functions:
    from sysid.mmg import propeller
    return propeller.propeller_force, propeller.propeller_inflow, propeller.propeller_forces, propeller.inflow_of


def _standard_propeller(wake: str) -> Functions:
    from sysid.mmg import propeller_standard as p
    wake_fn = getattr(p, wake)
    return (functools.partial(p.propeller_force_standard, wake=wake_fn),
            functools.partial(p.propeller_inflow_standard, wake=wake_fn),
            p.propeller_forces_standard,
            functools.partial(p.inflow_standard_of, wake=wake_fn))


def _four_quadrant_rudder() -> Functions:
    from sysid.mmg import rudder
    return rudder.rudder_force, None, rudder.rudder_forces, None


def _standard_rudder() -> Functions:
    from sysid.mmg import rudder_standard
    return rudder_standard.rudder_force_standard, None, rudder_standard.rudder_forces_standard, None


def _fujiwara_wind() -> Functions:
    from sysid.mmg import wind
    return wind.wind_force, None, wind.wind_forces, None


_FAMILIES = [
    ForceFamily("hull", "yoshimura_low_speed", YOSHIMURA_HULL,
                "Yoshimura's unified low-speed hull with cross-flow drag (Esso Osaka)", _yoshimura_hull),
    ForceFamily("hull", "standard", STANDARD_HULL,
                "standard MMG polynomial hull derivatives (Yasukawa & Yoshimura 2015)", _standard_hull),
    ForceFamily("propeller", "four_quadrant", FOUR_QUADRANT_PROPELLER,
                "four-quadrant propeller: K_T polynomial ahead, CMT polynomials astern (Esso Osaka)",
                _four_quadrant_propeller),
    ForceFamily("propeller", "standard", {**STANDARD_PROPELLER, **STANDARD_WAKE},
                "standard MMG thrust, K_T(J_P), wake w_P0 with the C_1/C_2 drift correction",
                functools.partial(_standard_propeller, "wake_yasukawa")),
    ForceFamily("propeller", "standard_gaussian_wake", STANDARD_PROPELLER,
                "standard MMG thrust, wake w_P0 exp(-4 beta_P^2) (shipmmg's form)",
                functools.partial(_standard_propeller, "wake_gaussian")),
    ForceFamily("rudder", "four_quadrant", FOUR_QUADRANT_RUDDER,
                "Yoshimura low-speed / Kitagawa reverse-rotation rudder inflow, Fujii f_alpha (Esso Osaka)",
                _four_quadrant_rudder),
    ForceFamily("rudder", "standard", STANDARD_RUDDER,
                "standard MMG rudder (Yasukawa & Yoshimura 2015)", _standard_rudder),
    ForceFamily("wind", "fujiwara", FUJIWARA_WIND, "Fujiwara's wind-force regression", _fujiwara_wind),
]

FAMILIES: dict[str, dict[str, ForceFamily]] = {c: {} for c in COMPONENTS}
for _family in _FAMILIES:
    FAMILIES[_family.component][_family.name] = _family


def family(component: str, name: str) -> ForceFamily:
    """The family `name` of `component`, its functions loaded (imports torch); KeyError if
    unknown."""
    found = FAMILIES[component][name]
    found.force, found.inflow, found.forces, found.inflow_of  # noqa: B018 (load the functions now, not inside a traced call)
    return found
