"""The report's figures (the paper's Figs. 3-21 and the loss curves), one function each.

Every function takes plain data (trace frames, `sysid.evaluation.evaluate.TRACE_COLUMNS`, with a label
and a colour per model) and returns a matplotlib `Figure` built without pyplot (no global
state). Units follow the traces: positions [m], velocities [m/s], angles shown in degrees,
forces [N], moments [N m].
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd
from matplotlib.artist import Artist
from matplotlib.figure import Figure, FigureBase
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FixedLocator, FormatStrFormatter, NullFormatter

from sysid.report.palette import (COMPONENT_COLOURS, COMPONENT_LABELS, KNN_LINE, MEASURED,
                                  OOD_SHADE, THRESHOLD)

RAD2DEG = 180.0 / math.pi
WIDE = (10.0, 6.2)      # in, landscape figures (fits an A4 landscape page with caption)
TALL = (10.0, 7.0)
RATIO_TICKS = [0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0]   # RMSE ratios [-] on a log axis


BASELINE_LINE = {"ls": "--", "lw": 1.0}   # a physics baseline's lines, beside its learned model's solid ones
BASELINE_HATCH = "//"                      # and its boxes


@dataclass
class ModelTrace:
    """A model's trace of one file at one horizon, with the model's label and colour;
    `baseline`: a learned model's physics baseline on the same windows, drawn dashed."""

    label: str
    colour: str
    frame: pd.DataFrame
    baseline: bool = False

    def line(self, lw: float) -> dict:
        """Line style: solid of width `lw` [pt], a baseline's dashed and thinner."""
        return dict(BASELINE_LINE) if self.baseline else {"lw": lw}


def _broken(frame: pd.DataFrame, column: str, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Time [s] and values of every window joined with NaN gaps (one line, no jumps drawn)."""
    ts, ys = [], []
    for _, w in frame.groupby("window", sort=True):
        ts += [w["t"].to_numpy(), [np.nan]]
        ys += [w[column].to_numpy() * scale, [np.nan]]
    return np.concatenate(ts), np.concatenate(ys)


def _canvas(into: FigureBase | None, size: tuple[float, float]) -> FigureBase:
    """Draw into `into` (a PDF page's sub-figure) or a new constrained-layout figure of
    `size` [in]."""
    return into if into is not None else Figure(figsize=size, layout="constrained")


def _legend_top(fig: FigureBase, handles: Sequence[Artist], ncol: int | None = None) -> None:
    """Figure legend in its own row under the axes (the title stays alone on top)."""
    fig.legend(handles=handles, loc="outside lower center", ncol=ncol or min(len(handles), 6),
               frameon=False, fontsize=8)


def _model_handles(traces: list[ModelTrace], measured: bool = True) -> list:
    handles = [Line2D([], [], color=MEASURED, lw=1.6, label="measured")] if measured else []
    return handles + [Line2D([], [], color=t.colour, label=t.label, **t.line(1.4)) for t in traces]


def error_boxplots(traces: list[ModelTrace], title: str, into: FigureBase | None = None) -> FigureBase:
    """Absolute prediction error of u, v_m [m/s] and r [rad/s] per model (Figs. 3-5):
    boxes = IQR, line = median, diamond = mean, whiskers 1.5 IQR."""
    fig = _canvas(into, (10.0, 4.6))
    axes = fig.subplots(1, 3)
    for ax, (col, name, unit) in zip(axes, [("u", "u", "m/s"), ("v", "v_m", "m/s"), ("r", "r", "rad/s")]):
        data = [np.abs(t.frame[f"pred_{col}"] - t.frame[f"obs_{col}"]).to_numpy() for t in traces]
        box = ax.boxplot(data, patch_artist=True, showmeans=True, widths=0.6,
                         medianprops={"color": "black"},
                         meanprops={"marker": "D", "markerfacecolor": "white",
                                    "markeredgecolor": "black", "markersize": 4},
                         flierprops={"marker": ".", "markersize": 2, "alpha": 0.4})
        for patch, t in zip(box["boxes"], traces):
            patch.set_facecolor(t.colour)
            if t.baseline:
                patch.set_hatch(BASELINE_HATCH)
                patch.set_linestyle("--")
        ax.set_xticks(range(1, len(traces) + 1), [t.label for t in traces], rotation=35,
                      ha="right", fontsize=8)
        ax.set_ylabel(f"|error of {name}| [{unit}]")
        ax.set_title(name)
    handles: list[Artist] = [Patch(facecolor=t.colour, edgecolor="black", label=t.label,
                                   hatch=BASELINE_HATCH if t.baseline else None) for t in traces]
    handles += [Line2D([], [], color="black", label="median"),
                Line2D([], [], marker="D", ls="", markerfacecolor="white", markeredgecolor="black",
                       label="mean")]
    _legend_top(fig, handles, ncol=min(len(handles), 8))
    fig.suptitle(title, fontsize=10)
    return fig


def _window(frame: pd.DataFrame, start_s: float) -> pd.DataFrame:
    """The window whose first time is closest to `start_s` [s]."""
    firsts = frame.groupby("window")["t"].min()
    k = (firsts - start_s).abs().idxmin()
    return frame[frame["window"] == k]


def _signed_deg(angle_rad: np.ndarray) -> np.ndarray:
    """Angle [rad] to degrees in [-180, 180)."""
    return (np.asarray(angle_rad) * RAD2DEG + 180.0) % 360.0 - 180.0


def _measured_relative_wind(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(U_A [m/s], gamma_A [rad]) seen by the recorded state: the trace's observed u, v_m,
    psi and the true wind, through the MMG's relative wind (`sysid.mmg.wind`)."""
    import torch

    from sysid.mmg.wind import relative_wind

    cols = ["obs_u", "obs_v", "obs_psi", "wind_velo_true", "wind_dir_true"]
    wind = relative_wind(*torch.as_tensor(frame[cols].to_numpy(dtype=float)).unbind(-1))
    return wind.U_A.numpy(), wind.gamma_A.numpy()


def actuator_wind(traces: list[ModelTrace], start_s: float, title: str,
                  into: FigureBase | None = None) -> FigureBase:
    """Propeller speed [rps], rudder angle [deg] and the relative wind speed [m/s] and
    direction [deg] (Figs. 6, 8) in the window starting nearest `start_s`. The relative
    wind of each model is the one seen by its predicted state; "measured" uses the
    recorded state."""
    fig = _canvas(into, TALL)
    axes = fig.subplots(4, 1, sharex=True)
    first = _window(traces[0].frame, start_s)
    t = first["t"].to_numpy()
    axes[0].plot(t, first["n_prop"], color=MEASURED, drawstyle="steps-post")
    axes[1].plot(t, first["delta_rudder"] * RAD2DEG, color=MEASURED, drawstyle="steps-post")
    U_A, gamma_A = _measured_relative_wind(first)
    axes[2].plot(t, U_A, color=MEASURED, lw=1.6)
    axes[3].plot(t, _signed_deg(gamma_A), color=MEASURED, lw=1.6, ls="", marker=".", ms=3)
    for tr in traces:
        w = _window(tr.frame, start_s)
        axes[2].plot(w["t"], w["wind_velo_relative"], color=tr.colour, **tr.line(1.1))
        axes[3].plot(w["t"], _signed_deg(w["wind_dir_relative"].to_numpy()), color=tr.colour, ls="",
                     marker="x" if tr.baseline else ".", ms=2.5)
    labels = ["n_P [rps]", "δ [deg]", "U_A [m/s]", "γ_A [deg]\n(0 = from ahead)"]
    for ax, label in zip(axes, labels):
        ax.set_ylabel(label)
    axes[3].set_ylim(-180, 180)
    axes[3].set_yticks([-180, -90, 0, 90, 180])
    axes[-1].set_xlabel("t [s]")
    _legend_top(fig, _model_handles(traces))
    fig.suptitle(title, fontsize=10)
    return fig


def state_timeseries(traces: list[ModelTrace], start_s: float, title: str,
                     into: FigureBase | None = None) -> FigureBase:
    """Heading ψ [deg], u, v_m [m/s] and r [deg/s] predicted by each model against the
    measurement in the window starting nearest `start_s` (Figs. 7, 9)."""
    fig = _canvas(into, TALL)
    axes = fig.subplots(4, 1, sharex=True)
    rows = [("psi", "ψ [deg]", RAD2DEG), ("u", "u [m/s]", 1.0), ("v", "v_m [m/s]", 1.0),
            ("r", "r [deg/s]", RAD2DEG)]
    first = _window(traces[0].frame, start_s)
    for ax, (col, label, scale) in zip(axes, rows):
        obs = first[f"obs_{col}"].to_numpy() * scale
        pred = [(_window(tr.frame, start_s), tr) for tr in traces]
        if col == "psi":  # unwrap into one branch so a 0/360 crossing draws no jump
            obs = np.rad2deg(np.unwrap(first["obs_psi"].to_numpy()))
        ax.plot(first["t"], obs, color=MEASURED, lw=1.8)
        for w, tr in pred:
            y = w[f"pred_{col}"].to_numpy() * scale
            if col == "psi":
                y = np.rad2deg(np.unwrap(w["pred_psi"].to_numpy()))
                y += 360.0 * np.round((obs[0] - y[0]) / 360.0)
            ax.plot(w["t"], y, color=tr.colour, **tr.line(1.2))
        ax.set_ylabel(label)
    axes[-1].set_xlabel("t [s]")
    _legend_top(fig, _model_handles(traces))
    fig.suptitle(title, fontsize=10)
    return fig


def ship_outline(L: float, B: float) -> np.ndarray:
    """Waterline outline in the body frame, (n, 2) of (x forward, y starboard) [m]."""
    return np.array([[-L / 2, -B / 2], [0.3 * L, -B / 2], [L / 2, 0.0], [0.3 * L, B / 2],
                     [-L / 2, B / 2], [-L / 2, -B / 2]])


def _outline_at(outline: np.ndarray, x: float, y: float, psi: float) -> tuple[np.ndarray, np.ndarray]:
    """Outline placed at earth position (x north, y east) [m] and heading psi [rad];
    returned as (east, north) for plotting."""
    c, s = math.cos(psi), math.sin(psi)
    north = x + outline[:, 0] * c - outline[:, 1] * s
    east = y + outline[:, 0] * s + outline[:, 1] * c
    return east, north


def trajectories(traces: list[ModelTrace], L: float, B: float, title: str,
                 into: FigureBase | None = None) -> FigureBase:
    """Earth-frame trajectories (x0 north, y0 east [m]) of each model's windows against the
    measured track, with the ship's outline every `interval` seconds (Figs. 10-12)."""
    n = len(traces)
    measured = traces[0].frame.drop_duplicates("t").sort_values("t")
    east = np.concatenate([measured["obs_y"].to_numpy()] + [t.frame["pred_y"].to_numpy() for t in traces])
    north = np.concatenate([measured["obs_x"].to_numpy()] + [t.frame["pred_x"].to_numpy() for t in traces])
    tall = np.ptp(north) > 1.3 * np.ptp(east)
    cols = n if tall else (min(n, 2) if n > 1 else 1)  # tall tracks side by side
    rows = math.ceil(n / cols)
    fig = _canvas(into, (10.0, 5.4 if tall else 3.6 * rows + 0.8))
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    outline = ship_outline(L, B)
    duration = float(measured["t"].iloc[-1] - measured["t"].iloc[0])
    interval = max(10.0, 10.0 * round(duration / 20.0 / 10.0))
    for ax, tr in zip(axes, traces):
        ax.plot(measured["obs_y"], measured["obs_x"], color=MEASURED, lw=1.4)
        for _, w in tr.frame.groupby("window", sort=True):
            ax.plot(w["pred_y"], w["pred_x"], color=tr.colour, **tr.line(1.3))
            ax.plot(w["pred_y"].iloc[0], w["pred_x"].iloc[0], "o", color=tr.colour, ms=3)
            marks = w[((w["t_rel"] % interval) < 0.5)]
            for row in marks.itertuples(index=False):
                e, nn = _outline_at(outline, row.pred_x, row.pred_y, row.pred_psi)
                ax.plot(e, nn, color=tr.colour, lw=0.7, ls="--" if tr.baseline else "-")
                e, nn = _outline_at(outline, row.obs_x, row.obs_y, row.obs_psi)
                ax.plot(e, nn, color=MEASURED, lw=0.6, alpha=0.7)
        ax.set_title(tr.label, fontsize=9)
    pad = 0.6 * L
    for ax in axes[:n]:  # same limits in every panel (equal aspect, boxes sized to the limits)
        ax.set_xlim(np.nanmin(east) - pad, np.nanmax(east) + pad)
        ax.set_ylim(np.nanmin(north) - pad, np.nanmax(north) + pad)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("y0 (east) [m]")
        ax.set_ylabel("x0 (north) [m]")
    for ax in axes[n:]:
        ax.set_visible(False)
    handles = _model_handles(traces)
    handles.append(Line2D([], [], color="grey", lw=0.7,
                          label=f"ship outline every {interval:.0f} s ({L:g} m x {B:g} m)"))
    handles.append(Line2D([], [], color="grey", marker="o", ls="", ms=3, label="window start"))
    _legend_top(fig, handles, ncol=4)
    fig.suptitle(title, fontsize=10)
    return fig


def _spans(t: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """Intervals [s] where `flag` holds, each sample covering [t - 0.5, t + 0.5] s."""
    spans, start, prev = [], None, 0.0  # prev: the sample before; read only after one
    for ti, f in zip(t, flag):
        if f and start is None:
            start = ti
        if not f and start is not None:
            spans.append((start - 0.5, prev + 0.5))
            start = None
        prev = ti
    if start is not None:
        spans.append((start - 0.5, prev + 0.5))
    return spans


def knn_distance(trace: ModelTrace, threshold: float | None, title: str,
                 into: FigureBase | None = None) -> FigureBase:
    """kNN distance [-] of the hybrid model's inputs at each step, the gate threshold and
    the periods judged out of distribution (FNN off) shaded (Figs. 13-16)."""
    fig = _canvas(into, (10.0, 3.8))
    ax = fig.subplots()
    frame = trace.frame.sort_values(["window", "t_rel"])
    t, d = _broken(frame, "knn_distance")
    ax.plot(t, d, color=KNN_LINE, lw=1.1)
    handles: list[Artist] = [Line2D([], [], color=KNN_LINE, label="kNN distance")]
    if threshold is not None:
        ax.axhline(threshold, color=THRESHOLD, ls="--", lw=1.4)
        handles.append(Line2D([], [], color=THRESHOLD, ls="--", label=f"threshold {threshold:.3g}"))
    off = frame["gate_on"].to_numpy() < 0.5
    for a, b in _spans(frame["t"].to_numpy(), off):
        ax.axvspan(a, b, color=OOD_SHADE, alpha=0.25, lw=0)
    share = 100.0 * off.mean() if len(off) else 0.0
    handles.append(Patch(color=OOD_SHADE, alpha=0.25, label=f"OOD, FNN off ({share:.0f}% of steps)"))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("kNN distance [-]")
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    fig.suptitle(title, fontsize=10)
    return fig


AXES = [("X", "X [N]"), ("Y", "Y [N]"), ("N", "N [N m]")]


def force_components(trace: ModelTrace, title: str, into: FigureBase | None = None) -> FigureBase:
    """Hull, propeller, rudder, wind and FNN forces X, Y [N] and moment N [N m] along the
    predictions (Figs. 17, 19); windows are joined with gaps."""
    fig = _canvas(into, TALL)
    axes = fig.subplots(3, 1, sharex=True)
    def present(key: str) -> bool:  # components that are zero throughout (NN-only: H, P, R, A) are left out
        return bool(np.nanmax(np.abs(trace.frame[[f"X{key}", f"Y{key}", f"N{key}"]].to_numpy())) > 0)
    keys = [k for k in ("H", "P", "R", "A", "NN") if present(k)]
    for ax, (axis, label) in zip(axes, AXES):
        for key in keys:
            t, y = _broken(trace.frame, f"{axis}{key}")
            ax.plot(t, y, color=COMPONENT_COLOURS[key], lw=1.1 if key != "NN" else 1.5)
        ax.set_ylabel(label)
        ax.axhline(0, color="grey", lw=0.5)
    axes[-1].set_xlabel("t [s]")
    handles = [Line2D([], [], color=COMPONENT_COLOURS[k], label=f"{k} ({COMPONENT_LABELS[k]})") for k in keys]
    _legend_top(fig, handles)
    fig.suptitle(title, fontsize=10)
    return fig


def force_models(trace: ModelTrace, title: str, into: FigureBase | None = None) -> FigureBase:
    """F_MMG (H + P + R + A), F_NN and their sum for X, Y [N] and N [N m] (Figs. 18, 20)."""
    fig = _canvas(into, TALL)
    axes = fig.subplots(3, 1, sharex=True)
    frame = trace.frame.copy()
    for axis, _ in AXES:
        frame[f"{axis}MMG"] = sum(frame[f"{axis}{k}"] for k in ("H", "P", "R", "A"))
        frame[f"{axis}SUM"] = frame[f"{axis}MMG"] + frame[f"{axis}NN"]
    for ax, (axis, label) in zip(axes, AXES):
        for key, lw, ls in (("MMG", 1.2, "-"), ("NN", 1.4, "-"), ("SUM", 1.0, "--")):
            t, y = _broken(frame, f"{axis}{key}")
            ax.plot(t, y, color=COMPONENT_COLOURS[key], lw=lw, ls=ls)
        ax.set_ylabel(label)
        ax.axhline(0, color="grey", lw=0.5)
    axes[-1].set_xlabel("t [s]")
    handles = [Line2D([], [], color=COMPONENT_COLOURS["MMG"], label="F_MMG"),
               Line2D([], [], color=COMPONENT_COLOURS["NN"], label="F_NN"),
               Line2D([], [], color=COMPONENT_COLOURS["SUM"], ls="--", label="F_MMG + F_NN")]
    _legend_top(fig, handles)
    fig.suptitle(title, fontsize=10)
    return fig


def fnn_error_scatter(groups: list[tuple[str, str, pd.DataFrame]], title: str,
                      into: FigureBase | None = None) -> FigureBase:
    """|F_NN| against the absolute velocity prediction error (Fig. 21): |X_NN| [N] vs |u|
    error [m/s], |Y_NN| [N] vs v_m error [m/s], |N_NN| [N m] vs r error [rad/s]; `groups`
    are (label, colour, pooled trace frame)."""
    fig = _canvas(into, (10.0, 4.2))
    axes = fig.subplots(1, 3)
    pairs = [("X", "u", "|X_NN| [N]", "|error of u| [m/s]"), ("Y", "v", "|Y_NN| [N]", "|error of v_m| [m/s]"),
             ("N", "r", "|N_NN| [N m]", "|error of r| [rad/s]")]
    for ax, (axis, col, xlabel, ylabel) in zip(axes, pairs):
        for _label, colour, frame in groups:
            ax.scatter(np.abs(frame[f"{axis}NN"]), np.abs(frame[f"pred_{col}"] - frame[f"obs_{col}"]),
                       s=4, color=colour, alpha=0.35, lw=0, rasterized=len(frame) > 5000)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
    handles = [Line2D([], [], marker="o", ls="", color=c, label=l) for l, c, _ in groups]
    _legend_top(fig, handles)
    fig.suptitle(title, fontsize=10)
    return fig


def loss_curves(histories: list[tuple[str, str, pd.DataFrame, int | None]], title: str,
                into: FigureBase | None = None) -> FigureBase:
    """Training loss (solid) and early-stopping loss (dashed: L_v on the validation windows
    during training, before the kNN gate) [-] per epoch, log scale; the best epoch is marked. `histories` are (label, colour, history frame, best epoch)."""
    fig = _canvas(into, (10.0, 4.6))
    ax = fig.subplots()
    positive, marked = True, set()
    for _label, colour, hist, best in histories:
        x = hist["epoch"].to_numpy()
        last = np.ones(len(hist), dtype=bool)
        if "stage" in hist.columns and hist["stage"].nunique() > 1:  # stages restart their epochs
            x = np.arange(1, len(hist) + 1)
            stages = hist["stage"].astype(str).to_numpy()
            last = stages == stages[-1]
            for i in np.nonzero(stages[1:] != stages[:-1])[0]:
                ax.axvline(x[i] + 0.5, color=colour, ls=":", lw=0.8)
                if (x[i], stages[i + 1]) in marked:
                    continue
                marked.add((x[i], stages[i + 1]))
                ax.annotate(f"stage {stages[i + 1]}", (x[i] + 0.5, 0.03), xycoords=("data", "axes fraction"),
                            xytext=(2, 0), textcoords="offset points", fontsize=7, color=colour,
                            ha="left", va="bottom", rotation=90)
        ax.plot(x, hist["train_loss"], color=colour, lw=1.3)
        ax.plot(x, hist["early_stopping_loss"], color=colour, lw=1.3, ls="--")
        positive &= bool((hist[["train_loss", "early_stopping_loss"]].to_numpy() > 0).all())
        hit = last & (hist["epoch"].to_numpy() == best)
        if best is not None and hit.any():
            ax.plot(x[hit][0], hist["early_stopping_loss"].to_numpy()[hit][0], "*", color=colour, ms=9)
    if positive:
        ax.set_yscale("log")
    staged = any("stage" in h.columns and h["stage"].nunique() > 1 for _, _, h, _ in histories)
    ax.set_xlabel("epoch [-] (stages one after the other)" if staged else "epoch [-]")
    ax.set_ylabel("loss [-]")
    handles = [Line2D([], [], color=c, label=l) for l, c, _, _ in histories]
    handles += [Line2D([], [], color="grey", label="training"),
                Line2D([], [], color="grey", ls="--", label="early stopping (validation)"),
                Line2D([], [], color="grey", marker="*", ls="", label="best epoch")]
    ax.legend(handles=handles, fontsize=8, ncol=2, loc="upper right")
    fig.suptitle(title, fontsize=10)
    return fig


def identified_coefficients(names: list[str], estimate: list, two_sigma: list, prior: list,
                            correlation: list, title: str, into: FigureBase | None = None) -> FigureBase:
    """Left: each identified coefficient [-] with its ± 2 sigma bar beside its prior value
    (the ship file's); right: their correlation matrix [-1, 1]."""
    fig = _canvas(into, (10.0, 4.0))
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.3, 1.0]})
    y = np.arange(len(names))[::-1]
    est = np.array([np.nan if v is None else v for v in estimate], dtype=float)
    err = np.array([np.nan if v is None else v for v in two_sigma], dtype=float)
    left.errorbar(est, y, xerr=np.where(np.isfinite(err), err, 0.0), fmt="o", color=MEASURED, capsize=3,
                  label="identified ± 2σ")
    if prior:
        left.plot(np.asarray(prior, dtype=float), y, "s", mfc="none", color="#1f5fbf", label="prior (ship file)")
    left.axvline(0.0, color="grey", lw=0.6)
    left.set_yticks(y, names)
    left.set_xlabel("coefficient value [-] (non-dimensional)")
    left.legend(fontsize=8, loc="best")
    corr = np.array([[np.nan if v is None else v for v in row] for row in correlation], dtype=float)
    image = right.imshow(corr, vmin=-1.0, vmax=1.0, cmap="RdBu_r")
    right.set_xticks(range(len(names)), names, rotation=45, ha="right")
    right.set_yticks(range(len(names)), names)
    right.grid(False)
    for i in range(len(names)):
        for j in range(len(names)):
            if np.isfinite(corr[i, j]):
                right.text(j, i, f"{corr[i, j]:.2f}", ha="center", va="center", fontsize=7)
    fig.colorbar(image, ax=right, label="correlation [-]")
    fig.suptitle(title, fontsize=10)
    return fig


@dataclass
class SeedSpread:
    """One learned model's RMSE per seed: rows scenario, columns rmse_u, rmse_v, rmse_r, seed."""

    label: str
    colour: str
    rmse: pd.DataFrame


def seed_boxplots(models: list[SeedSpread], scenarios: list[str], title: str,
                  paper: dict | None = None, into: FigureBase | None = None) -> FigureBase:
    """RMSE of u, v_m [m/s] and r [rad/s] across seeds, per scenario and model: boxes = IQR
    over the seeds, dots = single seeds, black bar = the paper's hybrid (when given)."""
    fig = _canvas(into, (10.0, 4.8))
    axes = fig.subplots(1, 3)
    width = 0.8 / max(len(models), 1)
    for ax, (col, name, unit) in zip(axes, [("u", "u", "m/s"), ("v", "v_m", "m/s"), ("r", "r", "rad/s")]):
        for j, m in enumerate(models):
            positions = np.arange(len(scenarios)) + (j - (len(models) - 1) / 2) * width
            data = [m.rmse.loc[m.rmse.scenario == s, f"rmse_{col}"].to_numpy() for s in scenarios]
            box = ax.boxplot(data, positions=positions, widths=width * 0.85, patch_artist=True,
                             medianprops={"color": "black"}, showfliers=False)
            for patch in box["boxes"]:
                patch.set_facecolor(m.colour)
                patch.set_alpha(0.75)
            for x, values in zip(positions, data):
                ax.plot(np.full(len(values), x), values, ".", color="black", markersize=3)
        if paper:
            for i, s in enumerate(scenarios):
                ref = paper.get(s)
                if ref is not None:
                    ax.hlines(ref[["u", "v", "r"].index(col)], i - 0.45, i + 0.45, colors="black", lw=1.6)
        ax.set_xticks(range(len(scenarios)), scenarios, rotation=35, ha="right", fontsize=8)
        ax.set_ylabel(f"RMSE of {name} [{unit}]")
        ax.set_title(name)
    handles: list[Artist] = [Patch(facecolor=m.colour, edgecolor="black", label=m.label) for m in models]
    handles.append(Line2D([], [], marker=".", ls="", color="black", label="one seed"))
    if paper:
        handles.append(Line2D([], [], color="black", lw=1.6, label="paper's hybrid"))
    _legend_top(fig, handles, ncol=min(len(handles), 6))
    fig.suptitle(title, fontsize=10)
    return fig


def relative_rmse(cells, title: str, into: FigureBase | None = None) -> FigureBase:
    """Every Table 7/8 cell of one data set relative to MMG-only (`sysid.report.cell_ratios.CellRatios`):
    rows the horizons, columns u, v_m, r, scenarios along x; per learned model its seed mean
    (marker) with the min-max over the seeds (bar; none for one seed), the paper's printed
    hybrid (black bar) and the baseline MMG at 1 (dashed). One log axis for all panels:
    RMSE / RMSE of the baseline [-], below 1 is better than the baseline.

    Artists carry ``gid``s "{model}|{horizon}|{channel}" (markers), "... |spread" (seed bars)
    and "paper|{horizon}|{channel}", so the plotted values can be read back."""
    from sysid.report.cell_ratios import CHANNEL_NAMES, CHANNELS

    fig = _canvas(into, (10.0, 6.4))
    rows, scenarios = list(cells.horizons), list(cells.scenarios)
    axes = np.atleast_2d(fig.subplots(len(rows), 3, sharey=True, squeeze=False))
    x = np.arange(len(scenarios))
    width = 0.7 / max(len(cells.models), 1)
    for i, horizon in enumerate(rows):
        for j, c in enumerate(CHANNELS):
            ax = axes[i, j]
            ax.axhline(1.0, color=cells.baseline_colour, ls="--", lw=1.2)
            for k, model in enumerate(cells.models):
                at = cells.cells[(cells.cells.model == model.label) & (cells.cells.horizon_s == horizon)
                                 & (cells.cells.channel == c)].set_index("scenario").reindex(scenarios)
                xs = x + (k - (len(cells.models) - 1) / 2) * width
                ax.plot(xs, at.ratio.to_numpy(), "o", color=model.colour, markeredgecolor="black",
                        markeredgewidth=0.5, markersize=5, gid=f"{model.label}|{horizon}|{c}", zorder=3)
                if (at.n_seeds > 1).any():
                    ax.vlines(xs, at.low.to_numpy(), at.high.to_numpy(), colors=model.colour, lw=2.0,
                              gid=f"{model.label}|{horizon}|{c}|spread", zorder=2)
            paper = cells.paper[(cells.paper.horizon_s == horizon) & (cells.paper.channel == c)]
            paper = paper.set_index("scenario").reindex(scenarios)
            ax.hlines(paper.ratio.to_numpy(), x - 0.4, x + 0.4, colors="black", lw=1.4,
                      gid=f"paper|{horizon}|{c}", zorder=4)
            ax.set_yscale("log")
            ax.yaxis.set_major_locator(FixedLocator(RATIO_TICKS))
            ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_xticks(x, scenarios if i == len(rows) - 1 else [""] * len(scenarios), rotation=35,
                          ha="right", fontsize=8)
            ax.set_title(f"{CHANNEL_NAMES[c]}, {horizon} s predictions", fontsize=9)
            if j == 0:
                ax.set_ylabel(f"RMSE / RMSE of {cells.baseline} [-]", fontsize=8)
    seeds = cells.seeds
    mean = f" (mean of {seeds} seeds; bar: min-max)" if seeds > 1 else ""
    handles = [Line2D([], [], color=cells.baseline_colour, ls="--", lw=1.2, label=f"{cells.baseline} = 1")]
    handles += [Line2D([], [], marker="o", ls="", color=m.colour, markeredgecolor="black", markeredgewidth=0.5,
                       label=m.label + mean) for m in cells.models]
    handles.append(Line2D([], [], color="black", lw=1.4, label=f"paper's hybrid {cells.dataset}"))
    _legend_top(fig, handles, ncol=len(handles))
    fig.suptitle(title, fontsize=10)
    return fig
