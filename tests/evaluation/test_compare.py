"""Acceptance: ``sysid compare`` of a hybrid, an NN-only model and the ship file's MMG on two
held-back real logs, the user's own (columns in knots, deg, deg/s, rpm under new names),
writes its tables and verdicts. The numbers are checked against independent computations:
the protocol's metrics of each model (`evaluate_model` on the logs read in SI), window counts
from the logs' lengths, and each verdict's overall change from the table's own RMSE."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cli_harness import in_process
from own_logs import columns_table, write_own_log

LOGS = {  # the user's name -> the dataset file; role
    "harbour_1.csv": ("berthing/berthing_12-Nov-2020_13_37_05.csv", "train"),
    "zigzag_a.csv": ("zigzag/zigzag_31-Jul-2020_13_57_45.csv", "train"),
    "harbour_2.csv": ("berthing/berthing_12-Nov-2020_13_21_03.csv", "validation"),
    "zigzag_b.csv": ("zigzag/zigzag_31-Jul-2020_13_29_19.csv", "held back"),
    "harbour_3.csv": ("berthing/berthing_12-Nov-2020_11_21_46.csv", "held back"),
}


def _config(model: str, logs: dict[str, list[str]]) -> str:
    return (f'[experiment]\nname = "{model}"\nmodel = "{model}"\nship = "esso_osaka"\nseed = 0\n'
            f"[data]\ntrain = {json.dumps(logs['train'])}\nvalidation = {json.dumps(logs['validation'])}\n"
            f"test = {json.dumps(logs['held back'])}\n"
            "[network]\nhidden = [8]\n[training]\nepochs = 2\nwarm_start_epochs = 5\nbatch_size = 64\n"
            "[gate]\nk = 3\nspace = \"inputs\"\n[evaluation]\nhorizons = [30.0, 100.0]\n" + columns_table())


@pytest.fixture(scope="module")
def project(dataset_dir, tmp_path_factory):
    """The user's logs, and a hybrid and an NN-only model trained on two of them (seconds)."""
    from sysid.cli import run

    root = tmp_path_factory.mktemp("compare")
    roles: dict[str, list[str]] = {"train": [], "validation": [], "held back": []}
    (root / "logs").mkdir()
    for name, (source, role) in LOGS.items():
        write_own_log(dataset_dir / source, root / "logs" / name)
        roles[role].append(f"logs/{name}")
    for model in ("hybrid", "nn"):
        (root / f"{model}.toml").write_text(_config(model, roles))
        run(["train", str(root / f"{model}.toml"), "-o", str(root / "runs" / model), "--threads", "1"])
    return root


@pytest.mark.slow
def test_compare_hybrid_nn_and_ship_mmg_on_two_held_back_logs(project, dataset_dir, capsys, monkeypatch):
    from sysid.config.experiment import load_experiment
    from sysid.data.recordings import read_run
    from sysid.evaluation.evaluate import evaluate_model
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship
    from sysid.runs.layout import load_model

    monkeypatch.chdir(project)
    done = in_process(capsys, "compare", "runs/hybrid", "runs/nn", "--ship", "esso_osaka",
                      "--config", "hybrid.toml", "-o", "cmp")
    assert done.code == 0, done.err
    out = project / "cmp"
    table = pd.read_csv(out / "comparison.csv")
    verdicts = pd.read_csv(out / "verdicts.csv")
    mmg = "MMG (ship file esso_osaka)"
    assert list(dict.fromkeys(table.model)) == ["hybrid", "nn", mmg]
    # one table per log, horizon and channel: 2 logs x 2 horizons x 3 channels, each with every model
    assert len(table.groupby(["log", "horizon_s", "channel"])) == 12 and len(table) == 36
    assert set(table.log) == {"zigzag_b", "harbour_3"}

    # independent truth: each model's protocol metrics on the same logs, read in SI from the dataset
    si = [read_run(dataset_dir / LOGS[f"{name}.csv"][0]) for name in ("zigzag_b", "harbour_3")]
    for r, name in zip(si, ("zigzag_b", "harbour_3")):
        r.name = name
    models = {"hybrid": load_model(project / "runs" / "hybrid")[1], "nn": load_model(project / "runs" / "nn")[1],
              mmg: MMG(load_ship("esso_osaka"))}
    for label, model in models.items():
        metrics = evaluate_model(model, si, (30.0, 100.0), traces=False).metrics
        for row in metrics.itertuples(index=False):
            assert row.n_windows == len(si[[r.name for r in si].index(row.file)]) // int(row.horizon_s)
            for channel, column in (("u", "rmse_u"), ("v_m", "rmse_v"), ("r", "rmse_r")):
                cell = table[(table.model == label) & (table.log == row.file) & (table.horizon_s == row.horizon_s)
                             & (table.channel == channel)].iloc[0]
                assert cell.n_windows == row.n_windows
                assert cell.rmse == pytest.approx(getattr(row, column), rel=1e-5)

    # every model but the first judged against the first, with the change the table's RMSE give
    assert list(verdicts.model) == ["nn", mmg] and set(verdicts.reference) == {"hybrid"}
    for v in verdicts.itertuples(index=False):
        mine = table[table.model == v.model].set_index(["log", "horizon_s", "channel"]).rmse
        first = table[table.model == "hybrid"].set_index(["log", "horizon_s", "channel"]).rmse
        geometric = math.exp(float(np.mean(np.log(mine / first)))) - 1
        assert v.change == pytest.approx(geometric, rel=1e-4)
        assert v.change_low <= v.change <= v.change_high
        assert v.outcome in ("beats", "worse", "not_distinguishable") and v.n_logs == 2
        assert v.model in v.sentence and "hybrid" in v.sentence
    summary = json.loads((out / "comparison.json").read_text())
    assert summary["against"] == "first" and summary["horizons_s"] == [30.0, 100.0]
    assert (out / "report.html").read_text().count("<table class=\"plain\">") == 13   # verdicts + 12 cells
    assert (out / "report.pdf").stat().st_size > 0 and (out / "manifest.json").is_file()
    assert "verdict: nn " in done.out
    # each log's table names its scenario, the maneuver recognised from its rudder and heading
    from sysid.data.scenario import scenario_of
    for run in _si_runs(dataset_dir):
        assert set(table[table.log == run.name].scenario) == {scenario_of(run)}
        assert f"{run.name} ({scenario_of(run)}) at 30 s" in done.out

    # against the physics baseline: the learned models judged against the ship file's MMG
    again = in_process(capsys, "compare", "runs/hybrid", "runs/nn", "--data", "logs/zigzag_b.csv",
                       "--horizon", "30", "--against", "baseline", "-o", "cmp_baseline")
    assert again.code == 0, again.err
    verdicts = pd.read_csv(project / "cmp_baseline" / "verdicts.csv")
    assert list(verdicts.model) == ["hybrid", "nn"] and set(verdicts.reference) == {"MMG (ship file)"}
    base = pd.read_csv(project / "cmp_baseline" / "comparison.csv")
    assert set(base.horizon_s) == {30.0} and set(base.log) == {"zigzag_b"}
    assert base[base.model == "MMG (ship file)"].decision.eq("reference").all()

    # an existing output is refused; a bad --against is one line
    assert in_process(capsys, "compare", "runs/hybrid", "runs/nn", "--config", "hybrid.toml", "-o", "cmp").code == 2
    bad = in_process(capsys, "compare", "runs/hybrid", "runs/nn", "--config", "hybrid.toml", "--against", "x",
                     "-o", "cmp_x")
    assert bad.code == 2 and len(bad.error_lines) == 1 and "--against" in bad.error_lines[0]
    assert not (project / "cmp_x").exists()
    # a run directory that is not there is named as such, not taken for a ship
    typo = in_process(capsys, "compare", "runs/hybrid", "runs/second", "--config", "hybrid.toml", "-o", "cmp_y")
    assert typo.code == 2 and len(typo.error_lines) == 1 and "runs/second: no such run directory" in typo.error_lines[0]
    assert not (project / "cmp_y").exists()
    shutil.rmtree(out)


def _si_runs(dataset_dir):
    """The held-back logs read in SI from the dataset, under the user's names."""
    from sysid.data.recordings import read_run

    runs = []
    for name, (source, role) in LOGS.items():
        if role == "held back":
            run = read_run(dataset_dir / source)
            run.name = Path(name).stem
            runs.append(run)
    return runs


@pytest.mark.slow
def test_evaluate_scores_remapped_logs_with_a_config_and_a_run_beside_its_baseline(project, dataset_dir, capsys,
                                                                                      monkeypatch):
    from sysid.evaluation.evaluate import evaluate_model
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship

    monkeypatch.chdir(project)
    truth = evaluate_model(MMG(load_ship("esso_osaka")), _si_runs(dataset_dir), (30.0, 100.0), traces=False).metrics
    # the baseline MMG on the user's logs (knots, deg, deg/s, rpm): the config's columns, test logs and horizons
    done = in_process(capsys, "evaluate", "--model", "mmg", "--config", "hybrid.toml", "-o", "mmg.csv")
    assert done.code == 0, done.err
    scored = pd.read_csv(project / "mmg.csv")
    assert list(scored.file) == list(truth.file) and list(scored.horizon_s) == [30.0, 30.0, 100.0, 100.0]
    for column in ("rmse_u", "rmse_v", "rmse_r"):
        np.testing.assert_allclose(scored[column], truth[column], rtol=1e-5)
    assert list(scored.n_windows) == list(truth.n_windows)
    # without the config the same logs are refused in one line naming the columns to map
    refused = in_process(capsys, "evaluate", "--model", "mmg", "--data", "logs/zigzag_b.csv", "-o", "x.csv")
    assert refused.code == 2 and len(refused.error_lines) == 1 and "[data.columns]" in refused.error_lines[0]

    # a run on its own [data] test logs: the model, its baseline on the same windows, the verdict
    run = in_process(capsys, "evaluate", "runs/hybrid", "-o", "hybrid.csv")
    assert run.code == 0, run.err
    lines = run.out.splitlines()
    assert "RMSE of u, v_m [m/s] and r [rad/s]:" in lines   # SI, said: the logs are in knots and deg/s
    at = lines.index("beside its physics baseline(s), on the same windows (RMSE of u, v_m [m/s] and r [rad/s]):")
    baseline_rows = [line.split() for line in lines[at + 2:] if "MMG (ship file)" in line]
    assert len(baseline_rows) == 4
    for row, expected in zip(baseline_rows, truth.itertuples(index=False)):
        assert row[0] == expected.file and float(row[1]) == expected.horizon_s
        assert [float(v) for v in row[-3:]] == pytest.approx([expected.rmse_u, expected.rmse_v, expected.rmse_r],
                                                              abs=6e-6)
    verdict = (run.out + run.err).splitlines()
    assert any(line.startswith(("verdict: The hybrid", "WARNING: The hybrid")) and "MMG (ship file)" in line
               and "2 logs" in line for line in verdict)


@pytest.mark.slow
def test_maneuver_puts_the_users_recorded_zigzag_beside_the_model(project, dataset_dir, capsys, monkeypatch):
    """``sysid maneuver SHIP --recorded LOG --config EXP``: the user's zig-zag (knots, deg) read
    through the config's [data.columns]; its indices in recorded.csv are those of the same
    record read in SI from the dataset; logs holding no turning circle or zig-zag are one line."""
    from sysid.data.recordings import read_run
    from sysid.maneuvers.recorded import record_comparison
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship

    monkeypatch.chdir(project)
    done = in_process(capsys, "maneuver", "esso_osaka", "-o", "man", "--zigzag", "10/10", "--side", "starboard",
                      "--dt", "0.5", "--duration", "60", "--eager", "--no-report",
                      "--recorded", "logs/zigzag_b.csv", "--config", "hybrid.toml")
    assert done.code == 0, done.err
    ours = pd.read_csv(project / "man" / "recorded_indices.csv")
    si = read_run(dataset_dir / LOGS["zigzag_b.csv"][0])
    truth = record_comparison({"esso_osaka": [MMG(load_ship("esso_osaka"))]}, {ours.scenario.iloc[0]: si})
    assert list(ours.model) == list(truth.model) == ["recorded", "esso_osaka"]
    for column in ("first_overshoot_deg", "second_overshoot_deg"):
        np.testing.assert_allclose(ours[column], truth[column], rtol=1e-5)   # the CSV keeps 6 digits
    assert ours.maneuver.iloc[0] == truth.maneuver.iloc[0] and ours.maneuver.iloc[0].startswith("zigzag_")
    refused = in_process(capsys, "maneuver", "esso_osaka", "-o", "man2", "--recorded", "logs/harbour_3.csv",
                         "--config", "hybrid.toml", "--no-report")
    assert refused.code == 2 and len(refused.error_lines) == 1 and "--recorded" in refused.error_lines[0]
    assert not (project / "man2").exists()


@pytest.mark.slow
def test_maneuver_of_a_run_reads_the_recorded_logs_in_the_runs_units(project, dataset_dir, capsys, monkeypatch):
    """``sysid maneuver RUN --recorded LOG`` without --config: the user's zig-zag (knots, deg)
    is read through the run's own [data.columns], as ``sysid evaluate RUN --data LOG`` reads
    it; the record's overshoots equal those of the same record read in SI from the dataset."""
    from sysid.data.recordings import read_run
    from sysid.maneuvers.recorded import record_comparison
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship

    monkeypatch.chdir(project)
    done = in_process(capsys, "maneuver", "runs/hybrid", "-o", "man_run", "--zigzag", "10/10", "--side",
                      "starboard", "--dt", "0.5", "--duration", "60", "--eager", "--no-report",
                      "--recorded", "logs/zigzag_b.csv")
    assert done.code == 0, done.err
    ours = pd.read_csv(project / "man_run" / "recorded_indices.csv")
    si = read_run(dataset_dir / LOGS["zigzag_b.csv"][0])
    truth = record_comparison({"esso_osaka": [MMG(load_ship("esso_osaka"))]}, {ours.scenario.iloc[0]: si})
    assert list(ours.model) == ["recorded", "hybrid"]
    for column in ("first_overshoot_deg", "second_overshoot_deg"):
        np.testing.assert_allclose(ours[column].iloc[0], truth[column].iloc[0], rtol=1e-5)


@pytest.mark.slow
def test_an_identified_mmg_run_with_validation_logs_evaluates_again(project, dataset_dir, capsys, monkeypatch):
    """An MMG with N_r identified, validated on its own log, evaluated again later on its test
    logs: only the test logs must still be there (its validation log has moved away)."""
    from sysid.evaluation.evaluate import evaluate_model
    from sysid.mmg import MMG
    from sysid.mmg.ship import load_ship

    monkeypatch.chdir(project)
    text = _config("mmg", {"train": ["logs/harbour_1.csv", "logs/zigzag_a.csv"], "validation": ["logs/harbour_2.csv"],
                           "held back": ["logs/zigzag_b.csv"]})
    (project / "mmg_id.toml").write_text(text + '[identify]\nparameters = ["N_r"]\nepochs = 2\n')
    trained = in_process(capsys, "train", "mmg_id.toml", "-o", "runs/mmg_id", "--threads", "1")
    assert trained.code == 0, trained.err
    moved = project / "harbour_2.moved"
    (project / "logs" / "harbour_2.csv").rename(moved)
    try:
        again = in_process(capsys, "evaluate", "runs/mmg_id", "-o", "mmg_id.csv")
    finally:
        moved.rename(project / "logs" / "harbour_2.csv")
    assert again.code == 0, again.err
    scored = pd.read_csv(project / "mmg_id.csv")
    written = pd.read_csv(project / "runs" / "mmg_id" / "metrics.csv")   # what training scored
    np.testing.assert_allclose(scored[["rmse_u", "rmse_v", "rmse_r"]], written[["rmse_u", "rmse_v", "rmse_r"]],
                               rtol=1e-5)
    truth = evaluate_model(MMG(load_ship("esso_osaka")), _si_runs(dataset_dir)[:1], (30.0, 100.0),
                           traces=False).metrics
    rows = [line.split() for line in again.out.splitlines() if "MMG (ship file)" in line and "zigzag_b" in line]
    assert [float(r[-3]) for r in rows] == pytest.approx(list(truth.rmse_u), abs=6e-6)
    assert any("The identified MMG" in line and "MMG (ship file)" in line
               for line in (again.out + again.err).splitlines() if line.startswith(("verdict:", "WARNING:")))


def test_runs_of_the_paper_data_sets_compare_on_its_six_test_files(dataset_dir, tmp_path, capsys):
    """Without --data or --config, runs trained on D1/D2 are compared on the paper's test files
    (as `sysid evaluate RUN` is); an own-logs run still needs them named."""
    from sysid.data.splits import PAPER_TEST_STEMS

    (tmp_path / "d1.toml").write_text('[experiment]\nname = "m"\nmodel = "mmg"\ndataset = "D1"\n')
    assert in_process(capsys, "train", tmp_path / "d1.toml", "-o", tmp_path / "run").code == 0
    done = in_process(capsys, "compare", tmp_path / "run", "esso_osaka", "-o", tmp_path / "cmp", "--no-report")
    assert done.code == 0, done.err
    logs = set(pd.read_csv(tmp_path / "cmp" / "comparison.csv")["log"])
    assert logs == set(PAPER_TEST_STEMS) and len(logs) == 6
    own = tmp_path / "own.toml"
    own.write_text(f'[experiment]\nname = "o"\nmodel = "mmg"\n[data]\nfiles = ["{tiny_file(dataset_dir)}"]\n')
    assert in_process(capsys, "train", own, "-o", tmp_path / "own").code == 0
    refused = in_process(capsys, "compare", tmp_path / "own", "esso_osaka", "-o", tmp_path / "cmp2")
    assert refused.code == 2 and "no logs to compare on" in refused.err


def tiny_file(dataset_dir):
    return dataset_dir / "berthing" / "berthing_12-Nov-2020_11_07_23.csv"
