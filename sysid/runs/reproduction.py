"""summary.json of a reproduction directory (``sysid reproduce``) as a typed record: what
`sysid.protocol.reproduce.reproduce` returns, writes, and the CLI and the report read."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sysid.runs.records import JsonRecord


@dataclass(frozen=True)
class DatasetScore(JsonRecord):
    """A model against the baseline MMG and the paper's hybrid on one training data set:
    RMSE reductions (1 - ours / MMG's, mean over u, v_m, r) and cells beating the paper."""

    reduction_vs_mmg_30s_by_scenario: dict[str, float]
    reduction_vs_mmg_30s_mean: float
    reduction_vs_mmg_100s_mean: float
    cells_beating_paper_hybrid: int
    cells: int
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def least_reduction_30s(self) -> float:
        """The smallest 30 s reduction over the scenarios."""
        return min(self.reduction_vs_mmg_30s_by_scenario.values())


@dataclass(frozen=True)
class Scorecard(JsonRecord):
    """`model` (label) against `baseline` (label of the MMG with the same X'vr) on D1 and D2."""

    baseline: str
    model: str
    D1: DatasetScore | None = None
    D2: DatasetScore | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def datasets(self) -> dict[str, DatasetScore]:
        """Data set -> its score, D1 then D2."""
        return {name: score for name, score in (("D1", self.D1), ("D2", self.D2)) if score is not None}


@dataclass(frozen=True)
class Reproduction(JsonRecord):
    """A reproduction's summary: wall time [s], the protocol runs done (``runs``, ensembles
    included) and all of them (``protocol``: fewer done is a partial reproduction), failed
    runs (name -> why), seeds per learned run, the scorecards (with the four runs they
    compare), the identified hybrid's cells beating the paper's hybrid (beating, cells) and
    the gate-off share of each hybrid on the Random test's 30 s predictions (None: no trace)."""

    SPARSE = True
    seconds: float | None = None
    runs: tuple[str, ...] | None = None
    failed: dict[str, str] | None = None
    protocol: tuple[str, ...] | None = None
    seeds: int | None = None
    scorecard: Scorecard | None = None
    scorecard_ensemble: Scorecard | None = None
    identified_hybrid_D2_cells_beating_paper_hybrid: tuple[int, ...] | None = None
    gate_off_share_random_30s: dict[str, float | None] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def scorecards(self) -> list[Scorecard]:
        """The hybrid's scorecard, then its ensemble's (those present)."""
        return [card for card in (self.scorecard, self.scorecard_ensemble) if card is not None]
