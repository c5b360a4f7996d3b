"""Standard maneuvers of any model: turning circle, zig-zag and crash stop (IMO
MSC.137(76)), their indices and criteria, and the same indices of recorded runs beside a
model's prediction of them.

`base` (the typed maneuver specs, conditions, results), `controllers` (closed-loop rudder
and engine orders), `closed_loop` (eager and compiled step loops), `straight` (the
revolutions of straight running), `simulate` (conditions, simulation, spread), `indices`
(each index a pure function of a trajectory), `criteria` (IMO limits), `recorded` (indices
of recorded runs and of predictions of them), `outputs` (CSV tables), `any_model` (a ship
file or a run directory).
"""
from __future__ import annotations

from sysid.maneuvers.any_model import BASELINE_LABEL, ManeuverModel, load_maneuver_model, physics_baseline, ship_of
from sysid.maneuvers.base import (Conditions, CrashStop, Maneuver, ManeuverError, ManeuverResult, Side,
                                  TurningCircle, ZigZag, imo_maneuvers)
from sysid.maneuvers.criteria import Criterion, criteria_for, overshoot_limits_10_10
from sysid.maneuvers.indices import INDEX_COLUMNS, ManeuverIndices, Track, maneuver_indices
from sysid.maneuvers.simulate import default_conditions, run_baseline, run_maneuvers, simulate_maneuvers
from sysid.maneuvers.straight import straight_running_rps

__all__ = ["BASELINE_LABEL", "ManeuverModel", "load_maneuver_model", "physics_baseline", "ship_of", "Conditions", "CrashStop", "Maneuver", "ManeuverError",
           "ManeuverResult", "Side", "TurningCircle", "ZigZag", "imo_maneuvers", "Criterion", "criteria_for",
           "overshoot_limits_10_10", "INDEX_COLUMNS", "ManeuverIndices", "Track", "maneuver_indices",
           "default_conditions", "run_baseline", "run_maneuvers", "simulate_maneuvers", "straight_running_rps"]
