"""Force-model families a ship file chooses from (``[hull] model = "standard"`` ...).

Each family is one module of `sysid.mmg` behind one interface per component:

* hull: ``force(u, v, r, c, quadrature) -> (X, Y, N)``
* propeller: ``inflow(u, v, r, n, c) -> PropellerState`` (read by every rudder family) and
  ``force(u, v, r, n, c, inflow) -> (X, Y, N)``
* rudder: ``force(u, v, r, n, delta, c, propeller_inflow) -> (X, Y, N)``
* wind (optional section): ``force(U_A, gamma_A, c) -> (X, Y, N)``

and a table ``parameters``: name -> (section of the ship file, low, high), the keys the
family needs. Units: u, v [m/s], r [rad/s], n [rps], delta [rad]; X, Y [N], N [N m].
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable, Mapping

from sysid.mmg import hull, hull_standard, propeller, propeller_standard, rudder, rudder_standard, wind

COMPONENTS = ("hull", "propeller", "rudder", "wind")
OPTIONAL_COMPONENTS = ("wind",)

# the families of the Esso Osaka, used when a section names no model (files before issue 12)
DEFAULT_MODELS = {"hull": "yoshimura_low_speed", "propeller": "four_quadrant",
                  "rudder": "four_quadrant", "wind": "fujiwara"}


@dataclass(frozen=True)
class ForceFamily:
    """One force model of one component.

    component : "hull", "propeller", "rudder" or "wind".
    name : the value of ``model = ...`` in the ship file.
    parameters : name -> (section, low, high) of every key it needs.
    force : the force function (signature by component, see the module docstring).
    inflow : the propeller's inflow function (propeller families only).
    summary : one line for messages and ``sysid ship check``.
    """

    component: str
    name: str
    parameters: Mapping[str, tuple[str, float, float]]
    force: Callable
    summary: str
    inflow: Callable | None = None


def _hull_standard(u, v, r, c, quadrature="exact"):
    return hull_standard.hull_force_standard(u, v, r, c)


_FAMILIES = [
    ForceFamily("hull", "yoshimura_low_speed", hull.PARAMETERS, hull.hull_force,
                "Yoshimura's unified low-speed hull with cross-flow drag (Esso Osaka)"),
    ForceFamily("hull", "standard", hull_standard.PARAMETERS, _hull_standard,
                "standard MMG polynomial hull derivatives (Yasukawa & Yoshimura 2015)"),
    ForceFamily("propeller", "four_quadrant", propeller.PARAMETERS, propeller.propeller_force,
                "four-quadrant propeller: K_T polynomial ahead, CMT polynomials astern (Esso Osaka)",
                propeller.propeller_inflow),
    ForceFamily("propeller", "standard",
                {**propeller_standard.PARAMETERS, **propeller_standard.WAKE_PARAMETERS},
                partial(propeller_standard.propeller_force_standard, wake=propeller_standard.wake_yasukawa),
                "standard MMG thrust, K_T(J_P), wake w_P0 with the C_1/C_2 drift correction",
                partial(propeller_standard.propeller_inflow_standard, wake=propeller_standard.wake_yasukawa)),
    ForceFamily("propeller", "standard_gaussian_wake", propeller_standard.PARAMETERS,
                partial(propeller_standard.propeller_force_standard, wake=propeller_standard.wake_gaussian),
                "standard MMG thrust, wake w_P0 exp(-4 beta_P^2) (shipmmg's form)",
                partial(propeller_standard.propeller_inflow_standard, wake=propeller_standard.wake_gaussian)),
    ForceFamily("rudder", "four_quadrant", rudder.PARAMETERS, rudder.rudder_force,
                "Yoshimura low-speed / Kitagawa reverse-rotation rudder inflow, Fujii f_alpha (Esso Osaka)"),
    ForceFamily("rudder", "standard", rudder_standard.PARAMETERS, rudder_standard.rudder_force_standard,
                "standard MMG rudder (Yasukawa & Yoshimura 2015)"),
    ForceFamily("wind", "fujiwara", wind.PARAMETERS, wind.wind_force,
                "Fujiwara's wind-force regression"),
]

FAMILIES: dict[str, dict[str, ForceFamily]] = {c: {} for c in COMPONENTS}
for _family in _FAMILIES:
    FAMILIES[_family.component][_family.name] = _family


def family(component: str, name: str) -> ForceFamily:
    """The family `name` of `component`; KeyError if unknown."""
    return FAMILIES[component][name]


def known_models(component: str) -> list[str]:
    return sorted(FAMILIES[component])
