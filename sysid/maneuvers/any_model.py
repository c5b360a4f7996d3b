"""Any model a maneuver can be run with: a ship file (its MMG) or a run directory (MMG,
identified MMG, NN-only, hybrid, a mean-of-seeds ensemble), or a folder of seed run
directories (``runs/NAME/seed0``, ``seed1``, ... of ``sysid reproduce --seeds``), whose
mean-of-seeds ensemble is then the model and whose seeds give the spread."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from torch import nn

from sysid.data.columns import ColumnMap
from sysid.errors import CheckpointError
from sysid.evaluation.divergence import PhysicalRange
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.mmg.model import MMG
from sysid.mmg.ship import Ship, load_ship
from sysid.runs.rundir import RunDir
from sysid.runs.layout import load_model
from sysid.store.manifest import has_manifest, seed_run_dirs

BASELINE_LABEL = "MMG (ship file)"  # the physics baseline of a learned model, as `sysid compare` names it
LEARNED_KINDS = ("nn", "hybrid")


@dataclass
class ManeuverModel:
    """A model to maneuver.

    label : its name (the ship's or the run directory's); model : the force model; ship :
    its ship (dimensions, [maneuvering] defaults); kind : "mmg", "nn" or "hybrid"; members :
    (label, model) of an ensemble's members or a folder's seeds, whose maneuvers give the
    spread of the indices (empty for a single model); spread : what the members are;
    training_range : the training logs' range a run recorded (None: unknown), against
    which a maneuver diverged; columns : the run's `[data.columns]` (its logs' names and
    units; None for a ship file or a run on the processed columns).
    """

    label: str
    model: nn.Module
    ship: Ship
    kind: str = "mmg"
    members: list[tuple[str, nn.Module]] = field(default_factory=list)
    spread: str = ""
    training_range: PhysicalRange | None = None
    columns: ColumnMap | None = None


def ship_of(model: nn.Module) -> Ship:
    """The `Ship` behind a force model (its MMG's; an ensemble's first member's)."""
    if isinstance(model, MMG):
        return model.ship
    if isinstance(model, SeedEnsemble):
        return ship_of(model.members[0])
    mmg = getattr(model, "mmg", None)
    if isinstance(mmg, MMG):
        return mmg.ship
    raise CheckpointError(f"{type(model).__name__}: no MMG to take the ship's dimensions from")


def load_maneuver_model(path: str | os.PathLike) -> ManeuverModel:
    """A `ManeuverModel` from a ship file or bundled ship name, a run directory, or a folder
    of seed run directories; one clear error otherwise."""
    path = Path(path)
    if path.is_dir():
        if has_manifest(path):
            exp, model = load_model(path)
            members = []
            if isinstance(model, SeedEnsemble):
                members = [(f"{path.name} member {i}", m) for i, m in enumerate(model.members)]
            return ManeuverModel(path.name, model, ship_of(model), getattr(model, "kind", "mmg"), members,
                                 "ensemble members" if members else "", _training_range([path]), exp.data.columns)
        seeds = seed_run_dirs(path)
        if not seeds:
            raise CheckpointError(f"{path}: neither a run directory (no manifest.json) nor a folder of seed run "
                                  "directories (seed0/, seed1/, ...)")
        loaded = [load_model(p) for p in seeds]
        members = [(f"{path.name} {p.name}", m) for p, (_, m) in zip(seeds, loaded)]
        model = SeedEnsemble([m for _, m in members])
        return ManeuverModel(path.name, model, ship_of(model), model.kind, members, "seeds", _training_range(seeds),
                             loaded[0][0].data.columns)
    ship = load_ship(path)
    return ManeuverModel(ship.name, MMG(ship), ship, "mmg")


def physics_baseline(subject: ManeuverModel) -> ManeuverModel | None:
    """The physics baseline of a learned model (kind "nn" or "hybrid", alone, an ensemble or
    a folder of seeds): the MMG of its ship file with the run's [mmg] overrides
    (``MMG(subject.ship)``, the baseline ``sysid compare`` shows), labelled `BASELINE_LABEL`,
    judged against the subject's training range; None for an MMG (it is the physics model)."""
    if subject.kind not in LEARNED_KINDS:
        return None
    return ManeuverModel(BASELINE_LABEL, MMG(subject.ship), subject.ship, "mmg",
                         training_range=subject.training_range, columns=subject.columns)


def _training_range(runs: list[Path]) -> PhysicalRange | None:
    """The widest training range the run directories recorded (None: none recorded one)."""
    kept = [r for r in (PhysicalRange.of_summary(RunDir(p).read_summary()) for p in runs) if r is not None]
    if not kept:
        return None
    return PhysicalRange(max(r.speed for r in kept), max(r.yaw_rate for r in kept), kept[0].factor)
