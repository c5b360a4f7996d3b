"""A verdict of known truth: a model whose per-window RMSE is a fixed factor x the ship file's
MMG's on 3 logs of 8 windows (the same logs and MMG for every call)."""
from __future__ import annotations

import numpy as np

from sysid.evaluation.judgement import CHANNELS, PairedCell, VerdictRule
from sysid.evaluation.verdict import SHIP_FILE_MMG, TEST, BaselineVerdict, ChannelCell, verdict_of

RULE = VerdictRule(resamples=500)


def seed_verdict(factor: float, model: str = "hybrid") -> BaselineVerdict:
    """One seed: the model's per-window RMSE `factor` x the MMG's on 3 logs of 8 windows."""
    rng = np.random.default_rng(0)          # the same logs and MMG in every seed
    cells = []
    for log in ("a", "b", "c"):
        base = 0.01 + 0.01 * rng.random(8)
        for channel in CHANNELS:
            cells.append(PairedCell(log, log.upper(), 30.0, channel, (factor * base)[None, :], base[None, :],
                                    30.0 * np.arange(8)))
    pooled = tuple(ChannelCell(TEST, 30.0, c, factor, {SHIP_FILE_MMG: 1.0}) for c in CHANNELS)
    return verdict_of(model, (SHIP_FILE_MMG,), pooled, {}, {TEST: {SHIP_FILE_MMG: tuple(cells)}}, RULE)
