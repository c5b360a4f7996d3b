"""reproduction.json (summary.json before) of a reproduction directory (``sysid reproduce``) as a typed record: what
`sysid.protocol.reproduce.reproduce` returns, writes, and the CLI and the report read."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sysid.records.base import JsonRecord


@dataclass(frozen=True)
class DatasetScore(JsonRecord):
    """A model against the baseline MMG, the paper's hybrid and NN-only on one training data
    set: RMSE reductions (1 - ours / MMG's, mean over u, v_m, r; per scenario at 30 s) and
    cells (scenario x u, v_m, r x horizon) beating the paper's hybrid and beating NN-only
    (`nn`: its label; with seeds both sides are seed means). The NN fields are None in a
    summary written before they existed or when NN-only was not run on this data set;
    ``paper_cells_hybrid_beating_nn``: the same count between the paper's printed hybrid and NN."""

    reduction_vs_mmg_30s_by_scenario: dict[str, float]
    reduction_vs_mmg_30s_mean: float
    reduction_vs_mmg_100s_mean: float
    cells_beating_paper_hybrid: int
    cells: int
    nn: str | None = None
    cells_beating_nn: int | None = None
    paper_cells_hybrid_beating_nn: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def least_reduction_30s(self) -> float:
        """The smallest 30 s reduction over the scenarios."""
        return min(self.reduction_vs_mmg_30s_by_scenario.values())

    def by_scenario_text(self) -> str:
        """The 30 s reductions per scenario: "Berthing 37 %, Random 11 %"."""
        return ", ".join(f"{k} {100 * v:.0f} %" for k, v in self.reduction_vs_mmg_30s_by_scenario.items())

    def nn_text(self) -> str:
        """"beats NN on 30/36 cells (the paper's hybrid beats its NN on 25/36)", or "" when NN-only was not compared."""
        if self.cells_beating_nn is None:
            return ""
        paper = (f" (the paper's hybrid beats its NN on {self.paper_cells_hybrid_beating_nn}/{self.cells})"
                 if self.paper_cells_hybrid_beating_nn is not None else "")
        return f"beats {self.nn} on {self.cells_beating_nn}/{self.cells} cells{paper}"


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
