"""One colour per model, the same in every figure and table of a report (labels: `sysid.protocol.paper`).

Measured data is black; MMG blues, NN oranges, hybrid greens (the darker shade for D2, the
data set the paper's figures use). Force components have their own fixed colours.
"""
from __future__ import annotations

from sysid.config.choices import ModelKind

MEASURED = "#000000"
BASELINE_COLOURS = ["#7f7f7f", "#4d4d4d"]   # a learned run's physics baselines (dashed), in their order

MODEL_COLOURS = {
    "mmg_paper": "#1f5fbf",
    "mmg_lab": "#7fb2f0",
    "nn_D1": "#ffb366",
    "nn_D2": "#e06c00",
    "hybrid_D1": "#8fd18f",
    "hybrid_D2": "#1b8a3a",
    "mmg_identified_D2": "#8c3fbf",
    "hybrid_identified_D2": "#17a2a2",
}
KIND_COLOURS = {"mmg": "#1f5fbf", "nn": "#e06c00", "hybrid": "#1b8a3a"}
EXTRA_COLOURS = ["#8c3fbf", "#bf3f6f", "#6f6f2f", "#2f8f8f"]

# force components (Figs. 17-20)
COMPONENT_COLOURS = {"H": "#1f5fbf", "P": "#8c3fbf", "R": "#d62728", "A": "#17becf",
                     "NN": "#1b8a3a", "MMG": "#1f5fbf", "SUM": "#000000"}
COMPONENT_LABELS = {"H": "hull", "P": "propeller", "R": "rudder", "A": "wind (air)", "NN": "FNN"}

OOD_SHADE = "#d62728"
THRESHOLD = "#2ca02c"
KNN_LINE = "#1f5fbf"


def run_key(name: str, kind: ModelKind, dataset: str) -> str:
    """Canonical key of a run: the reproduction's directory name, else ``{kind}_{dataset}``."""
    if name in MODEL_COLOURS:
        return name
    return f"{kind}_{dataset}" if kind is not ModelKind.MMG else name


def model_colour(name: str, kind: ModelKind, dataset: str, index: int = 0) -> str:
    """Fixed colour of a run (see module docstring)."""
    key = run_key(name, kind, dataset)
    if key in MODEL_COLOURS:
        return MODEL_COLOURS[key]
    if kind in KIND_COLOURS:
        return KIND_COLOURS[kind]
    return EXTRA_COLOURS[index % len(EXTRA_COLOURS)]

# preprocessing quality timeline
QUALITY_COLOURS = {"kept": "#1b8a3a", "dropped": "#9a9a9a", "split": "#d62728", "filled": "#ff9f1c",
                   "baseline": "#1f5fbf", "gate": "#8c3fbf"}
