"""Samples of logs outside what a ship's force models cover.

The ``standard`` MMG propeller (K_T polynomial in the advance ratio) holds for the first
quadrant only: propeller ahead (n > 0) and ship ahead (u > 0); astern revolutions or
astern motion need the ``four_quadrant`` family. The ``standard`` MMG rudder (normal force
f_alpha U_R^2 sin alpha_R, no stall) holds for ahead flow up to the hard-over angle
`STANDARD_RUDDER_MAX_DEG`; the ``four_quadrant`` rudder covers every angle and flow.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

STANDARD_RUDDER_MAX_DEG = 35.0  # deg, the hard-over angle of the IMO maneuvers


def one_quadrant_propeller(models: Mapping[str, str]) -> bool:
    """Whether the propeller family of `models` (component -> family) holds for the first
    quadrant only (n > 0, u > 0): every family but ``four_quadrant``."""
    return models.get("propeller", "") != "four_quadrant"


def astern_samples(models: Mapping[str, str], u: np.ndarray, n_prop: np.ndarray) -> np.ndarray:
    """(N,) True for the samples outside the propeller model's quadrant: under a one-quadrant
    propeller those with astern revolutions (n_prop < 0 [rps]) or going astern (u < 0 [m/s]);
    none under ``four_quadrant``. u, n_prop: (N,)."""
    if not one_quadrant_propeller(models):
        return np.zeros(len(u), dtype=bool)
    return (np.asarray(n_prop) < 0) | (np.asarray(u) < 0)


def windows_touching(outside: np.ndarray, starts: np.ndarray, length: int) -> np.ndarray:
    """(W,) True for the windows of `length` samples at `starts` (W,) holding at least one
    sample flagged in `outside` (N,)."""
    before = np.concatenate([[0], np.cumsum(outside)])
    starts = np.asarray(starts, dtype=int)
    return before[np.minimum(starts + length, len(outside))] - before[starts] > 0


def outside_force_models(models: Mapping[str, str], u: np.ndarray, n_prop: np.ndarray,
                         delta: np.ndarray) -> list[str]:
    """Sentences naming the share of samples outside the force models `models` (component ->
    family) cover, from the surge speed u (N,) [m/s], revolutions n_prop (N,) [rps] and
    rudder angle delta (N,) [rad] of the logs; empty when every sample is covered."""
    out = []
    total = len(u)
    if not total:
        return out
    if one_quadrant_propeller(models):
        astern_n, astern_u = float(np.mean(n_prop < 0)), float(np.mean((u < 0) & (n_prop >= 0)))
        if astern_n > 0:
            out.append(f"{100 * astern_n:.1f} % of the samples have astern revolutions (n_prop < 0), which the "
                       f"one-quadrant propeller model {models.get('propeller')!r} does not cover: use "
                       "[propeller] model = \"four_quadrant\" in the ship file, or leave those logs out")
        if astern_u > 0:
            out.append(f"{100 * astern_u:.1f} % of the samples go astern (u < 0) with ahead revolutions, which the "
                       f"propeller model {models.get('propeller')!r} does not cover")
    if models.get("rudder", "") == "standard":
        beyond = float(np.mean(np.abs(delta) > math.radians(STANDARD_RUDDER_MAX_DEG) + 1e-9))
        if beyond > 0:
            out.append(f"{100 * beyond:.1f} % of the samples have |delta_rudder| beyond "
                       f"{STANDARD_RUDDER_MAX_DEG:g} deg, which the standard rudder model (no stall) does not cover")
    return out
