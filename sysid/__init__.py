"""sysid: physics-informed system identification for ship maneuvering.

One obvious entry point per task: `load_ship` for a ship definition, `MMG` for the force
model, `integrate` for (differentiable) trajectories, `predict` for fast predictions
(``predict(model, x0, inputs, dt, Integrator("rk4", compiled=True))``);
`sysid.lifecycle.run_experiment` trains, evaluates and writes one experiment (``sysid
train``), `sysid.reproduce.reproduce` the paper's protocol.

Layers, each importing only those before it: `state`, `ship`, `mmg`, `integrators` →
`dynamics`, `correction`, `ood` → `stepper`, `knn_index` → `compiled` → `export`;
`experiment`, `models` → `data` → `train` → `evaluate` → `rundir` → `lifecycle` → `paper`,
`reproduce` → `report` → `cli`.
"""
from sysid.dynamics import ShipDynamics, body_acceleration, integrate, state_derivative
from sysid.integrators import Integrator, Method
from sysid.compiled import predict
from sysid.mmg import MMG, ForceBreakdown
from sysid.ship import Ship, load_ship

__version__ = "0.1.0"

__all__ = ["Ship", "load_ship", "MMG", "ForceBreakdown", "ShipDynamics", "integrate", "predict", "Integrator", "Method",
           "state_derivative", "body_acceleration", "__version__"]
