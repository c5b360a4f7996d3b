"""sysid: physics-informed system identification for ship maneuvering.

One obvious entry point per task: `load_ship` for a ship definition, `MMG` for the force
model, `integrate` for predictions; `sysid.lifecycle.run_experiment` trains, evaluates and
writes one experiment (``sysid train``), `sysid.reproduce.reproduce` the paper's protocol.

Layers, each importing only those before it: `state`, `ship`, `mmg` → `dynamics`,
`correction`, `ood` → `experiment`, `models` → `data` → `train` → `evaluate` → `rundir` →
`lifecycle` → `paper`, `reproduce` → `report` → `cli`.
"""
from sysid.dynamics import ShipDynamics, body_acceleration, integrate, state_derivative
from sysid.mmg import MMG, ForceBreakdown
from sysid.ship import Ship, load_ship

__version__ = "0.1.0"

__all__ = ["Ship", "load_ship", "MMG", "ForceBreakdown", "ShipDynamics", "integrate",
           "state_derivative", "body_acceleration", "__version__"]
