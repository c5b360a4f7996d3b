"""`sysid forces --run` and `sysid simulate --run`: a trained hybrid's forces, the FNN's
correction beside the MMG's components, its kNN gate per row, and its prediction beside
its physics baseline's. Truths: the MMG's components from `sysid forces --ship` of the
run's copy of its ship file; the gate's distance from a brute-force numpy kNN over the
run's bank (knn.pt); each predicted Euler step from the forces' state derivative."""
from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from cli_fixtures import sysid  # noqa: F401 (fixture)
from sysid.channel_names import FORCE, INPUTS, STATE
from sysid.hybrid.correction import correction_inputs
from sysid.mmg.wind import relative_wind
from sysid.runs.layout import load_model

MMG_COLUMNS = [f"{a}{k}" for k in ("H", "P", "R", "A") for a in FORCE]


def _ship_copy(run_dir):
    return next((run_dir / "ship").glob("*.toml"))


def _brute_force_distance(run_dir, rows: pd.DataFrame) -> tuple[np.ndarray, float]:
    """(d_kNN of each row by numpy over every bank vector, the gate's threshold)."""
    exp, model = load_model(run_dir)
    bank = torch.load(run_dir / "knn.pt", weights_only=True)
    bank = (bank["bank"] if isinstance(bank, dict) else bank).double().numpy()
    x = torch.tensor(rows[list(STATE)].to_numpy(dtype=float))
    u = torch.tensor(rows[list(INPUTS)].to_numpy(dtype=float))
    wind = torch.stack(relative_wind(x[:, 1], x[:, 3], x[:, 4], u[:, 2], u[:, 3]), -1)
    with torch.no_grad():
        z = model.gate_coordinates(correction_inputs(x, u, wind)).double().numpy()
    d = np.sort(np.sqrt(((z[:, None] - bank[None]) ** 2).sum(-1)), 1)[:, :exp.gate.k].mean(1)
    return d, float(model.gate.threshold)


def test_simulate_and_forces_of_a_run_show_the_correction_and_the_gate(sysid, trained, files, tmp_path):  # noqa: F811
    run_csv, mmg_csv = tmp_path / "run.csv", tmp_path / "mmg.csv"
    outcome = sysid("simulate", "--run", trained, "--log", files["test"], "--start", "10", "--horizon", "40",
                    "-o", run_csv)
    assert outcome.code == 0, outcome.err
    assert "the physics baseline: mmg_ columns" in outcome.out and "kNN gate" in outcome.out
    assert sysid("simulate", "--ship", _ship_copy(trained), "--log", files["test"], "--start", "10", "--horizon",
                 "40", "-o", mmg_csv).code == 0
    predicted, physics = pd.read_csv(run_csv), pd.read_csv(mmg_csv)
    # the physics baseline's prediction is the ship file's MMG's
    np.testing.assert_allclose(predicted[[f"mmg_{c}" for c in STATE]].to_numpy(), physics[list(STATE)].to_numpy(),
                               rtol=1e-12, atol=1e-12)
    assert np.abs(predicted[["u", "v", "r"]].to_numpy() - physics[["u", "v", "r"]].to_numpy()).max() > 1e-6

    rows = predicted[list(STATE) + list(INPUTS)]
    rows_csv, forces_csv = tmp_path / "rows.csv", tmp_path / "forces.csv"
    rows.to_csv(rows_csv, index=False)
    outcome = sysid("forces", rows_csv, "--run", trained, "-o", forces_csv)
    assert outcome.code == 0, outcome.err
    forces = pd.read_csv(forces_csv)
    assert sysid("forces", rows_csv, "--ship", _ship_copy(trained), "-o", mmg_csv).code == 0
    mmg = pd.read_csv(mmg_csv)
    # the run's MMG: the ship file's coefficients as the float32 training kept them
    np.testing.assert_allclose(forces[MMG_COLUMNS].to_numpy(), mmg[MMG_COLUMNS].to_numpy(), rtol=1e-6, atol=1e-9)
    for a in FORCE:   # the total is the MMG's plus the FNN's
        np.testing.assert_allclose(forces[a], mmg[a] + forces[f"{a}NN"], rtol=1e-6, atol=1e-9)
    distance, threshold = _brute_force_distance(trained, rows)
    np.testing.assert_allclose(forces["knn_distance"], distance, rtol=1e-7)
    np.testing.assert_array_equal(forces["gate_on"], (distance <= threshold).astype(int))
    assert (forces.loc[forces.gate_on == 0, ["XNN", "YNN", "NNN"]].to_numpy() == 0).all()   # off: the MMG alone
    # the simulate CSV's own forces and gate are the same rows'
    np.testing.assert_allclose(predicted[["XNN", "YNN", "NNN", "knn_distance"]].to_numpy(),
                               forces[["XNN", "YNN", "NNN", "knn_distance"]].to_numpy(), rtol=1e-12, atol=1e-12)
    # every Euler step of the prediction is dt times the forces' state derivative
    state = predicted[list(STATE)].to_numpy()
    rate = forces[[f"{c}_dot" for c in STATE]].to_numpy()
    np.testing.assert_allclose(state[1:], state[:-1] + 1.0 * rate[:-1], rtol=1e-10, atol=1e-10)


def test_a_run_takes_no_ship_overrides(sysid, trained, files, tmp_path):  # noqa: F811
    outcome = sysid("forces", files["test"], "--run", trained, "--set", "Xvr=0.1", "-o", tmp_path / "f.csv")
    assert outcome.code == 2 and "--run" in outcome.err and not (tmp_path / "f.csv").exists()


def test_a_run_takes_no_other_ship(sysid, trained, tmp_path):  # noqa: F811
    """--ship beside --run was ignored: the forces were those of the run's ship (Esso Osaka),
    not of the KVLCC2 named. Refused, nothing written."""
    rows = pd.DataFrame([[0.0, 0.5, 0.0, 0.01, 0.0, 0.01, 10.0, 0.1, 0.0, 0.0]], columns=list(STATE) + list(INPUTS))
    rows.to_csv(tmp_path / "rows.csv", index=False)
    outcome = sysid("forces", tmp_path / "rows.csv", "--run", trained, "--ship", "kvlcc2_l7", "-o", tmp_path / "f.csv")
    assert outcome.code == 2 and "--ship" in outcome.err and "--run" in outcome.err
    assert not (tmp_path / "f.csv").exists()
