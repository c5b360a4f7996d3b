"""`sysid reproduce --seeds N`: every learned run trained with N seeds (on Ray), cells are
the seed mean with its spread, and the mean-of-seeds ensemble is a model of its own."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from sysid.hybrid.ensemble import SeedEnsemble
from sysid.protocol.seeds import seed_metrics


def test_seed_metrics_are_means_and_sample_std():
    rng = np.random.default_rng(0)
    frames = []
    for _ in range(4):
        frames.append(pd.DataFrame({"scenario": ["Berthing", "Random"], "file": ["a", "b"], "horizon_s": [30.0, 30.0],
                                    "n_windows": [10, 20], "rmse_u": rng.random(2), "rmse_v": rng.random(2),
                                    "rmse_r": rng.random(2)}))
    out = seed_metrics(frames)
    u = np.array([f.rmse_u.to_numpy() for f in frames])
    assert np.allclose(out.rmse_u, u.mean(0)) and np.allclose(out.std_u, u.std(0, ddof=1))
    assert list(out.n_seeds) == [4, 4] and list(out.n_windows) == [10, 20]


@pytest.mark.slow
def test_reproduce_with_two_seeds(tmp_path, dataset_dir):
    pytest.importorskip("ray.tune")
    from sysid.store.manifest import write_manifest
    from sysid.report import build_report
    from sysid.protocol.reproduce import reproduce
    from sysid.runs.layout import load_model

    out = tmp_path / "repro"
    tiny = {"training": {"epochs": 3, "warm_start_epochs": 3}, "evaluation": {"horizons": (30.0,)}}
    lines: list[str] = []
    summary = reproduce(out, dataset_dir.parent, only=["mmg_lab", "nn_D1", "hybrid_D1"], overrides=tiny, jobs=2,
                        seeds=2, log=lines.append)
    assert summary.seeds == 2 and not summary.failed
    assert summary.runs == ("mmg_lab", "nn_D1", "hybrid_D1", "nn_ensemble_D1", "hybrid_ensemble_D1")
    # the two seeds trained side by side in one trial, each into its own run directory
    from sysid.sweep.inbox import read_journal
    started = [e for e in read_journal(out) if e["event"] == "started"]
    assert sorted(e["trial"] for e in started) == ["runs/hybrid_D1/seed0", "runs/hybrid_D1/seed1",
                                                   "runs/nn_D1/seed0", "runs/nn_D1/seed1"]
    assert all(e["side_by_side"] == 2 for e in started)
    seeds = [pd.read_csv(out / "runs" / "hybrid_D1" / f"seed{k}" / "metrics.csv").set_index("scenario")
             for k in (0, 1)]
    assert not seeds[0][["rmse_u", "rmse_v", "rmse_r"]].equals(seeds[1][["rmse_u", "rmse_v", "rmse_r"]])
    table = pd.read_csv(out / "comparison.csv")
    hybrid = table[(table.model == "Hybrid") & (table.dataset == "D1")].set_index("scenario")
    for c in ("u", "v", "r"):
        values = np.array([f.loc[hybrid.index, f"rmse_{c}"].to_numpy() for f in seeds])
        assert np.allclose(hybrid[f"rmse_{c}"], values.mean(0), atol=1e-5)
        assert np.allclose(hybrid[f"std_{c}"], values.std(0, ddof=1), atol=1e-5)
    assert set(hybrid.n_seeds) == {2}
    assert "Hybrid (ensemble)" in set(table.model)
    # each ensemble records its verdict against the ship file's MMG, as its seeds do
    from sysid.runs.rundir import RunDir
    for name in ("nn_ensemble_D1", "hybrid_ensemble_D1"):
        verdict = RunDir(out / "runs" / name).read_summary().verdict
        assert verdict is not None and verdict.to_json()["baselines"] == ["MMG (ship file)"], name
    assert "± " in (out / "table7.md").read_text()
    # every run (sweep trials, side-by-side seeds, ensembles) keeps the ship file it was made with
    from sysid.mmg.ship import ships_dir
    from sysid.store.manifest import verify_manifest
    bundled = (ships_dir() / "esso_osaka.toml").read_bytes()
    for name in ("mmg_lab", "nn_D1/seed0", "hybrid_D1/seed1", "hybrid_ensemble_D1"):
        assert (out / "runs" / name / "ship" / "esso_osaka.toml").read_bytes() == bundled, name
        assert "ship/esso_osaka.toml" in verify_manifest(out / "runs" / name, "run")["files"], name

    # after training, overlapped with the last trial (sysid.protocol.overlap): NN-only's ensemble
    # and the recorded maneuvers of its seeds and of the MMG may take the slot its trial left;
    # all of it equals the same work done after training (ensemble metrics, maneuver_indices.csv)
    import shutil
    from sysid.maneuvers.recorded import RECORD_FILE, RECORDED, write_record_comparison
    from sysid.protocol.paper import run_label
    from sysid.protocol.seed_runs import SeedGroup, write_ensemble
    from sysid.runs.lifecycle import cached_test_runs

    # every piece went through the overlap (how many while a trial still ran depends on timing):
    # 2 ensembles, the predictions of mmg_lab, and per learned run its 2 seeds' and its ensemble's
    # predictions in one piece (one batched rollout)
    overlapped = next(line for line in lines if line.startswith("after training:"))
    assert overlapped.split()[4] == "5", overlapped
    again = tmp_path / "again"
    labels = {run_label(n, k, d): out / "runs" / n for n, k, d in
              (("mmg_lab", "mmg", "-"), ("nn_D1", "nn", "D1"), ("nn_ensemble_D1", "nn", "D1"))}
    write_record_comparison(again, labels, dataset_dir.parent, workers=2)
    ours = pd.read_csv(out / RECORD_FILE)
    pd.testing.assert_frame_equal(pd.read_csv(again / RECORD_FILE),
                                  ours[ours.model.isin([RECORDED, *labels])].reset_index(drop=True))
    shutil.copytree(out / "runs" / "nn_D1", again / "runs" / "nn_D1")
    exp, _ = load_model(out / "runs" / "nn_D1" / "seed0")
    write_ensemble("nn_D1", exp, SeedGroup("nn_D1", [0, 1], pd.DataFrame(), {}, None, 0.0), again,
                   cached_test_runs(dataset_dir.parent), threads=1)
    assert ((again / "runs" / "nn_ensemble_D1" / "metrics.csv").read_bytes()
            == (out / "runs" / "nn_ensemble_D1" / "metrics.csv").read_bytes())

    # the ensemble run loads from its members and averages their forces
    exp, ensemble = load_model(out / "runs" / "hybrid_ensemble_D1")
    assert isinstance(ensemble, SeedEnsemble) and len(ensemble.members) == 2
    members = [load_model(out / "runs" / "hybrid_D1" / f"seed{k}")[1] for k in (0, 1)]
    state = torch.tensor([[0.0, 0.5, 0.02, 0.01, 0.3, 0.005]], dtype=torch.float64)
    inputs = torch.tensor([[10.0, 0.2, 1.0, 0.5]], dtype=torch.float64)
    with torch.no_grad():
        mean = (members[0](state, inputs).total + members[1](state, inputs).total) / 2
        assert torch.allclose(ensemble(state, inputs).total, mean, rtol=1e-12)

    write_manifest(out, "reproduction")  # the CLI seals it; the library call leaves that to it
    paths = build_report(out, tmp_path / "report")
    html = paths.html.read_text()
    assert "Spread over 2 seeds" in html and "±" in html
