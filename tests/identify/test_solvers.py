"""The identification strategies (`sysid.identify.solvers`) behind one interface, against a
known truth: KVLCC2 maneuvers simulated by Euler at 1 Hz (the identification model is then
exactly right), noise-free, hull derivatives from starts perturbed by 20-30 %.
Levenberg-Marquardt lands on the truth; gradient (Adam on the multi-step loss, run by the
training loop) moves towards it; each `fit` returns the strategy with what it learned, and
the checkpoint and log lines come from the loop's parts."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from benchmark_scripts import load_benchmark
from sysid import load_ship
from sysid.config.choices import Solver
from sysid.config.experiment import parse_experiment
from sysid.device import compute_threads
from sysid.errors import ConfigError
from sysid.dynamics.rollouts import WindowSet
from sysid.hybrid.force_models import build_mmg
from sysid.identify.checkpoint import Checkpointing
from sysid.identify.journal import TrainingJournal
from sysid.identify.loop import RunProgress, TrainingLoop
from sysid.identify.losses import multistep_loss
from sysid.identify.solvers.base import Identification, IdentificationData, coefficients
from sysid.identify.solvers.gradient import GradientIdentification
from sysid.identify.solvers.least_squares import LevenbergMarquardtIdentification
from sysid.identify.trainer import TrainingSummary
from sysid.identify.windowing import SplitReport

NAMES = ["Y_v", "Y_r", "N_v", "N_r"]
W_V = torch.tensor([0.004, 0.003, 0.0008], dtype=torch.float64) ** -2  # 1 / noise variance of u, v_m, r


@pytest.fixture(autouse=True)
def one_thread():
    with compute_threads(1):
        yield


@pytest.fixture(scope="module")
def problem():
    bench = load_benchmark("identification_kvlcc2")
    ship = load_ship(bench.SHIP)
    records = bench.maneuvers(ship, {"turning35_stbd": 60, "zigzag10": 100}, "euler")
    raw = bench.windows_from(records, 10, (0.0, 0.0, 0.0), 0)
    windows = WindowSet(raw.states, raw.inputs, raw.dt)
    return bench.SHIP, windows, bench.perturbed_start(ship, NAMES, 0), np.array([ship[n] for n in NAMES])


def _experiment(ship: str, start: dict, solver: str, epochs: int = 1, integrator: str = "euler"):
    return parse_experiment({"experiment": {"name": "solvers", "model": "mmg", "ship": ship},
                             "mmg": {"overrides": start},
                             "training": {"steps": 10, "batch_size": 8, "patience": 1000},
                             "identify": {"parameters": NAMES, "solver": solver, "start_states": "recorded",
                                          "epochs": epochs, "learning_rate": 0.01, "integrator": integrator}})


def _data(windows: WindowSet) -> IdentificationData:
    return IdentificationData(windows, windows, W_V, lambda dtype: windows)  # consecutive windows: disjoint


def test_levenberg_marquardt_strategy_lands_on_the_truth(problem):
    ship, windows, start, truth = problem
    exp = _experiment(ship, start, "levenberg_marquardt")
    mmg = build_mmg(exp, torch.float64)
    first = np.array(list(coefficients(mmg, NAMES).values()))
    assert np.all(np.abs(first - truth) >= 0.2 * np.abs(truth) - 1e-12)  # really perturbed
    solver = LevenbergMarquardtIdentification(exp)
    assert isinstance(solver, Identification) and solver.fit(mmg, _data(windows)) is solver
    np.testing.assert_allclose(list(coefficients(mmg, NAMES).values()), truth, rtol=1e-6)
    assert solver.stage_.history[0]["epoch"] == solver.fit_.iterations and solver.val_loss_ < 1e-10
    assert solver.estimator_.solver is Solver.LEVENBERG_MARQUARDT and list(solver.uncertainty_.names) == NAMES


def test_levenberg_marquardt_integrates_by_the_configured_rule():
    """Records of the true ship integrated by RK4 over 1 s steps (noise-free): with `[identify]
    integrator = "rk4"` LM lands on the truth; with the default Euler it does not (its
    coefficients absorb Euler's error over the 1 s step, 1 % or more in some derivative)."""
    bench = load_benchmark("identification_kvlcc2")
    ship = load_ship(bench.SHIP)
    raw = bench.windows_from(bench.maneuvers(ship, {"turning35_stbd": 60, "zigzag10": 100}, "rk4"), 10,
                             (0.0, 0.0, 0.0), 0)
    windows = WindowSet(raw.states, raw.inputs, raw.dt)
    truth = np.array([ship[n] for n in NAMES])
    found = {}
    for rule in ("rk4", "euler"):
        exp = _experiment(bench.SHIP, bench.perturbed_start(ship, NAMES, 0), "levenberg_marquardt",
                          integrator=rule)
        mmg = build_mmg(exp, torch.float64)
        solver = LevenbergMarquardtIdentification(exp).fit(mmg, _data(windows))
        found[rule] = np.array(list(coefficients(mmg, NAMES).values()))
        assert solver.estimator_.integrator == rule
        said: list[str] = []
        TrainingJournal(said.append).least_squares(solver)
        assert ("disjoint windows integrated by RK4," in said[0]) is (rule == "rk4")
    np.testing.assert_allclose(found["rk4"], truth, rtol=1e-6)
    assert np.max(np.abs(found["euler"] / truth - 1)) > 0.01


def test_an_integrator_other_than_euler_needs_levenberg_marquardt():
    with pytest.raises(ConfigError, match=r"\[identify\] integrator = 'rk4' needs solver = \"levenberg_marquardt\""):
        _experiment("kvlcc2_l7", {}, "gradient", integrator="rk4")


def test_gradient_strategy_moves_towards_the_truth_through_the_loop(problem, tmp_path):
    ship, windows, start, truth = problem
    exp = _experiment(ship, start, "gradient", epochs=15)
    mmg = build_mmg(exp, torch.float64)
    first = np.array(list(coefficients(mmg, NAMES).values()))
    with torch.no_grad():
        first_loss = float(multistep_loss(mmg, windows, W_V)[0])
    said: list[str] = []
    reports: list = []
    run = RunProgress([], TrainingSummary(len(windows), len(windows), SplitReport(), "cpu"))
    loop = TrainingLoop(exp, Checkpointing(tmp_path / "ckpt.pt", exp.to_toml()), TrainingJournal(said.append),
                        run, on_epoch=reports.append)
    solver = GradientIdentification(exp, loop)
    assert isinstance(solver, Identification) and solver.fit(mmg, _data(windows)) is solver
    after = np.array(list(coefficients(mmg, NAMES).values()))
    assert np.linalg.norm((after - truth) / truth) < 0.7 * np.linalg.norm((first - truth) / truth)
    assert solver.stage_.best_loss < 0.5 * first_loss and len(solver.stage_.history) == 15
    assert solver.estimator_.solver is Solver.GRADIENT and solver.estimator_.epochs == 15
    # the loop's parts wrote and said it: one checkpoint, one report per epoch, the stage's line
    assert (tmp_path / "ckpt.pt").is_file() and [r.epoch for r in reports] == list(range(1, 16))
    assert said[-1].startswith("identify: 15 epochs, best early-stopping loss")
