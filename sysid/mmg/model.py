"""The MMG force model: hull + propeller + rudder + wind, every component by name.

Each component is computed by the force-model family the ship file chose
(`sysid.mmg.families`); a ship without a [wind] section has a zero wind force.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

import torch
from torch import nn

from sysid.errors import ShipDefinitionError
from sysid.mmg.coefficients import Coefficients
from sysid.mmg.families import family
from sysid.mmg.wind import relative_wind
from sysid.mmg.ship import Ship


@dataclass
class ForceBreakdown:
    """Forces by component, each (..., 3) = (X [N], Y [N], N [N m] about midship).

    ``correction`` is the FNN term (zeros for MMG-only); ``relative_wind`` is (..., 2)
    = (U_A [m/s], gamma_A [rad]) as seen with the state the forces were computed for.
    """

    hull: torch.Tensor
    propeller: torch.Tensor
    rudder: torch.Tensor
    wind: torch.Tensor
    correction: torch.Tensor
    relative_wind: torch.Tensor
    ood_distance: torch.Tensor | None = None  # (...,) kNN distance, None without a gate
    gate_on: torch.Tensor | None = None       # (...,) True where F_NN is applied

    @property
    def mmg(self) -> torch.Tensor:
        """F_MMG = hull + propeller + rudder + wind."""
        return self.hull + self.propeller + self.rudder + self.wind

    @property
    def total(self) -> torch.Tensor:
        """F_MMG + F_NN, the right-hand side of the maneuvering equations."""
        return self.mmg + self.correction


class MMG(nn.Module):
    """Batched, differentiable MMG model (paper Appendix A; docs: MMG equations).

    Parameters
    ----------
    ship : validated ship definition.
    trainable : coefficient names to expose as parameters (gradient identification).
    bounds : ``{name: (low, high)}`` for trainable coefficients.
    dtype : float64 (default) or float32.
    quadrature : cross-flow integrals of the Yoshimura hull, "exact" (closed form, default)
        or "simpson" (the lab simulator's 100-point rule, to reproduce it to round-off).
    """

    def __init__(self, ship: Ship, trainable: Iterable[str] = (),
                 bounds: Mapping[str, tuple[float, float]] | None = None,
                 dtype: torch.dtype = torch.float64, quadrature: str = "exact"):
        super().__init__()
        if quadrature not in ("exact", "simpson"):
            raise ValueError(f"quadrature {quadrature!r}: choose 'exact' or 'simpson'")
        if quadrature == "simpson" and ship.models["hull"] != "yoshimura_low_speed":
            raise ShipDefinitionError(f"ship {ship.name!r}: quadrature 'simpson' applies to the "
                                      f"yoshimura_low_speed hull only, not to hull model {ship.models['hull']!r}")
        self.ship = ship
        self.quadrature = quadrature
        self.families = {component: family(component, name) for component, name in ship.models.items()}
        self.coefficients = Coefficients(ship, trainable, bounds, dtype)

    def components(self, state: torch.Tensor, inputs: torch.Tensor):
        """((X, Y, N) of hull, propeller, rudder, wind or None), relative wind: each (...,)."""
        c = self.coefficients.values_view(state.dtype)  # constants and derived constants, cached
        _, u, _, v, psi, r = state.unbind(-1)
        n, delta, U_T, zeta = inputs.unbind(-1)
        families = self.families
        hull = families["hull"].force(u, v, r, c, self.quadrature)
        prop_state = families["propeller"].inflow(u, v, r, n, c)
        propeller = families["propeller"].force(u, v, r, n, c, prop_state)
        rudder = families["rudder"].force(u, v, r, n, delta, c, prop_state)
        wind_rel = relative_wind(u, v, psi, U_T, zeta)
        wind = families["wind"].force(wind_rel.U_A, wind_rel.gamma_A, c) if "wind" in families else None
        return (hull, propeller, rudder, wind), wind_rel

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        """Force breakdown for state (..., 6) = (x, u, y, v, psi, r) and inputs (..., 4)
        = (n_prop [rps], delta_rudder [rad], wind_velo_true [m/s], wind_dir_true [rad])."""
        (hull, propeller, rudder, wind), wind_rel = self.components(state, inputs)
        hull = torch.stack(hull, -1)
        wind = torch.zeros_like(hull) if wind is None else torch.stack(wind, -1)
        return ForceBreakdown(hull, torch.stack(propeller, -1), torch.stack(rudder, -1), wind,
                              torch.zeros_like(hull), torch.stack(wind_rel, -1))

    def force_channels(self, state: torch.Tensor, inputs: torch.Tensor):
        """(X, Y, N) of F_MMG, each (...,) [N, N, N m], and the relative wind: the sums of
        `forward`'s components in the same order, without (..., 3) stacks (fewer, larger
        operations in compiled code)."""
        (hull, propeller, rudder, wind), wind_rel = self.components(state, inputs)
        total = tuple(h + p + r for h, p, r in zip(hull, propeller, rudder))
        if wind is not None:
            total = tuple(t + w for t, w in zip(total, wind))
        return total, wind_rel
