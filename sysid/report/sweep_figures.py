"""Figures of a sweep: validation loss against each varied key, and the spread over seeds
of each configuration (best first)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from matplotlib.figure import Figure, FigureBase
from matplotlib.lines import Line2D

CHOSEN = "#d62728"
TRIAL = "#1f77b4"


def _canvas(into: FigureBase | None, size: tuple[float, float]) -> FigureBase:
    return into if into is not None else Figure(figsize=size, layout="constrained")


def _numeric(values: pd.Series) -> bool:
    try:
        numbers = pd.to_numeric(values)
    except (TypeError, ValueError):
        return False
    return bool(numbers.notna().all())


def objective_by_key(trials: pd.DataFrame, keys: list[str], chosen: str | None, title: str,
                     into: FigureBase | None = None) -> FigureBase:
    """Validation loss [-] of every trial (dots: one seed each) against each varied key;
    lines join the means over seeds and the other keys; the chosen configuration in red."""
    keys = keys or ["point"]
    fig = _canvas(into, (10.0, 3.6 if len(keys) <= 3 else 6.4))
    cols = min(len(keys), 3)
    axes = np.atleast_1d(fig.subplots(math.ceil(len(keys) / cols), cols)).ravel()
    done = trials[trials.status == "complete"]
    for ax, key in zip(axes, keys):
        values = list(dict.fromkeys(done[key]))
        numeric = _numeric(pd.Series(values)) and len(values) > 1
        if numeric:
            order = sorted(float(v) for v in values)
            x_of = {v: float(v) for v in values}
            positive = all(v > 0 for v in order)
            if positive and order[-1] / order[0] > 20:
                ax.set_xscale("log")
        else:
            x_of = {v: i for i, v in enumerate(values)}
            ax.set_xticks(range(len(values)), [str(v) for v in values], rotation=20, fontsize=8)
        x = done[key].map(x_of)
        ax.plot(x, done.val_loss_multistep, ".", color=TRIAL, alpha=0.7)
        means = done.groupby(key, sort=False).val_loss_multistep.mean()
        xs = sorted((x_of[v], m) for v, m in means.items())
        ax.plot([a for a, _ in xs], [b for _, b in xs], "-", color="grey", lw=1)
        if chosen is not None:
            mine = done[done.point == chosen]
            ax.plot(mine[key].map(x_of), mine.val_loss_multistep, "o", mfc="none", color=CHOSEN, ms=7)
        ax.set_xlabel(key + ("" if numeric else " (categories)"))
        ax.set_ylabel("val_loss_multistep [-]")
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    handles = [Line2D([], [], marker=".", ls="", color=TRIAL, label="one trial (seed)"),
               Line2D([], [], color="grey", label="mean over seeds and other keys"),
               Line2D([], [], marker="o", ls="", mfc="none", color=CHOSEN, label="chosen configuration")]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, frameon=False, fontsize=8)
    fig.suptitle(title, fontsize=10)
    return fig


def seed_spread(trials: pd.DataFrame, points: pd.DataFrame, chosen: str | None, title: str,
                top: int = 12, into: FigureBase | None = None) -> FigureBase:
    """Validation loss [-] of each configuration over its seeds (boxes, dots: seeds), the
    `top` best by mean first; the chosen one in red."""
    fig = _canvas(into, (10.0, 4.6))
    ax = fig.subplots()
    names = list(points.point[:top])
    done = trials[trials.status == "complete"]
    data = [done[done.point == n].val_loss_multistep.to_numpy() for n in names]
    box = ax.boxplot(data, patch_artist=True, showfliers=False, medianprops={"color": "black"})
    for patch, name in zip(box["boxes"], names):
        patch.set_facecolor(CHOSEN if name == chosen else "#aec7e8")
        patch.set_alpha(0.7)
    for i, values in enumerate(data, 1):
        ax.plot(np.full(len(values), i), values, ".", color="black", ms=4)
    ax.set_xticks(range(1, len(names) + 1), names, rotation=30, ha="right", fontsize=7)
    ax.set_ylabel("val_loss_multistep [-]")
    ax.set_xlabel("configuration (best mean first)")
    fig.suptitle(title, fontsize=10)
    return fig
