"""The tables of a maneuvers directory (``sysid maneuver MODEL -o DIR``), as data frames.

- ``indices.csv`` (`indices_table`): one row per maneuver (``turning_35_starboard``,
  ``zigzag_10_10_starboard``, ``crash_stop``): the indices (`INDEX_COLUMNS`: m, deg, ratio;
  empty where not applicable), with an ensemble or seeds ``n_members`` and the standard
  deviation over the members ``<index>_std``; ``gate_off_share`` (kNN gate off at this share
  of the steps, empty without a gate) and ``mostly_outside`` (True when over half);
  ``knn_distance_max`` (the largest d_kNN along the maneuver, NaN rows skipped) and ``knn_threshold`` (the gate's
  delta_kNN; the FNN is off where d_kNN exceeds it), empty without a gate;
  ``diverged`` and ``diverged_at_s`` (time from the execute [s] at which the simulation
  diverged, `sysid.maneuvers.simulate.first_divergence`; empty otherwise: its indices are
  not valid); each IMO criterion that applies as ``imo_<index>`` = "met" / "not met" /
  "not assessed" (always for a diverged maneuver);
- ``criteria.csv`` (`criteria_table`): every criterion with value, limit, the values as
  ratios to L (lengths) or in deg (angles), met, the rule, and the model;
- ``trajectories.csv`` (`trajectory_table`): every step of every maneuver (and of every
  member), states and inputs in `sysid.channel_names`'s units (m, m/s, rad, rad/s, rps);
  of a model with a kNN gate, ``gate_on`` (the gate's decision at the step's start: 1 the
  FNN acts, 0 the physics MMG alone; empty on a maneuver's last row) and ``knn_distance``
  (d_kNN of the state and the inputs held from it, in the gate's feature units).

A learned model's physics baseline (`sysid.maneuvers.any_model.physics_baseline`) runs the
same maneuvers under the same conditions: its rows follow the learned model's in all three
tables, their ``model`` column naming it (`BASELINE_LABEL`), and `beside_baseline` sets the
two models' indices side by side with their difference.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from sysid.maneuvers.any_model import BASELINE_LABEL
from sysid.maneuvers.base import ManeuverResult
from sysid.maneuvers.criteria import Criterion, criteria_for
from sysid.maneuvers.indices import INDEX_COLUMNS
from sysid.channel_names import INPUTS, STATE
from sysid.store.files import write_csv, write_text
from sysid.store.target import RECORD_FILES, OutputKind

MOSTLY_OUTSIDE = 0.5  # gate off on more than this share of the steps: "mostly outside the training data"
CRITERION_COLUMNS = ("maneuver", "index", "value", "limit", "ratio", "limit_ratio", "met", "rule")
INDEX_UNITS = {"m": "m", "deg": "deg", "ratio": "-"}  # unit of an index column, from its name's last part


def spread(result: ManeuverResult) -> dict[str, float]:
    """Standard deviation (ddof 1) of each index over the result's members; empty without
    at least two members."""
    if len(result.members) < 2:
        return {}
    out = {}
    for c in INDEX_COLUMNS:
        values = np.array([getattr(m.indices, c) for m in result.members], dtype=float)
        values = values[np.isfinite(values)]
        out[f"{c}_std"] = float(np.std(values, ddof=1)) if len(values) >= 2 else math.nan
    return out


def _verdict(met: bool | None) -> str:
    return "not assessed" if met is None else ("met" if met else "not met")


def indices_table(results: Sequence[ManeuverResult], L: float, U: float, scale: float | None) -> pd.DataFrame:
    """One row per maneuver (see the module docstring); L [m], U approach speed [m/s],
    `scale` (full over model length, or None) for the criteria."""
    rows = []
    for r in results:
        row = {"maneuver": r.maneuver.name, "kind": r.maneuver.kind, "model": r.model, **r.indices.as_dict()}
        if r.members:
            row["n_members"] = len(r.members)
            row.update(spread(r))
        row["gate_off_share"] = r.gate_off_share
        row["mostly_outside"] = None if r.gate_off_share is None else bool(r.gate_off_share > MOSTLY_OUTSIDE)
        row["knn_distance_max"] = r.knn_distance_max
        row["knn_threshold"] = r.knn_threshold
        row["diverged"] = r.diverged
        row["diverged_at_s"] = r.diverged_at_s if r.diverged_at_s is not None else math.nan
        for c in criteria_for(r.maneuver, r.indices, L, U, scale):
            row[f"imo_{c.index.rsplit('_', 1)[0]}"] = _verdict(None if r.diverged else c.met)
        rows.append(row)
    frame = pd.DataFrame(rows)
    order = ["maneuver", "kind", "model", *INDEX_COLUMNS]
    return frame[order + [c for c in frame.columns if c not in order]]


def criteria_table(results: Sequence[ManeuverResult], L: float, U: float, scale: float | None) -> pd.DataFrame:
    """Every IMO criterion of every maneuver (`Criterion` fields; met as "met", "not met" or
    "not assessed")."""
    pairs: list[tuple[Criterion, ManeuverResult]] = [(c, r) for r in results
                                                     for c in criteria_for(r.maneuver, r.indices, L, U, scale)]
    frame = pd.DataFrame([{k: getattr(c, k) for k in CRITERION_COLUMNS} for c, _ in pairs],
                         columns=list(CRITERION_COLUMNS))
    frame["met"] = [_verdict(None if r.diverged else c.met) for c, r in pairs]
    frame["model"] = [r.model for _, r in pairs]
    return frame


def beside_baseline(indices: pd.DataFrame, learned: str, baseline: str = BASELINE_LABEL) -> pd.DataFrame:
    """Each index (`INDEX_COLUMNS`) of each maneuver that both models of an indices table
    ran and that applies to either: one row with ``maneuver``, ``index``, ``unit`` (m, deg or
    -), the `learned` model's value, the `baseline`'s, ``difference`` = learned minus
    baseline (NaN where either is NaN, not reached, or where either run diverged: its
    indices are not valid) and ``diverged``, the model(s) that diverged ("" none). No
    pass/fail: docs/verdict.md defines no rule for maneuver indices."""
    columns = ["maneuver", "index", "unit", "learned", "baseline", "difference", "diverged"]
    mine = indices[indices["model"] == learned].set_index("maneuver")
    theirs = indices[indices["model"] == baseline].set_index("maneuver")
    rows = []
    for name in mine.index:
        if name not in theirs.index:
            continue
        diverged = [label for label, own in ((learned, mine), (baseline, theirs))
                    if "diverged" in own and bool(own.at[name, "diverged"])]
        for c in INDEX_COLUMNS:
            a, b = float(mine.at[name, c]), float(theirs.at[name, c])
            if math.isnan(a) and math.isnan(b):
                continue
            rows.append({"maneuver": name, "index": c, "unit": INDEX_UNITS[c.rsplit("_", 1)[1]], "learned": a,
                         "baseline": b, "difference": math.nan if diverged else a - b,
                         "diverged": ", ".join(diverged)})
    return pd.DataFrame(rows, columns=columns)


def trajectory_table(results: Sequence[ManeuverResult]) -> pd.DataFrame:
    """Every step of every maneuver and member: maneuver, model, t [s], the state (`STATE`),
    the inputs held over the step (`INPUTS`; delta_rudder their mean over the step) and
    ``rudder_angle`` [rad] at t; ``gate_on`` and ``knn_distance`` where the model has a kNN
    gate."""
    parts = []
    for r in results:
        for own in [r, *r.members]:
            frame = pd.DataFrame(own.states, columns=list(STATE))
            frame[list(INPUTS)] = own.inputs
            frame.insert(0, "t", own.t)
            frame.insert(0, "model", own.model)
            frame.insert(0, "maneuver", r.maneuver.name)
            frame["rudder_angle"] = own.rudder
            if own.gate_on is not None:
                frame["gate_on"] = own.gate_on
            if own.knn_distance is not None:
                frame["knn_distance"] = own.knn_distance
            parts.append(frame)
    return pd.concat(parts, ignore_index=True)


def summary_document(subject_label: str, kind: str, ship, conditions, sources: dict[str, str],
                     results: Sequence[ManeuverResult], compiled: bool, seconds: float, spread: str = "",
                     baseline: Sequence[ManeuverResult] | None = None, left_out: Sequence[str] = ()) -> dict:
    """maneuvers.json of a maneuvers directory: the model, the ship's dimensions and scale,
    every condition with where it came from, per maneuver the kNN gate's off share, and the
    physics baseline (None: the model is an MMG): its label, the maneuvers it ran, those it
    could not (`left_out`), where it diverged."""
    shown = None
    if baseline is not None:
        shown = {"model": BASELINE_LABEL, "kind": "mmg", "ship_file": ship.source,
                 "maneuvers": [r.maneuver.name for r in baseline], "left_out": list(left_out),
                 "diverged_at_s": {r.maneuver.name: r.diverged_at_s for r in baseline if r.diverged}}
    L, B = float(ship["L_pp"]), float(ship["B"])
    scale = ship.maneuvering.get("scale")
    return {
        "model": subject_label, "kind": kind, "ship": ship.name, "ship_file": ship.source,
        "L_pp_m": L, "B_m": B, "scale": scale,
        "L_over_U_s": L / conditions.speed,
        "L_over_U_full_scale_s": None if scale is None else L / conditions.speed * math.sqrt(scale),
        "conditions": {"speed_m_s": conditions.speed, "rps": conditions.rps,
                       "rudder_rate_deg_s": conditions.rudder_rate, "dt_s": conditions.dt,
                       "duration_s": conditions.duration, "wind_speed_m_s": conditions.wind_speed,
                       "wind_direction_deg": math.degrees(conditions.wind_direction),
                       "integrator": conditions.method.value},
        "sources": dict(sources), "compiled": compiled, "seconds": seconds,
        "spread": spread, "n_members": len(results[0].members) if results else 0,
        "maneuvers": [r.maneuver.name for r in results],
        "gate_off_share": {r.maneuver.name: r.gate_off_share for r in results},
        "knn_threshold": next((r.knn_threshold for r in results if r.knn_threshold is not None), None),
        "diverged_at_s": {r.maneuver.name: r.diverged_at_s for r in results if r.diverged},
        "baseline": shown,
    }


def write_maneuvers(directory, results: Sequence[ManeuverResult], ship, conditions, summary: dict,
                    baseline: Sequence[ManeuverResult] = ()) -> None:
    """indices.csv, criteria.csv, trajectories.csv and maneuvers.json into `directory` (a
    staging directory: `sysid.store.staging.staged_directory`); the `baseline`'s results
    (a learned model's physics baseline) as rows after the model's."""
    directory = Path(directory)
    results = [*results, *baseline]
    L, scale = float(ship["L_pp"]), ship.maneuvering.get("scale")
    write_csv(indices_table(results, L, conditions.speed, scale), directory / "indices.csv", float_format="%.8g")
    write_csv(criteria_table(results, L, conditions.speed, scale), directory / "criteria.csv", float_format="%.8g")
    write_csv(trajectory_table(results), directory / "trajectories.csv", float_format="%.10g")
    write_text(json.dumps(summary, indent=2), directory / RECORD_FILES[OutputKind.MANEUVERS])
