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
from sysid.mmg.motion import as_channels, motion_of
from sysid.mmg.wind import relative_wind_of
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

    def components(self, state: torch.Tensor, inputs: torch.Tensor, relative: bool = True):
        """(hull, propeller, rudder, wind or None), each (..., 3) = (X, Y, N) [N, N, N m], the
        relative wind (None unless `relative` or a wind force needs it) and the forward's
        `Motion`."""
        return self._components(state, inputs, self.coefficients.values_view(state.dtype), relative)

    def _components(self, state, inputs, c, relative: bool):
        m = motion_of(state, inputs, c)
        families = self.families
        hull = families["hull"].forces(m, c, self.quadrature)
        propeller_family = families["propeller"]
        prop_state = propeller_family.inflow_of(m, c)
        propeller = propeller_family.forces(m, c, prop_state)
        rudder = families["rudder"].forces(m, c, prop_state)
        wind_family = families.get("wind")
        wind_rel = relative_wind_of(m) if relative or wind_family is not None else None
        wind = wind_family.forces(wind_rel.U_A, wind_rel.gamma_A, c) if wind_family is not None else None
        return (hull, propeller, rudder, wind), wind_rel, m

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        """Force breakdown for state (..., 6) = (x, u, y, v, psi, r) and inputs (..., 4)
        = (n_prop [rps], delta_rudder [rad], wind_velo_true [m/s], wind_dir_true [rad])."""
        (hull, propeller, rudder, wind), wind_rel, _ = self.components(state, inputs)
        zero = torch.zeros_like(hull)
        return ForceBreakdown(hull, propeller, rudder, zero if wind is None else wind, zero,
                              torch.cat(wind_rel, -1))

    def total_force(self, state: torch.Tensor, inputs: torch.Tensor, relative: bool = True):
        """F_MMG (..., 3) = (X, Y, N) [N, N, N m] (the sum of `forward`'s components in the
        same order), the relative wind (None unless `relative` or a wind force needs it) and
        the forward's `Motion`."""
        return self._total_force(state, inputs, self.coefficients.values_view(state.dtype), relative)

    def _total_force(self, state, inputs, c, relative: bool):
        (hull, propeller, rudder, wind), wind_rel, m = self._components(state, inputs, c, relative)
        total = hull + propeller + rudder
        return (total if wind is None else total + wind), wind_rel, m

    def force_channels(self, state: torch.Tensor, inputs: torch.Tensor):
        """(X, Y, N) of F_MMG, each (...,) [N, N, N m], and the relative wind (`total_force`
        as channels)."""
        total, wind_rel, _ = self.total_force(state, inputs)
        return total.unbind(-1), as_channels(wind_rel)

    def eager_rate(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, None] | None:
        """(dx/dt (..., 6) of the equations of motion driven by F_MMG, None: no gate) without
        gradient where `no_grad_rate` applies; else None (the torch path, `rate_terms`, which
        this equals to round-off)."""
        if torch.is_grad_enabled():
            return None
        rate = self.no_grad_rate(state)
        return rate(state, inputs) if rate is not None else None

    def identified_rate(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor | None:
        """dx/dt (..., 6) of the equations of motion driven by F_MMG through the hand-derived
        VJP with respect to the state and the identified hull coefficients
        (`sysid.mmg.vjp.identified_rate`: the identification's rollouts) where it applies;
        else None (the torch path, `rate_terms`, which this equals to round-off)."""
        from sysid.mmg.vjp import identified_rate
        return identified_rate(self, state, inputs)

    def no_grad_rate(self, like: torch.Tensor):
        """A function (state (..., 6), inputs (..., 4)) -> (dx/dt (..., 6), None), one call of
        the native kernel (`sysid.mmg.native.rate`), to call without gradient on tensors of
        `like`'s dtype and device while the coefficients stay as they are; None where the
        kernel does not compute this MMG's families or take such tensors."""
        from sysid.mmg import native
        families = native.families_of(self)
        with torch.no_grad():
            c = self.coefficients.values_view(like.dtype)
            if families is None or not native.applies(like, like.new_empty(like.shape[:-1] + (4,)), c):
                return None
        return lambda state, inputs: (native.rate(state, inputs, c, families)[..., :6], None)

    def rate_terms(self, state: torch.Tensor, inputs: torch.Tensor):
        """What the equations of motion need for dx/dt at state (..., 6) with inputs (..., 4),
        in one forward: the force components present, each (..., 3) = (X, Y, N) [N, N, N m],
        the forward's `sysid.mmg.motion.Motion` and the coefficients' values view
        (`sysid.dynamics.equations.motion_rate` takes them)."""
        c = self.coefficients.values_view(state.dtype)
        forces, _, m = self._components(state, inputs, c, False)
        return [f for f in forces if f is not None], m, c
