"""sysid: physics-informed system identification for ship maneuvering.

One obvious entry point per task: `load_ship` for a ship definition, `MMG` for the force
model, `integrate` for (differentiable) trajectories, `predict` for fast predictions
(``predict(model, x0, inputs, dt, Integrator("rk4", compiled=True))``);
`sysid.runs.lifecycle.run_experiment` trains, evaluates and writes one experiment (``sysid
train``), `sysid.protocol.reproduce.reproduce` the paper's protocol; `RunDir` opens a run
directory (``RunDir.open("runs/hybrid_D2").read_summary()``: its typed `RunSummary`).

Subpackages in layers, each importing only those before it (`LAYERS` in
tests/test_import_graph.py, docs/layout.md): `preprocessing`, `errors`, `channel_names`, `logs`,
`workers`, `package_data` → `progress`, `store` (files, manifests) → `mmg` (ship files, force
families, the force model) → `config` (the closed choices and experiment configs, no torch,
no pandas) → `records` (what a run directory holds, no torch), `device` → `dynamics`,
`hybrid`, `data` → `fast` (the compiled path and export; imported by the CLI, elsewhere only
where compilation is chosen) → `identify`, `evaluation` → `runs` → `experiment_tracking` → `sweep` →
`maneuvers` → `protocol` → `report` → `cli`.

The names are loaded on first use, so ``import sysid`` (and ``sysid --help``) does not pay
for torch.
"""
from __future__ import annotations

import importlib

__version__ = "0.1.0"

_HOME = {
    "Ship": "sysid.mmg.ship", "load_ship": "sysid.mmg.ship",
    "MMG": "sysid.mmg", "ForceBreakdown": "sysid.mmg",
    "ShipDynamics": "sysid.dynamics.equations", "integrate": "sysid.dynamics.equations",
    "predict": "sysid.fast.compiled", "Integrator": "sysid.dynamics.integrators", "Method": "sysid.config.choices",
    "state_derivative": "sysid.dynamics.equations", "body_acceleration": "sysid.dynamics.equations",
    "RunDir": "sysid.runs.directory", "RunSummary": "sysid.records.summary",
}

__all__ = ["Ship", "load_ship", "MMG", "ForceBreakdown", "ShipDynamics", "integrate", "predict", "Integrator", "Method",
           "state_derivative", "body_acceleration", "RunDir", "RunSummary", "__version__"]


def __getattr__(name: str):
    if name in _HOME:
        value = getattr(importlib.import_module(_HOME[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'sysid' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
