"""The tables of maneuver indices in reports: a maneuvers directory's indices and IMO
criteria (`sysid.report.maneuver_report`), and a reproduction's recorded turning and
zig-zag runs beside each model's prediction of them (``maneuver_indices.csv``)."""
from __future__ import annotations

import math

import pandas as pd

from sysid.maneuvers.recorded import RECORD_INDICES
from sysid.report.plain_tables import PlainTable, number

INDEX_LABELS = {"advance_m": "advance [m]", "transfer_m": "transfer [m]", "tactical_diameter_m": "tactical diam. [m]",
                "steady_turning_diameter_m": "steady diam. [m]", "speed_loss_ratio": "speed loss [-]",
                "initial_turning_distance_m": "initial turning [m]", "first_overshoot_deg": "1st overshoot [deg]",
                "second_overshoot_deg": "2nd overshoot [deg]", "head_reach_m": "head reach [m]",
                "track_reach_m": "track reach [m]",
                "open_loop_first_peak_deg": "1st peak, open loop [deg]",
                "open_loop_second_peak_deg": "2nd peak, open loop [deg]"}


def _several_models(frame: pd.DataFrame) -> bool:
    """Whether a maneuvers table holds more than one model (a learned model and its baseline)."""
    return "model" in frame and frame["model"].nunique() > 1


def indices_plain_table(indices: pd.DataFrame, model: str | None = None) -> PlainTable:
    """Indices per maneuver (± the members' standard deviation) and the kNN gate's share, of
    the rows of `model` (all rows: None), which the title then names (a learned model and
    its physics baseline get a table each, as wide as one model's)."""
    if model is not None:
        indices = indices[indices["model"] == model]
    shown = [c for c in INDEX_LABELS if c in indices and indices[c].notna().any()]
    gate = indices["gate_off_share"].notna().any() if "gate_off_share" in indices else False
    rows, marks = [], []
    for r in indices.itertuples(index=False):
        d = r._asdict()
        cells = [d["maneuver"]] + [number(d[c], 4, d.get(f"{c}_std")) for c in shown]
        mark = [""] * len(cells)
        if gate:
            share = d["gate_off_share"]
            outside = " (mostly outside)" if share > 0.5 else ""
            cells.append("" if pd.isna(share) else f"{100 * share:.1f} %{outside}")
            mark.append("not-met" if not pd.isna(share) and share > 0.5 else "")
        rows.append(cells)
        marks.append(mark)
    columns = ["maneuver"] + [INDEX_LABELS[c] for c in shown] + (["kNN gate off"] if gate else [])
    spread = "n_members" in indices and indices["n_members"].notna().any()
    note = ("Empty: not applicable or not reached in the run. ± : standard deviation over the members. "
            if spread else "Empty: not applicable or not reached in the run. ")
    if gate:
        note += "kNN gate off: share of the steps at which the FNN is switched off (outside the training data)."
    key = "indices" if model is None else "indices-" + "".join(ch if ch.isalnum() else "-" for ch in model.lower())
    return PlainTable(key, "Maneuver indices" + ("" if model is None else f": {model}"), columns, rows, marks, note)


def criteria_plain_table(criteria: pd.DataFrame) -> PlainTable:
    """Every IMO criterion: value, limit, in L (lengths) or deg (angles), met or not; per
    model where there are several (a learned model and its physics baseline)."""
    several = _several_models(criteria)
    rows, marks = [], []
    for r in criteria.itertuples(index=False):
        unit = "deg" if r.index.endswith("_deg") else "L"
        rows.append([r.maneuver, *([r.model] if several else []), r.rule, number(r.value, 4), number(r.limit, 4),
                     f"{number(r.ratio, 3)} {unit}", r.met])
        marks.append([""] * (5 + several) + [{"met": "met", "not met": "not-met"}.get(r.met, "muted")])
    columns = ["maneuver", *(["model"] if several else []), "criterion", "value", "limit", "value in L or deg",
               "verdict"]
    return PlainTable("criteria", "IMO MSC.137(76) criteria", columns, rows, marks,
                      "Lengths in m and as multiples of L = L_pp (Froude-invariant); overshoot angles in deg."
                      + (" Each model is held to the criteria on its own." if several else ""))


def beside_plain_table(indices: pd.DataFrame, learned: str, baseline: str) -> PlainTable:
    """Each index of the learned model beside its physics baseline's, and the difference
    (`sysid.maneuvers.outputs.beside_baseline`)."""
    from sysid.maneuvers.outputs import beside_baseline

    table = beside_baseline(indices, learned, baseline)
    rows = [[r.maneuver, INDEX_LABELS[r.index], number(r.learned, 4), number(r.baseline, 4),
             number(r.difference, 3) or ("n/a: diverged" if r.diverged else "n/a")]
            for r in table.itertuples(index=False)]
    return PlainTable("beside-baseline", f"{learned} beside its physics baseline {baseline}",
                      ["maneuver", "index", learned, baseline, f"difference ({learned} - {baseline})"], rows, [],
                      "The same maneuvers under the same conditions (approach speed, revolutions, rudder rate, "
                      "time step, duration, wind, integrator). Difference in the index's unit; n/a: one of the two "
                      "did not reach it or diverged (its indices are not valid). No pass/fail rule is defined for maneuver indices: which model is nearer the "
                      "ship cannot be told from simulations alone (--recorded logs of the same maneuvers can).")


def record_plain_table(frame: pd.DataFrame) -> PlainTable:
    """One row per recorded run and index that applies, one column per model (the record
    first): the record's indices and each model's, computed the same way
    (`sysid.maneuvers.recorded`); ± the spread over seeds; the kNN gate's share."""
    models = list(dict.fromkeys(frame["model"]))
    rows = []
    for (scenario, maneuver), group in frame.groupby(["scenario", "maneuver"], sort=False):
        by_model = {r["model"]: r for _, r in group.iterrows()}
        kind = "zigzag" if maneuver.startswith("zigzag") else "turning"
        for index in RECORD_INDICES[kind]:
            if index not in group:  # a table written before the open-loop peaks
                continue
            cells = [number(by_model[m][index], 3, by_model[m].get(f"{index}_std")) if m in by_model else ""
                     for m in models]
            if not any(cells):
                continue
            rows.append([scenario, INDEX_LABELS[index], *cells])
        shares = [by_model[m]["gate_off_share"] if m in by_model else math.nan for m in models]
        if any(not pd.isna(v) for v in shares):
            rows.append([scenario, "kNN gate off [%]", *("" if pd.isna(v) else f"{100 * v:.0f}" for v in shares)])
    return PlainTable("maneuver-record", "Standard-maneuver indices: recorded runs and predictions", ["test", "index",
                      *models], rows, [],
                      "Like for like (sysid.maneuvers.recorded): a turning run's indices from the record and from "
                      "each model's prediction of the whole run from the record's execute with the recorded inputs "
                      "(1 Hz, the protocol's integrator). A zig-zag's IMO overshoots from the record and from each "
                      "model run closed loop from the record's approach (speed, revolutions, rudder angle and rate, "
                      "wind) with reversals when the heading reaches the check angle (RK4, 0.1 s). Open-loop peak: "
                      "the heading's peak beyond the check angle between the recorded rudder's reversals, under the "
                      "recorded rudder (negative: the model turns less than the ship did). Lengths in m. Empty: not "
                      "reached in the run. ""± : standard deviation over seeds.")
