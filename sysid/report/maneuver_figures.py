"""Figures of a maneuvers directory (``sysid maneuver``), from its trajectories.csv and
criteria.csv: tracks with the hull outline, heading and rudder over time, speed and
revolutions of a crash stop, and the indices against the IMO limits; a learned model's
physics baseline dashed beside it. Positions [m], speeds [m/s], angles [deg], revolutions
[rps], time [s] from the execute."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import FigureBase
from matplotlib.lines import Line2D

from sysid.report.figures import _canvas, _legend_top, _outline_at, ship_outline

RAD2DEG = 180.0 / math.pi
COLOURS = ["#1f5fbf", "#d62728", "#1b8a3a", "#e06c00", "#8c3fbf", "#17a2a2", "#6f6f2f", "#bf3f6f"]
OUTLINES = 12  # hull outlines drawn along each track
BASELINE_STYLE: dict[str, Any] = {"ls": "--", "lw": 1.0}  # the physics baseline's lines


def _by_maneuver(frame: pd.DataFrame, main: str, baseline: str | None = None
                 ) -> list[tuple[str, pd.DataFrame, list[pd.DataFrame], pd.DataFrame | None]]:
    """(maneuver, its main model's steps, its members' steps, its `baseline` model's steps or
    None) in file order, for the maneuvers the main model ran."""
    out = []
    for name, group in frame.groupby("maneuver", sort=False):
        if not (group.model == main).any():
            continue
        members = [g for label, g in group.groupby("model", sort=False) if label not in (main, baseline)]
        base = group[group.model == baseline] if baseline is not None else None
        out.append((name, group[group.model == main], members, base if base is not None and len(base) else None))
    return out


def _baseline_handle(groups, baseline: str | None, colour: str = "grey") -> list[Line2D]:
    """The legend entry naming the physics baseline, when any maneuver drew it."""
    if baseline is None or all(base is None for *_, base in groups):
        return []
    return [Line2D([], [], color=colour, **BASELINE_STYLE, label=f"dashed: physics baseline {baseline}")]


def _kind(name: str) -> str:
    """turning, zigzag or crash (from a maneuver's name)."""
    return "crash" if name.startswith("crash") else name.split("_")[0]


def tracks(frame: pd.DataFrame, main: str, L: float, B: float, title: str,
           into: FigureBase | None = None, baseline: str | None = None) -> FigureBase:
    """Earth-frame tracks (x0 north up, y0 east right [m]) of every maneuver, one panel per
    kind, the hull outline at `OUTLINES` instants; members (ensemble, seeds) as thin lines;
    the `baseline` model's track dashed."""
    groups = _by_maneuver(frame, main, baseline)
    kinds = list(dict.fromkeys(_kind(name) for name, *_ in groups))
    fig = _canvas(into, (10.0, 5.2))
    axes = np.atleast_1d(fig.subplots(1, len(kinds)))
    outline = ship_outline(L, B)
    handles = []
    for i, (name, own, members, base) in enumerate(groups):
        ax = axes[kinds.index(_kind(name))]
        colour = COLOURS[i % len(COLOURS)]
        for m in members:
            ax.plot(m["y"], m["x"], color=colour, lw=0.5, alpha=0.35)
        if base is not None:
            ax.plot(base["y"], base["x"], color=colour, **BASELINE_STYLE)
        ax.plot(own["y"], own["x"], color=colour, lw=1.3)
        for row in own.iloc[:: max(1, len(own) // OUTLINES)].itertuples(index=False):
            east, north = _outline_at(outline, row.x, row.y, row.psi)
            ax.plot(east, north, color=colour, lw=0.6)
        handles.append(Line2D([], [], color=colour, lw=1.3, label=name))
    titles = {"turning": "turning circles", "zigzag": "zig-zags", "crash": "crash stop"}
    for ax, kind in zip(axes, kinds):
        ax.plot(0.0, 0.0, "ko", ms=3)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("y0 (east) [m]")
        ax.set_ylabel("x0 (north) [m]")
        ax.set_title(titles[kind], fontsize=9)
    handles.append(Line2D([], [], color="k", marker="o", ls="", ms=3, label="execute (approach along x0)"))
    if any(members for _, _, members, _ in groups):
        handles.append(Line2D([], [], color="grey", lw=0.5, label="members"))
    handles += _baseline_handle(groups, baseline)
    _legend_top(fig, handles, ncol=4)
    fig.suptitle(f"{title}; hull outline ({L:g} m x {B:g} m) at {OUTLINES} instants", fontsize=10)
    return fig


def heading_rudder(frame: pd.DataFrame, main: str, kind: str, checks: dict[str, float], title: str,
                   into: FigureBase | None = None, baseline: str | None = None) -> FigureBase:
    """Heading change [deg] and rudder angle [deg] over time [s] of every maneuver of `kind`
    ("zigzag" or "turning"); turning panels add the speed U [m/s]; dotted: the zig-zag's
    check angles ± `checks[name]` [deg]; dashed: the `baseline` model's heading, rudder and
    speed."""
    groups = [g for g in _by_maneuver(frame, main, baseline) if g[0].startswith(kind)]
    fig = _canvas(into, (10.0, 1.9 * len(groups) + 1.0))
    axes = np.atleast_1d(fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0])
    for ax, (name, own, members, base) in zip(axes, groups):
        t = own["t"].to_numpy()
        psi = np.unwrap(own["psi"].to_numpy())
        for m in members:
            ax.plot(m["t"], (np.unwrap(m["psi"].to_numpy()) - m["psi"].iloc[0]) * RAD2DEG, color="#1f5fbf",
                    lw=0.5, alpha=0.35)
        ax.plot(t, (psi - psi[0]) * RAD2DEG, color="#1f5fbf", lw=1.3)
        ax.plot(t, own["rudder_angle"] * RAD2DEG, color="#d62728", lw=1.0)
        if base is not None:
            ax.plot(base["t"], (np.unwrap(base["psi"].to_numpy()) - base["psi"].iloc[0]) * RAD2DEG, color="#1f5fbf",
                    **BASELINE_STYLE)
            ax.plot(base["t"], base["rudder_angle"] * RAD2DEG, color="#d62728", **BASELINE_STYLE)
        if name in checks:
            for sign in (1, -1):
                ax.axhline(sign * checks[name], color="grey", lw=0.7, ls=":")
        ax.set_ylabel("[deg]")
        ax.set_title(name, fontsize=9, loc="left")
        if kind == "turning":
            speed = ax.twinx()
            speed.plot(t, np.hypot(own["u"], own["v"]), color="#1b8a3a", lw=1.0)
            if base is not None:
                speed.plot(base["t"], np.hypot(base["u"], base["v"]), color="#1b8a3a", **BASELINE_STYLE)
            speed.set_ylabel("U [m/s]", color="#1b8a3a")
            speed.grid(False)
    axes[-1].set_xlabel("t from the execute [s]")
    handles = [Line2D([], [], color="#1f5fbf", lw=1.3, label="heading change ψ - ψ0 [deg]"),
               Line2D([], [], color="#d62728", lw=1.0, label="rudder angle δ [deg]")]
    if kind == "turning":
        handles.append(Line2D([], [], color="#1b8a3a", lw=1.0, label="speed U [m/s]"))
    if checks:
        handles.append(Line2D([], [], color="grey", lw=0.7, ls=":", label="check angle [deg]"))
    handles += _baseline_handle(groups, baseline)
    _legend_top(fig, handles, ncol=4)
    fig.suptitle(title, fontsize=10)
    return fig


def crash_stop(frame: pd.DataFrame, main: str, title: str, into: FigureBase | None = None,
               baseline: str | None = None) -> FigureBase:
    """Surge speed u [m/s] and propeller revolutions n [rps] over time [s] of the crash stop;
    dotted: where u reaches zero (the stop); dashed: the `baseline` model's surge speed."""
    groups = [g for g in _by_maneuver(frame, main, baseline) if g[0] == "crash_stop"]
    name, own, members, base = groups[0]
    fig = _canvas(into, (10.0, 3.6))
    ax = fig.subplots()
    for m in members:
        ax.plot(m["t"], m["u"], color="#1f5fbf", lw=0.5, alpha=0.35)
    ax.plot(own["t"], own["u"], color="#1f5fbf", lw=1.3)
    if base is not None:
        ax.plot(base["t"], base["u"], color="#1f5fbf", **BASELINE_STYLE)
    ax.axhline(0.0, color="k", lw=0.6)
    stopped = own[own["u"] <= 0.0]
    if len(stopped):
        ax.axvline(stopped["t"].iloc[0], color="k", lw=0.8, ls=":")
    ax.set_ylabel("u [m/s]")
    ax.set_xlabel("t from the execute [s]")
    rps = ax.twinx()
    rps.plot(own["t"], own["n_prop"], color="#e06c00", lw=1.0)
    rps.set_ylabel("n [rps]", color="#e06c00")
    rps.grid(False)
    _legend_top(fig, [Line2D([], [], color="#1f5fbf", lw=1.3, label="surge speed u [m/s]"),
                      Line2D([], [], color="#e06c00", lw=1.0, label="propeller revolutions n [rps]"),
                      Line2D([], [], color="k", lw=0.8, ls=":", label="stop (u = 0)"),
                      *_baseline_handle(groups, baseline)])
    fig.suptitle(title, fontsize=10)
    return fig


def criteria_chart(criteria: pd.DataFrame, title: str, into: FigureBase | None = None) -> FigureBase:
    """Each assessed index as a share of its IMO limit (value / limit, dimensionless): at or
    below 1 the criterion is met (green), above it not (red)."""
    rows = criteria[criteria["met"].isin(["met", "not met"])].reset_index(drop=True)
    fig = _canvas(into, (10.0, 0.32 * max(len(rows), 1) + 1.4))
    ax = fig.subplots()
    share = (rows["value"] / rows["limit"]).to_numpy(dtype=float)
    colours = ["#1b8a3a" if m == "met" else "#d62728" for m in rows["met"]]
    several = "model" in rows and rows["model"].nunique() > 1  # a learned model and its physics baseline
    labels = [f"{r.maneuver}{f' ({r.model})' if several else ''}: {r.index.rsplit('_', 1)[0].replace('_', ' ')}"
              for r in rows.itertuples(index=False)]
    ax.barh(range(len(rows)), share, color=colours)
    ax.axvline(1.0, color="k", lw=1.0)
    ax.set_yticks(range(len(rows)), labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("index / IMO limit [-] (met at or below 1)")
    fig.suptitle(title, fontsize=10)
    return fig
