"""The MMG model in torch: one module per force component, `MMG` sums them."""
from sysid.mmg.coefficients import Coefficients
from sysid.mmg.hull import crossflow_integrals, hull_force
from sysid.mmg.breakdown import MMG, ForceBreakdown
from sysid.mmg.propeller import PropellerState, propeller_force, propeller_inflow
from sysid.mmg.rudder import RudderInflow, rudder_force, rudder_inflow
from sysid.mmg.wind import RelativeWind, relative_wind, wind_force

__all__ = [
    "MMG", "ForceBreakdown", "Coefficients", "hull_force", "crossflow_integrals",
    "propeller_force", "propeller_inflow", "PropellerState", "rudder_force", "rudder_inflow",
    "RudderInflow", "relative_wind", "wind_force", "RelativeWind",
]
