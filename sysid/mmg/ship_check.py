"""What a validated ship implies: derived quantities a naval architect checks at a glance,
and warnings for values that are legal but unusual (``sysid ship check FILE``).

Non-dimensional forms use 0.5 rho L_pp^2 d (masses), 0.5 rho L_pp^4 d (inertia) and L_pp
(lengths), as in the MMG literature.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from sysid.mmg.ship import Ship


@dataclass
class ShipCheck:
    """quantities : (label, value, unit) rows; verdicts : what a value means, one sentence
    each (course stability); warnings : one sentence each."""

    ship: Ship
    quantities: list[tuple[str, float, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    verdicts: list[str] = field(default_factory=list)

    def text(self) -> str:
        lines = [f"ship {self.ship.name!r} from {self.ship.source}",
                 "models: " + self.ship.describe_models() + ("" if self.ship.has_wind else " (no wind)"),
                 f"{len(self.ship.parameters)} parameters, all within their ranges", ""]
        width = max(len(label) for label, _, _ in self.quantities)
        lines += [f"  {label:<{width}}  {value:.6g} {unit}".rstrip() for label, value, unit in self.quantities]
        lines.append("")
        lines += self.verdicts
        lines += [f"warning: {w}" for w in self.warnings] or ["no warnings"]
        return "\n".join(lines)


def course_stability_verdict(index: float) -> str:
    """The hull's straight-line stability in words, from C' (`check_ship`)."""
    if index > 0:
        return f"course stability: C' = {index:.3g} > 0: the bare hull is course-stable"
    return f"course stability: C' = {index:.3g} {'<' if index < 0 else '='} 0: the bare hull is course-unstable"


def check_ship(ship: Ship) -> ShipCheck:
    """Derived quantities and warnings for `ship` (already validated by `load_ship`)."""
    out = ShipCheck(ship)
    _check_hull(ship.parameters, out)
    _check_propeller(ship.parameters, out)
    _check_rudder(ship.parameters, out)
    if not ship.has_wind:
        out.warnings.append("no [wind] section: wind forces are zero (fine for tank tests and calm water)")
    return out


def _check_hull(p: Mapping[str, float], out: ShipCheck) -> None:
    """The hull's masses (non-dimensional by 1/2 rho L^2 d and 1/2 rho L^4 d), block
    coefficient and course stability into `out`."""
    add, warn = out.quantities.append, out.warnings.append
    L, d, B, rho = p["L_pp"], p["d"], p["B"], p["rho"]
    q_mass, q_inertia = 0.5 * rho * L * L * d, 0.5 * rho * L ** 4 * d
    m_nd, mx_nd, my_nd = p["m"] / q_mass, p["m_x"] / q_mass, p["m_y"] / q_mass
    xG_nd = p["x_G"] / L
    block = p["m"] / (rho * L * B * d)
    add(("block coefficient C_b = m / (rho L B d)", block, ""))
    add(("m'", m_nd, ""))
    add(("m'_x, m'_y", mx_nd, f"/ {my_nd:.6g}"))
    add(("(I_zz + J_zz)'", p["I_zz_J_zz"] / q_inertia, ""))
    add(("x'_G", xG_nd, ""))
    if not 0.3 <= block <= 1.0:
        warn(f"block coefficient {block:.3g} is outside [0.3, 1.0]: check m, rho, L_pp, B, d")
    if p["m_x"] > p["m"] or p["m_y"] > 2.0 * p["m"]:
        warn("added masses are large against the ship's mass: check [mass] m_x, m_y (kg, not non-dimensional)")
    # straight-line (course) stability of the hull alone, rudder fixed at zero, from the
    # linearised sway-yaw equations (Y - (m + m_x) u r, N - m x_G u r; sysid.dynamics):
    # with the usual signs (Y'v < 0, N'r - m'x'_G < 0) the course is stable when C' > 0
    Yv, Yr, Nv, Nr = p["Y_v"], p["Y_r"], p["N_v"], p["N_r"]
    stability = Yv * (Nr - m_nd * xG_nd) - Nv * (Yr - m_nd - mx_nd)
    add(("hull course-stability index C' = Y'v (N'r - m'x'_G) - N'v (Y'r - m' - m'_x)", stability, ""))
    out.verdicts.append(course_stability_verdict(stability))
    if stability <= 0:
        warn(f"course-unstable bare hull: usual for full hull forms such as tankers (C_b = {block:.2f} here), "
             "which the rudder keeps on course; if this ship is known to be course-stable, check [hull] Y_v, Y_r, "
             "N_v, N_r and [mass] m, m_x, x_G")
    if Yv > 0 or Nr > 0:
        warn("Y'v > 0 or N'r > 0: sway and yaw damping of the hull should be negative")


def _check_propeller(p: Mapping[str, float], out: ShipCheck) -> None:
    """The propeller's bollard thrust coefficient, zero-thrust advance ratio and diameter against the draft."""
    add, warn = out.quantities.append, out.warnings.append
    d = p["d"]
    D = p["D"]
    add(("propeller K_T at J = 0", p["k0"], ""))
    disc = p["k1"] ** 2 - 4 * p["k2"] * p["k0"]
    if p["k2"] != 0 and disc >= 0:
        roots = [(-p["k1"] + s * math.sqrt(disc)) / (2 * p["k2"]) for s in (1, -1)]
        positive = [r for r in roots if r > 0]
        if positive:
            add(("advance ratio of zero thrust J_0", min(positive), ""))
    if p["k0"] <= 0:
        warn("K_T(0) = k0 <= 0: the propeller gives no bollard thrust")
    add(("propeller diameter / draft", D / d, ""))
    if D > d:
        warn(f"propeller diameter {D} m exceeds the draft {d} m")


def _check_rudder(p: Mapping[str, float], out: ShipCheck) -> None:
    """The rudder's height, area and position against the hull's (x_R in metres from midship)."""
    add, warn = out.quantities.append, out.warnings.append
    L, d, D = p["L_pp"], p["d"], p["D"]
    if "H_R" in p:
        H_R = p["H_R"]
        add(("eta = D / H_R", D / H_R, ""))
    else:
        H_R = math.sqrt(p["A_R"] * p["lambda_R"])
        add(("H_R = sqrt(A_R lambda_R)", H_R, "m"))
        add(("eta = D / H_R", D / H_R, ""))
        add(("kappa = k_x / epsilon", p["k_x"] / p["epsilon"], ""))
        add(("f_alpha (Fujii)", 6.13 * p["lambda_R"] / (2.25 + p["lambda_R"]), ""))
    add(("A_R / (L_pp d)", p["A_R"] / (L * d), ""))
    add(("x'_R, x'_H", p["x_R"] / L, f"/ {p['x_H'] / L:.6g}"))
    if p["x_R"] < -0.6 * L or p["x_R"] > -0.2 * L:
        warn(f"x_R = {p['x_R']} m is not near the stern (x'_R = {p['x_R'] / L:.3g}): "
             "x_R is in metres from midship, not a fraction of L_pp")
    if not 0.01 <= p["A_R"] / (L * d) <= 0.05:
        warn(f"rudder area ratio A_R/(L d) = {p['A_R'] / (L * d):.3g} is outside the usual 1/100 .. 1/20")
