"""The MMG model in torch: one module per force component, `MMG` sums them.

The names below load on first use: `sysid.mmg.ship` imports `sysid.mmg.families` while
`sysid.mmg.coefficients` imports `sysid.mmg.ship`, so this package must not import its
modules eagerly (else ``import sysid.mmg.ship`` as a program's first import is a circle).
"""
from __future__ import annotations

import importlib

_HOME = {
    "Coefficients": "coefficients", "crossflow_integrals": "hull", "hull_force": "hull",
    "MMG": "model", "ForceBreakdown": "model",
    "PropellerState": "propeller", "propeller_force": "propeller", "propeller_inflow": "propeller",
    "RudderInflow": "rudder", "rudder_force": "rudder", "rudder_inflow": "rudder",
    "RelativeWind": "wind", "relative_wind": "wind", "wind_force": "wind",
}

__all__ = [
    "MMG", "ForceBreakdown", "Coefficients", "hull_force", "crossflow_integrals",
    "propeller_force", "propeller_inflow", "PropellerState", "rudder_force", "rudder_inflow",
    "RudderInflow", "relative_wind", "wind_force", "RelativeWind",
]


def __getattr__(name: str):
    if name in _HOME:
        value = getattr(importlib.import_module(f"sysid.mmg.{_HOME[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'sysid.mmg' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
