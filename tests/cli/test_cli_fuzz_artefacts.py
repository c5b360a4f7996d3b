"""Fuzzing the artefacts a run directory holds: a kNN bank or model that breaks its own
contract (transposed, empty, k larger than the bank, NaN, a zero standard deviation) and
is then resealed, so that the manifest vouches for it. `evaluate` and `export` each refuse
it with one line naming the file and the field (`sysid.runs.knn_bank.KnnBank`), never a
traceback and never a silently disabled gate."""
from __future__ import annotations


import pytest
import torch

from cli_fixtures import run_copy, sysid  # noqa: F401 (fixtures)
from cli_harness import assert_refused
from sysid.store.manifest import write_manifest


def _edit_bank(run, edit) -> int:
    """Edit knn.pt's dict in place and reseal the run; returns the bank's size before."""
    knn = torch.load(run / "knn.pt", weights_only=True)
    size = knn["bank"].shape[0]
    edit(knn)
    torch.save(knn, run / "knn.pt")
    write_manifest(run, "run")
    return size


def _transposed(knn):
    knn["bank"] = knn["bank"].T.contiguous()


def _empty(knn):
    knn["bank"], knn["train_distances"] = knn["bank"][:0], knn["train_distances"][:0]


def _k_huge(knn):
    knn["k"] = torch.tensor(100000)


def _nan(knn):
    knn["bank"][3, 1] = float("nan")


def _alpha_one(knn):
    knn["alpha"] = torch.tensor(1.5, dtype=torch.float64)


def _no_threshold(knn):
    del knn["threshold"]


BANK_CASES = {  # name -> (edit, what the error line says; {n}: the bank's size, 9: the gate's inputs)
    "transposed": (_transposed, "knn.pt: bank has shape (9, {n}), transposed: expected one row per training vector"),
    "empty": (_empty, "knn.pt: bank is empty (0 x 9)"),
    "k larger than the bank": (_k_huge, "knn.pt: k = 100000 must be a whole number from 1 to the bank's {n} rows"),
    "NaN in the bank": (_nan, "knn.pt: bank holds NaN or inf values"),
    "alpha 1.5": (_alpha_one, "knn.pt: alpha = 1.5 must lie in (0, 1)"),
    "a field missing": (_no_threshold, "knn.pt: kNN bank has no 'threshold'"),
}


@pytest.mark.parametrize("command", ["evaluate", "export"])
@pytest.mark.parametrize("case", list(BANK_CASES))
def test_a_resealed_broken_knn_bank_is_refused(sysid, run_copy, files, tmp_path, case, command):  # noqa: F811
    edit, says = BANK_CASES[case]
    size = _edit_bank(run_copy, edit)
    out = tmp_path / ("m.csv" if command == "evaluate" else "model.pt2")
    args = (["evaluate", run_copy, "--data", files["test"], "--horizon", "30"] if command == "evaluate"
            else ["export", run_copy, "--portable"])
    line = assert_refused(sysid(*args, "-o", out), 2, says.format(n=size), absent=(out,))
    assert str(run_copy / "knn.pt") in line


def test_a_resealed_zero_standard_deviation_is_refused(sysid, run_copy, files, tmp_path):  # noqa: F811
    state = torch.load(run_copy / "model.pt", weights_only=True)
    state["correction_net.input_std"][4] = 0.0
    torch.save(state, run_copy / "model.pt")
    write_manifest(run_copy, "run")
    out = tmp_path / "model.pt2"
    assert_refused(sysid("export", run_copy, "-o", out, "--portable"), 2,
                   "model.pt: correction_net.input_std holds a standard deviation <= 0", absent=(out,))
