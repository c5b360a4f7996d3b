"""knn.pt as `KnnBank`: a written bank reloads to a gate giving the same distances, and a
bank breaking its contract (empty, transposed, k beyond its rows, NaN) is refused on load
with one line naming the file, the field and the fix."""
from __future__ import annotations

import re

import pytest
import torch

from sysid.errors import CheckpointError
from sysid.hybrid.knn_gate import KNNGate
from sysid.runs.rundir import RunDir
from sysid.runs.knn_bank import KnnBank
from sysid.runs.layout import load_model
from sysid.store.manifest import write_manifest


@pytest.fixture()
def gate() -> KNNGate:
    features = torch.randn(40, 6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    return KNNGate(k=4, alpha=0.9, features=6, dtype=torch.float64).fit(features)


def test_saved_bank_reloads_to_the_same_gate(gate, tmp_path):
    KnnBank.of(gate).save(tmp_path / "knn.pt")
    bank = KnnBank.load(tmp_path / "knn.pt", width=6)
    assert (bank.k, bank.alpha) == (4, 0.9) and bank.bank.shape == (40, 6)
    again = bank.gate(torch.float64)
    z = torch.randn(25, 6, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    assert torch.equal(again.distance(z), gate.distance(z))
    assert torch.equal(again.threshold, gate.threshold) and torch.equal(again.train_distances, gate.train_distances)


def _broken(state: dict, case: str) -> dict:
    if case == "empty":
        return {**state, "bank": state["bank"][:0], "train_distances": state["train_distances"][:0]}
    if case == "transposed":
        return {**state, "bank": state["bank"].t().contiguous()}
    if case == "k beyond the bank":
        return {**state, "k": torch.tensor(41)}
    if case == "NaN":
        bank = state["bank"].clone()
        bank[3, 2] = float("nan")
        return {**state, "bank": bank}
    raise ValueError(case)


@pytest.mark.parametrize("case, message", [
    ("empty", r"bank is empty \(0 x 6\): the gate has nothing to compare with; train the run again"),
    ("transposed", r"bank has shape \(6, 40\), transposed: expected one row per training vector, \(40, 6\)"),
    ("k beyond the bank", r"k = 41 must be a whole number from 1 to the bank's 40 rows; train the run again"),
    ("NaN", r"bank holds NaN or inf values \(a diverged training\); train the run again"),
])
def test_a_bank_breaking_its_contract_is_one_clear_line(gate, tmp_path, case, message):
    path = tmp_path / "knn.pt"
    torch.save(_broken(KnnBank.of(gate).to_state_dict(), case), path)
    with pytest.raises(CheckpointError, match=message) as err:
        KnnBank.load(path)
    assert str(err.value).startswith(f"{path}: ") and "\n" not in str(err.value)


def test_a_transposed_bank_without_distances_is_caught_by_the_models_width(gate, tmp_path):
    state = KnnBank.of(gate).to_state_dict()
    state = {k: v for k, v in state.items() if k != "train_distances"}
    torch.save({**state, "bank": state["bank"].t().contiguous()}, tmp_path / "knn.pt")
    with pytest.raises(CheckpointError, match=r"bank has shape \(6, 40\), transposed"):
        KnnBank.load(tmp_path / "knn.pt", width=6)


def test_load_model_refuses_a_transposed_bank_in_a_run(hybrid_run, tmp_path):
    """A sealed run whose knn.pt holds the bank transposed: the model is not built from it."""
    import shutil
    run = RunDir(shutil.copytree(hybrid_run.path, tmp_path / "run"))
    state = KnnBank.load(run.knn).to_state_dict()
    torch.save({**state, "bank": state["bank"].t().contiguous()}, run.knn)
    write_manifest(run.path, "run")
    with pytest.raises(CheckpointError, match=rf"^{re.escape(str(run.knn))}: bank has shape \(9, \d+\), transposed"):
        load_model(run.path)
