"""Seeds of one configuration side by side in one trial (`sysid.sweep.trial.run_group`, the
path of ``sysid reproduce --seeds N`` and of sweeps without a scheduler): each seed's run
directory holds what the seed trained alone gives (weights and val_loss_multistep to
round-off), reads as any run, resumes after an interrupted group, and is the same on every
run of the same config, data and seed."""
from __future__ import annotations

import math
import shutil
import tomllib

import pytest
import torch

from sysid.config.experiment import parse_experiment
from sysid.data.recordings import read_runs
from sysid.runs.rundir import RunDir
from sysid.sweep.inbox import RunInbox, read_journal
from sysid.sweep.trial import TrialData, TrialSpec, read_trial_data, run_group, run_trial, side_by_side_refusal
from tiny_experiment import TEST_FILE, TRAIN_FILES

VALIDATION_FILE = "berthing_12-Nov-2020_11_21_46.csv"
SEEDS = (3, 4)


def _config(dataset_dir, seed: int, **training) -> str:
    berthing = dataset_dir / "berthing"
    doc = {"experiment": {"name": f"group-seed{seed}", "model": "hybrid", "seed": seed},
           "data": {"train": [str(berthing / f) for f in TRAIN_FILES], "validation": [str(berthing / VALIDATION_FILE)],
                    "test": [str(berthing / TEST_FILE)]},
           "network": {"hidden": [16, 16]},
           "training": {"epochs": 8, "patience": 3, "warm_start_epochs": 3, "batch_size": 64, "steps": 5,
                        "learning_rate": 1e-2, "threads": 1, **training},
           "gate": {"k": 5, "space": "inputs"}, "evaluation": {"horizons": [30.0]}}
    return parse_experiment(doc).to_toml()


@pytest.fixture(scope="module")
def trials(dataset_dir) -> list[TrialSpec]:
    return [TrialSpec(f"runs/group/seed{s}", "group", s, _config(dataset_dir, s), label="group") for s in SEEDS]


@pytest.fixture(scope="module")
def data(dataset_dir, trials) -> TrialData:
    exps = [parse_experiment(tomllib.loads(t.config)) for t in trials]
    shipped = read_trial_data(exps, None)
    return TrialData(tuple(read_runs([dataset_dir / "berthing" / TEST_FILE])), shipped.training, None,
                     shipped.validation)


@pytest.fixture(scope="module")
def alone(tmp_path_factory, trials, data):
    """Each seed trained alone (`run_trial`, the path before seeds side by side)."""
    out = tmp_path_factory.mktemp("alone")
    inbox = RunInbox(str(out))
    rows = [run_trial(t, inbox, data) for t in trials]
    return out, rows


def _weights(run) -> dict[str, torch.Tensor]:
    return torch.load(run / "model.pt", map_location="cpu", weights_only=True)


def _assert_same_runs(a, b, rtol=1e-5) -> None:
    wa, wb = _weights(a), _weights(b)
    assert wa.keys() == wb.keys()
    for name in wa:
        assert torch.allclose(wa[name].double(), wb[name].double(), rtol=rtol, atol=1e-7), name
    sa, sb = RunDir(a).read_summary(), RunDir(b).read_summary()
    assert sa.val_loss_multistep == pytest.approx(sb.val_loss_multistep, rel=rtol)
    assert sa.epochs == sb.epochs and sa.best_epoch == sb.best_epoch


def test_a_group_of_seeds_equals_each_seed_alone(tmp_path, trials, data, alone):
    out_alone, rows_alone = alone
    out = tmp_path / "group"
    said: list[str] = []
    rows = run_group(trials, RunInbox(str(out)), data, log=said.append)
    for trial, row, row_alone in zip(trials, rows, rows_alone):
        assert row["status"] == "complete" and math.isfinite(row["val_loss_multistep"])
        assert row["val_loss_multistep"] == pytest.approx(row_alone["val_loss_multistep"], rel=1e-5)
        _assert_same_runs(out / trial.path, out_alone / trial.path)
        # the same files as a seed trained alone, readable as any run
        assert sorted(p.name for p in (out / trial.path).iterdir()) == sorted(
            p.name for p in (out_alone / trial.path).iterdir())
        run = RunDir(out / trial.path)
        assert run.read_summary().status == "complete" and len(run.read_metrics()) == 1
    # sysid evaluate reads a seed's run directory and scores it as the run itself did
    from sysid.cli import run as sysid
    evaluated = tmp_path / "evaluated.csv"
    sysid(["evaluate", str(out / trials[0].path), "-o", str(evaluated)])
    import pandas as pd
    mine, kept = pd.read_csv(evaluated), RunDir(out / trials[0].path).read_metrics()
    assert mine.rmse_u.to_numpy() == pytest.approx(kept.rmse_u.to_numpy(), rel=1e-6)
    first, second = (_weights(out / t.path) for t in trials)
    nets = [k for k in first if "correction" in k and "weight" in k]
    assert nets and not torch.equal(first[nets[0]], second[nets[0]])  # two seeds, two networks
    # one progress line for the group, seeds named; one journal "started" per seed, side by side
    lines = [m for m in said if m.startswith("train: ") and "seeds training" in m]
    assert lines and all(f"seed {s}" in lines[-1] for s in SEEDS)
    started = [e for e in read_journal(out) if e["event"] == "started"]
    assert sorted(e["trial"] for e in started) == [t.path for t in trials]
    assert all(e["side_by_side"] == 2 for e in started)


def test_an_interrupted_group_resumes_its_seeds_side_by_side(tmp_path, trials, data, alone, monkeypatch):
    """The inbox keeps each seed's checkpoint; a rerun of the group continues the seeds from
    them side by side to the models of an uninterrupted training."""
    out_alone, _ = alone
    out = tmp_path / "group"
    inbox = RunInbox(str(out))
    original = RunInbox.save_checkpoint
    saved = {"n": 0}

    def save_then_interrupt(self, path, holder, blob):
        kept = original(self, path, holder, blob)
        saved["n"] += 1
        if saved["n"] == 4:   # both seeds after their second epoch
            raise KeyboardInterrupt
        return kept

    monkeypatch.setattr(RunInbox, "save_checkpoint", save_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_group(trials, inbox, data)
    monkeypatch.setattr(RunInbox, "save_checkpoint", original)
    assert all(inbox.checkpoint(t.path) is not None for t in trials)
    said: list[str] = []
    rows = run_group(trials, inbox, data, log=said.append)
    assert all(r["status"] == "complete" for r in rows)
    assert sum("train: resumed after epoch 2" in m for m in said) == 2
    resumed = [e for e in read_journal(out) if e["event"] == "resumed"]
    assert [e["after_epochs"] for e in resumed] == [2, 2]
    for trial in trials:
        _assert_same_runs(out / trial.path, out_alone / trial.path)
        assert inbox.checkpoint(trial.path) is None


def test_a_group_is_deterministic_and_reuses_complete_seeds(tmp_path, trials, data):
    """The same group trained twice gives the same runs bit for bit (config, data and
    seeds decide them); a seed whose run is complete is reused, the other trains (alone
    here) to its run again, to round-off."""
    runs = []
    for name in ("first", "second"):
        out = tmp_path / name
        rows = run_group(trials, RunInbox(str(out)), data)
        runs.append((out, rows))
    (first, rows1), (second, rows2) = runs
    assert [r["val_loss_multistep"] for r in rows1] == [r["val_loss_multistep"] for r in rows2]
    for trial in trials:
        a, b = _weights(first / trial.path), _weights(second / trial.path)
        assert all(torch.equal(a[k], b[k]) for k in a), trial.path
    shutil.rmtree(second / trials[1].path)
    again = run_group(trials, RunInbox(str(second)), data)
    assert [e["event"] for e in read_journal(second)][-3:] == ["reused", "started", "trained"]
    assert again[0] == rows2[0]   # read back from the kept run
    _assert_same_runs(second / trials[1].path, first / trials[1].path)


def test_which_seeds_can_share_a_trial(trials, data):
    assert side_by_side_refusal(trials, data) is None
    assert side_by_side_refusal(trials[:1], data) == "a single seed"

    def varied(trial: TrialSpec, **sections) -> TrialSpec:
        exp = parse_experiment(tomllib.loads(trial.config)).replace(**sections)
        return TrialSpec(trial.path, trial.point, trial.seed, exp.to_toml(), label=trial.label)

    identified = [varied(t, identify={"parameters": ("Y_v",)}) for t in trials]
    assert "one set per seed" in side_by_side_refusal(identified, data)
    mmg = [varied(t, experiment={"model": "mmg"}) for t in trials]
    assert "no network" in side_by_side_refusal(mmg, data)


def test_a_sweep_trains_each_configurations_seeds_side_by_side(tmp_path, dataset_dir, trials):
    """`sysid sweep` (grid, no scheduler): one Tune trial per configuration, its two seeds
    side by side, each delivered as its own run directory with the rows of results.csv."""
    pytest.importorskip("ray.tune")
    import pandas as pd
    from sysid.cli import run

    base = tmp_path / "base.toml"
    base.write_text(parse_experiment(tomllib.loads(trials[0].config)).replace(data={"test": ()}).to_toml())
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(f"[sweep]\nbase = '{base.name}'\nseeds = [3, 4]\n[vary]\n'training.learning_rate' = [1e-2]\n")
    out = tmp_path / "sweep"
    run(["sweep", str(sweep), "-o", str(out), "--workers", "1"])
    table = pd.read_csv(out / "results.csv")
    assert sorted(table.seed) == [3, 4] and set(table.status) == {"complete"}
    started = [e for e in read_journal(out) if e["event"] == "started"]
    assert len(started) == 2 and all(e["side_by_side"] == 2 for e in started)
    for row in table.itertuples():
        assert RunDir(out / row.run).read_summary().val_loss_multistep == pytest.approx(row.val_loss_multistep, rel=1e-4)
