"""``sysid train`` with ``[identify] solver = "levenberg_marquardt"`` (the own-ship example
config) against a known truth:
KVLCC2 maneuvers simulated by Euler at 1 Hz (the identification model is then exactly
right), white noise on the recorded u, v_m, r, hull derivatives identified from a start
perturbed by 20-30 % ([mmg] overrides), sigma from the estimator that identified them."""
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from benchmark_scripts import load_benchmark
from sysid import load_ship
from sysid.cli import run as sysid
from sysid.errors import ConfigError
from sysid.config.experiment import load_experiment, parse_experiment
from sysid.report.methods import estimator_text
from sysid.runs.rundir import RunDir
from sysid.runs.layout import load_model

from processed_runs import write_processed_csv

NAMES = ["Y_v", "Y_r", "N_v", "N_r"]
ESSO_PARAMETERS = ["X_vr", "Y_v", "Y_r", "N_v", "N_r"]
EXAMPLE = Path(__file__).resolve().parents[2] / "configs" / "experiments" / "own_ship_identified.toml"
ESSO_LM = EXAMPLE.with_name("mmg_identified_lm_D2.toml")


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("identification_kvlcc2")


@pytest.fixture(scope="module")
def runs(bench, tmp_path_factory):
    return _write_runs(bench, tmp_path_factory.mktemp("kvlcc2_runs"))


def _write_runs(bench, out_dir, seed=0):
    """Training files (noisy u, v_m, r) and one clean test file; returns (train, test) paths."""
    ship = load_ship(bench.SHIP)
    records = bench.maneuvers(ship, {"turning35_stbd": 120, "zigzag10": 160, "zigzag20": 160, "random": 300},
                              "euler")
    g = torch.Generator().manual_seed(seed)
    paths = []
    for name, (states, inputs) in records.items():
        noisy = states.clone()
        if name != "zigzag20":
            noisy[:, [1, 3, 5]] += torch.tensor(bench.NOISE) * torch.randn(len(states), 3, generator=g,
                                                                             dtype=torch.float64)
        t = np.arange(len(states), dtype=float)
        paths.append(write_processed_csv(out_dir / f"{name}.csv", t, noisy.numpy(), inputs.numpy()))
    return [p for p in paths if p.stem != "zigzag20"], next(p for p in paths if p.stem == "zigzag20")


def _config(path, files, start, **sections):
    """The own-ship example config (configs/experiments/own_ship_identified.toml) on these
    files, starting from `start` ([mmg] overrides), one 30-s horizon, `sections` changed."""
    exp = load_experiment(EXAMPLE).replace(data={"train": tuple(str(f) for f in files)},
                                           mmg={"overrides": {k: float(v) for k, v in start.items()}},
                                           evaluation={"horizons": (30.0,)}, **sections)
    path.write_text(exp.to_toml())
    return path


@pytest.mark.slow
def test_levenberg_marquardt_run_covers_the_truth_within_two_sigma(bench, runs, tmp_path):
    ship = load_ship(bench.SHIP)
    truth = np.array([ship[n] for n in NAMES])
    start = bench.perturbed_start(ship, NAMES, 0)
    assert np.all(np.abs(np.array([start[n] for n in NAMES]) - truth) >= 0.2 * np.abs(truth) - 1e-12)
    train, test = runs
    run_dir = tmp_path / "run"
    config = _config(tmp_path / "lm.toml", train, start)
    assert load_experiment(config).identify.parameters == tuple(NAMES)  # the example's
    sysid(["train", str(config), "-o", str(run_dir), "--test", str(test)])
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["identification"]["solver"] == "levenberg_marquardt"
    assert summary["identification"]["start_states"] == "estimated"
    assert summary["identification"]["iterations"] >= 2
    assert summary["stopped"]["identify"] == "converged"
    u = summary["identified_uncertainty"]
    assert u["names"] == NAMES
    estimate, sigma = np.array(u["estimate"]), np.array(u["std_error"], dtype=float)
    # measured: |estimate - truth| / sigma = 0.70, 0.73, 0.08, 0.17 (noise seed 0)
    assert np.all(np.abs(estimate - truth) <= 2 * sigma), (estimate, truth, sigma)
    assert np.all(sigma < 0.05 * np.abs(truth)), sigma  # and well determined: the 2 sigma test has teeth
    assert not any(u["undetermined"])
    for name, value in zip(NAMES, estimate):  # the model the run saved carries the estimate (float32)
        assert summary["identified"][name] == pytest.approx(value, rel=1e-6)
    assert summary["val_loss_multistep"] is not None and summary["val_loss_multistep"] < 1.0
    said = estimator_text(RunDir(run_dir).read_summary())  # what the report's methods text and figure caption state
    assert "Levenberg-Marquardt" in said and "start state estimated" in said and "converged" in said
    # the model is exact here: the recorded-start fit lands within 2 sigma (measured 1.7, Y_r)
    check = summary["identification"]["start_state_check"]
    assert check["start_states"] == "recorded" and check["agrees"], check
    assert "within the ± 2σ" in said


@pytest.mark.slow
def test_hybrid_identifies_its_mmg_by_levenberg_marquardt_before_the_network(bench, runs, tmp_path):
    ship = load_ship(bench.SHIP)
    train, test = runs
    config = _config(tmp_path / "hybrid.toml", train, bench.perturbed_start(ship, NAMES, 0),
                     experiment={"model": "hybrid"}, identify={"start_states": "recorded"},
                     training={"epochs": 2, "warm_start_epochs": 2}, network={"hidden": (8,)},
                     gate={"k": 5, "space": "inputs"})
    run_dir = tmp_path / "run"
    sysid(["train", str(config), "-o", str(run_dir), "--test", str(test)])
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["identification"]["solver"] == "levenberg_marquardt"
    assert summary["identification"]["start_states"] == "recorded"
    assert set(summary["stopped"]) == {"identify", "train"}
    truth = np.array([ship[n] for n in NAMES])
    u = summary["identified_uncertainty"]
    assert np.all(np.abs(np.array(u["estimate"]) - truth) <= 3 * np.array(u["std_error"]))
    _, model = load_model(run_dir)  # the network was trained on the identified MMG, left as identified
    for name, value in summary["identified"].items():
        assert float(getattr(model.mmg.coefficients, name).detach()) == pytest.approx(value, rel=1e-6)


@pytest.mark.parametrize("identify, message", [
    ({"parameters": ["Y_v"], "solver": "newton"}, "solver = 'newton': choose one of gradient, levenberg_marquardt"),
    ({"parameters": ["Y_v"], "solver": 3}, "[identify] solver: expected a string"),
    ({"parameters": ["Y_v"], "start_states": "estimated"}, 'start_states = \'estimated\' needs solver = "levenberg_marquardt"'),
    ({"parameters": ["Y_v"], "solver": "levenberg_marquardt", "start_states": "guessed"},
     "start_states = 'guessed': choose one of estimated, recorded"),
    ({"parameters": ["Y_v"], "solver": "levenberg_marquardt", "prior_weight": -1.0}, "prior_weight must be >= 0"),
    ({"parameters": ["Y_v"], "prior_weight": 1.0}, 'prior_weight needs solver = "levenberg_marquardt"'),
    ({"parameters": ["Y_v"], "solver": "levenberg_marquardt", "stage": "joint"}, 'stage "joint"'),
    ({"solver": "levenberg_marquardt"}, "needs parameters to identify"),
])
def test_bad_identify_options_name_the_file_and_key(identify, message):
    doc = {"experiment": {"model": "hybrid"}, "identify": identify}
    with pytest.raises(ConfigError) as err:
        parse_experiment(doc, "exp.toml")
    assert str(err.value).startswith("exp.toml: [identify] "), str(err.value)
    assert message in str(err.value)


def test_start_states_default_to_the_solver_and_are_written_resolved():
    lm = parse_experiment({"experiment": {"model": "mmg"},
                           "identify": {"parameters": ["Y_v"], "solver": "levenberg_marquardt"}})
    assert lm.identify.start_states == "estimated"
    assert parse_experiment({"experiment": {"model": "mmg"}}).identify.start_states == "recorded"
    assert 'start_states = "estimated"' in lm.to_toml()


@pytest.mark.slow
def test_start_state_check_flags_the_esso_osaka_model_error(dataset_dir, tmp_path):
    """Real data, where the Esso Osaka MMG does not fit exactly: free start states take up
    part of the model error, so the two start-state treatments disagree far beyond the
    sigma (measured: Y'v -0.236 estimated against -0.415 recorded, 6.6 sigma), and each run's
    check reproduces the other run's estimate."""
    summaries = {}
    for start in ("estimated", "recorded"):
        config = tmp_path / f"{start}.toml"
        config.write_text(load_experiment(ESSO_LM).replace(identify={"start_states": start},
                                                           evaluation={"horizons": (30.0,)}).to_toml())
        sysid(["train", str(config), "-o", str(tmp_path / start), "--threads", "1"])
        summaries[start] = json.loads((tmp_path / start / "summary.json").read_text())
    check = summaries["estimated"]["identification"]["start_state_check"]
    assert check["start_states"] == "recorded" and not check["agrees"]
    assert check["largest"] == "Y_v" and abs(check["largest_sigma"]) > 4, check
    assert "lower bound on the uncertainty" in estimator_text(RunDir(tmp_path / "estimated").read_summary())
    back = summaries["recorded"]["identification"]["start_state_check"]
    assert back["start_states"] == "estimated" and not back["agrees"]
    for name in ESSO_PARAMETERS:
        assert check["coefficients"][name] == pytest.approx(summaries["recorded"]["identified"][name], rel=1e-5)
        assert back["coefficients"][name] == pytest.approx(summaries["estimated"]["identified"][name], rel=1e-5)
    assert summaries["recorded"]["identified"]["Y_v"] < summaries["estimated"]["identified"]["Y_v"] - 0.1
