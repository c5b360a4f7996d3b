"""A reproduction states every learned model's verdict, in its report and in what `sysid
reproduce` prints, by the one rule: the seeds of ``--seeds N`` as members of one model, their
mean-of-seeds ensemble as one model of its own, a run without a verdict named as not judged.
The verdicts are judged on made-up windows whose truth is known: a model 1.3 x the MMG's RMSE
on every window is worse, 0.6 x, 0.7 x and 0.8 x beat it."""
from __future__ import annotations

import json
import shutil

import pytest

from sysid.store.manifest import write_manifest

from synthetic_rundir import write_reproduction
from verdict_cases import seed_verdict

def verdict(model: str, factor: float) -> dict:
    """summary.json's verdict of a model whose per-window RMSE is `factor` x the MMG's."""
    return seed_verdict(factor, model).to_dict()


def with_summary(run_dir, **fields) -> None:
    path = run_dir / "summary.json"
    summary = json.loads(path.read_text())
    summary.update(fields)
    path.write_text(json.dumps(summary))
    write_manifest(run_dir, "run")


@pytest.fixture(scope="module")
def reproduction(tmp_path_factory):
    out = write_reproduction(tmp_path_factory.mktemp("repro"), scale=0.5,
                             names=("mmg_paper", "mmg_lab", "nn_D1", "hybrid_D1", "hybrid_D2"))
    runs = out / "runs"
    with_summary(runs / "hybrid_D1", verdict=verdict("hybrid", 1.3), beats_baseline=False, val_loss_multistep=0.05)
    with_summary(runs / "nn_D1", val_loss_multistep=0.04)  # no verdict recorded
    group = runs / "hybrid_D2"
    shutil.move(str(group), str(runs / "seed0"))
    group.mkdir()
    shutil.move(str(runs / "seed0"), str(group / "seed0"))
    shutil.copytree(group / "seed0", group / "seed1")
    for k, factor in enumerate((0.6, 0.8)):
        with_summary(group / f"seed{k}", verdict=verdict("hybrid", factor), beats_baseline=True, seed=k)
    ensemble = runs / "hybrid_ensemble_D2"   # as `sysid.protocol.seed_runs.write_ensemble` records it
    shutil.copytree(group / "seed0", ensemble)
    with_summary(ensemble, verdict=verdict("hybrid", 0.7), beats_baseline=True)
    write_manifest(out, "reproduction")
    return out


def test_the_report_states_each_models_verdict(reproduction):
    from sysid.report.methods import verdict_items
    from sysid.report.source import read_source

    items = dict(verdict_items(read_source(reproduction)))
    assert set(items) == {"Verdict: NN D1", "Verdict: Hybrid D1", "Verdict: Hybrid D2", "Verdict: Hybrid (ensemble) D2"}
    assert items["Verdict: Hybrid D1"].startswith("WARNING: The hybrid is WORSE than its physics baseline")
    both = items["Verdict: Hybrid D2"]  # the seeds as members: RMSE 0.6 x and 0.8 x the MMG's
    assert both.startswith("The hybrid (mean over 2 seeds) beats its physics baseline MMG (ship file)")
    assert "2 seeds or members (each alone -40 % to -20 %)" in both
    ensemble = items["Verdict: Hybrid (ensemble) D2"]  # one model: RMSE 0.7 x the MMG's on every window
    assert ensemble.startswith("The hybrid beats its physics baseline MMG (ship file)") and "-30 %" in ensemble
    assert "no spread: one model" in ensemble and "not judged" not in ensemble
    assert items["Verdict: NN D1"] == ("not judged: the run records no verdict (sysid compare runs/nn_D1 --against "
                                       "baseline judges it)")


def test_reproduce_prints_one_verdict_per_model(reproduction, capsys):
    from sysid.cli.train_commands import _warn_below_baseline

    _warn_below_baseline(reproduction)
    out, err = capsys.readouterr()
    assert (f"not judged against a physics baseline (no verdict recorded): nn_D1; sysid compare "
            f"{reproduction / 'runs' / 'nn_D1'} --against baseline judges one\n") in out
    assert [line.split(":")[1] for line in out.splitlines() if line.startswith("verdict:")] == [
        " run hybrid_D2 (2 seeds)", " run hybrid_ensemble_D2"]
    assert "each alone -40 % to -20 %" in out
    assert [line.split(": The")[0] for line in err.splitlines()] == ["WARNING: run hybrid_D1"]


def test_methods_name_the_gate_and_training_only_where_there_are_some(reproduction):
    from sysid.report.methods import methods_paragraphs
    from sysid.report.source import read_source

    paragraphs = {p.split(":")[0]: p for p in methods_paragraphs(read_source(reproduction))}
    assert "val_loss_multistep 0.05000: the validation loss, L_v of the final model (kNN gate included)" in \
        paragraphs["Hybrid D1"]
    assert "val_loss_multistep 0.04000: the validation loss, L_v of the final model on" in paragraphs["NN D1"]
    assert paragraphs["MMG (lab X'vr)"].startswith("MMG (lab X'vr): MMG model (hull, propeller, rudder and wind "
                                                   "forces of the ship definition); not trained.")


def test_eleven_seeds_print_the_verdict_the_report_states(tmp_path, capsys):
    """Seeds are the model's members in the order seed0, seed1, ..., seed10 in the report; the
    printed verdict draws them in that order too (not seed10 before seed2), so the bootstrap's
    intervals, and the sentence, are the report's to the letter."""
    from sysid.cli.train_commands import _warn_below_baseline
    from sysid.report.methods import verdict_items
    from sysid.report.source import read_source

    out = write_reproduction(tmp_path, scale=0.5, names=("mmg_paper", "hybrid_D2"))
    runs = out / "runs"
    group = runs / "hybrid_D2"
    shutil.move(str(group), str(runs / "seed0"))
    group.mkdir()
    shutil.move(str(runs / "seed0"), str(group / "seed0"))
    factors = (0.5, 1.4, 0.6, 1.3, 0.7, 1.2, 0.8, 1.1, 0.55, 1.35, 0.9)   # seed k: factors[k] x the MMG's RMSE
    for k, factor in enumerate(factors):
        if k:
            shutil.copytree(group / "seed0", group / f"seed{k}")
        with_summary(group / f"seed{k}", verdict=verdict("hybrid", factor), beats_baseline=factor < 1, seed=k)
    write_manifest(out, "reproduction")
    stated = dict(verdict_items(read_source(out)))["Verdict: Hybrid D2"].removeprefix("WARNING: ")
    _warn_below_baseline(out)
    printed = capsys.readouterr()
    lines = [line for line in (printed.out + printed.err).splitlines() if "run hybrid_D2 (11 seeds): " in line]
    assert len(lines) == 1 and lines[0].split("run hybrid_D2 (11 seeds): ", 1)[1] == stated
