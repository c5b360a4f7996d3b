"""Hybrid identification: penalty, kNN gate, run artefacts, training on a synthetic ship
with a known added force (ground truth)."""
from pathlib import Path

import numpy as np
import pytest
import torch

from sysid import MMG, integrate, load_ship
from sysid.hybrid.correction import ForceCorrection
from sysid.data.recordings import Run
from sysid.errors import CheckpointError, ConfigError, IncompleteOutputError
from sysid.store.manifest import write_manifest
from sysid.config.experiment import load_experiment, parse_experiment
from sysid.hybrid.knn_gate import KNNGate
from sysid.evaluation.evaluate import evaluate_model
from sysid.runs.layout import load_model, write_run
from sysid.identify.trainer import Trainer, output_penalty

ADDED_FORCE = torch.tensor([-1.5, 0.8, -0.6], dtype=torch.float64)  # X [N], Y [N], N [N m], body frame


class ShipWithAddedForce(torch.nn.Module):
    """The 'true' ship: our MMG plus a constant unmodelled body-frame force."""

    def __init__(self):
        super().__init__()
        self.mmg = MMG(load_ship("esso_osaka"))

    @property
    def coefficients(self):
        return self.mmg.coefficients

    def forward(self, state, inputs):
        f = self.mmg(state, inputs)
        f.correction = ADDED_FORCE.expand_as(f.hull)
        return f


def synthetic_runs(n_runs=4, seconds=240, seed=0):
    """1 Hz runs simulated at 0.1 s (RK4) with piecewise-constant random rudder and propeller."""
    rng = np.random.default_rng(seed)
    truth = ShipWithAddedForce()
    runs = []
    for k in range(n_runs):
        steps = seconds * 10 + 1
        hold = 150  # 15 s between command changes
        n_cmd = rng.uniform(6, 14, steps // hold + 1).repeat(hold)[:steps]
        d_cmd = np.radians(rng.uniform(-30, 30, steps // hold + 1)).repeat(hold)[:steps]
        inputs = np.stack([n_cmd, d_cmd, np.full(steps, 1.5), np.full(steps, 1.0)], -1)
        x0 = torch.tensor([0.0, 0.3, 0.0, 0.0, rng.uniform(-3, 3), 0.0], dtype=torch.float64)
        with torch.no_grad():
            states = integrate(truth, x0, torch.tensor(inputs), 0.1, "rk4").numpy()
        sel = slice(0, steps, 10)
        t = np.arange(steps)[sel] * 0.1
        runs.append(Run(f"synthetic_{k}", Path(f"synthetic_{k}.csv"), t, states[sel], inputs[sel],
                        np.zeros((len(t), 2)), 1.0))
    return runs


def small_experiment(**training):
    opts = {"epochs": 2, "batch_size": 64, "warm_start_epochs": 40, "max_minutes": 2.0, **training}
    return parse_experiment({"experiment": {"model": "hybrid", "dataset": "D2", "name": "synthetic"},
                             "data": {"exclude_suspect": False},
                             "training": opts, "gate": {"k": 5}})


@pytest.fixture(scope="module")
def trained():
    runs = synthetic_runs()
    trainer = Trainer(small_experiment(), progress=False, log=lambda m: None).fit(runs)
    return runs, trainer


def test_penalty_is_zero_inside_the_band_and_grows_outside():
    f_mmg = torch.tensor([[10.0, -20.0, 5.0]])
    w = torch.tensor([1.0, 0.5, 2.0])
    inside = torch.tensor([[1.99, 3.9, -0.99]])  # |F_NN| < 0.2 |F_MMG| componentwise
    assert float(output_penalty(inside, f_mmg, w)) == 0.0
    just = torch.tensor([[2.0, -4.0, 1.0]])
    assert float(output_penalty(just, f_mmg, w)) == 0.0
    out1 = torch.tensor([[3.0, 0.0, 0.0]])
    out2 = torch.tensor([[-4.0, 0.0, 0.0]])
    assert float(output_penalty(out1, f_mmg, w)) == pytest.approx(1.0)
    assert float(output_penalty(out2, f_mmg, w)) == pytest.approx(2.0)  # linear growth, sign-blind
    both = torch.tensor([[3.0, 6.0, 2.0]])
    assert float(output_penalty(both, f_mmg, w)) == pytest.approx(1.0 + 0.5 * 2.0 + 2.0 * 1.0)
    # [training] force_band widens or narrows the band: 0.5 |F_MMG| = (5, 10, 2.5)
    assert float(output_penalty(both, f_mmg, w, band=0.5)) == 0.0
    assert float(output_penalty(out1, f_mmg, w, band=0.0)) == pytest.approx(3.0)


def test_knn_threshold_is_the_alpha_quantile_of_leave_one_out_distances():
    g = torch.Generator().manual_seed(3)
    feats = torch.randn(500, 8, generator=g, dtype=torch.float64)
    gate = KNNGate(k=10, alpha=0.95, features=8, dtype=torch.float64).fit(feats)
    d = np.linalg.norm(feats.numpy()[:, None] - feats.numpy()[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    loo = np.sort(d, axis=1)[:, :10].mean(1)
    np.testing.assert_allclose(gate.train_distances.numpy(), loo, rtol=1e-10)
    expected = np.quantile(loo, 0.95, method="inverted_cdf")  # inf{x : F(x) >= alpha}
    assert float(gate.threshold) == pytest.approx(expected, rel=1e-12)
    assert (gate.train_distances <= gate.threshold).double().mean() >= 0.95
    # a query's distance is the mean over its k nearest bank points
    q = feats[:3] + 0.01
    dq = np.sort(np.linalg.norm(q.numpy()[:, None] - feats.numpy()[None], axis=-1), axis=1)[:, :10].mean(1)
    np.testing.assert_allclose(gate.distance(q).numpy(), dq, rtol=1e-10)


def test_knn_gate_in_chunks_sharing_one_buffer_has_the_brute_force_distances():
    """Leave-one-out and query distances in chunks of 64 rows (a partial last chunk, one
    squared-distance buffer reused across chunks): the brute-force distances."""
    g = torch.Generator().manual_seed(4)
    feats = torch.randn(500, 8, generator=g, dtype=torch.float64)
    gate = KNNGate(k=10, alpha=0.95, features=8, dtype=torch.float64, chunk=64).fit(feats)
    d = np.linalg.norm(feats.numpy()[:, None] - feats.numpy()[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    np.testing.assert_allclose(gate.train_distances.numpy(), np.sort(d, axis=1)[:, :10].mean(1), rtol=1e-10)
    q = feats[:130] + 0.01
    dq = np.sort(np.linalg.norm(q.numpy()[:, None] - feats.numpy()[None], axis=-1), axis=1)[:, :10].mean(1)
    np.testing.assert_allclose(gate.distance(q).numpy(), dq, rtol=1e-10)


@pytest.mark.slow
def test_gate_returns_the_mmg_force_exactly_far_outside(trained):
    runs, trainer = trained
    model = trainer.model_.double()
    state = torch.tensor([[0.0, 0.3, 0.0, 0.01, 0.5, 0.01], [0.0, 4.0, 0.0, 2.5, 0.5, 0.8]], dtype=torch.float64)
    inputs = torch.tensor([[10.0, 0.2, 1.5, 1.0], [-30.0, -0.6, 15.0, 4.0]], dtype=torch.float64)
    f = model(state, inputs)
    assert bool(f.gate_on[0]) and not bool(f.gate_on[1])
    assert float(f.ood_distance[1]) > float(model.gate.threshold)
    assert torch.equal(f.total[1], model.mmg(state, inputs).mmg[1])  # exactly F_MMG
    assert float(f.correction[0].detach().abs().sum()) > 0


@pytest.mark.slow
def test_two_epochs_on_a_synthetic_ship_recover_the_added_force(trained):
    runs, trainer = trained
    info, hist = trainer.summary_, trainer.history_
    train_hist = hist[hist.stage == "train"]
    assert len(train_hist) == 2
    assert train_hist.early_stopping_loss.iloc[-1] < info.mmg_val_loss * 0.5  # far better than MMG alone
    model = trainer.model_.double()
    states = torch.tensor(np.concatenate([r.states for r in runs]))
    inputs = torch.tensor(np.concatenate([r.inputs for r in runs]))
    with torch.no_grad():
        f_nn = model(states, inputs).correction.mean(0)
    assert torch.equal(torch.sign(f_nn), torch.sign(ADDED_FORCE))
    np.testing.assert_allclose(f_nn.numpy(), ADDED_FORCE.numpy(), rtol=0.35)


@pytest.mark.slow
def test_saved_run_reloads_to_identical_predictions(trained, tmp_path):
    runs, trainer = trained
    model = trainer.model_.double()
    exp = small_experiment()
    evaluation = evaluate_model(model, runs[:2], [30.0])
    write_run(tmp_path / "run", exp, model, evaluation, trainer.history_, trainer.summary_)
    for name in ("config.toml", "model.pt", "knn.pt", "standardization.json", "history.csv", "metrics.csv", "summary.json"):
        assert (tmp_path / "run" / name).is_file(), name
    assert len(list((tmp_path / "run" / "traces").glob("*.csv"))) == 2
    _, reloaded = load_model(tmp_path / "run")
    again = evaluate_model(reloaded, runs[:2], [30.0])
    np.testing.assert_array_equal(again.metrics[["rmse_u", "rmse_v", "rmse_r"]].to_numpy(),
                                  evaluation.metrics[["rmse_u", "rmse_v", "rmse_r"]].to_numpy())
    for name, frame in evaluation.traces.items():
        np.testing.assert_array_equal(again.traces[name].to_numpy(), frame.to_numpy())

    # a corrupt run directory gives one clear error naming the file
    (tmp_path / "run" / "model.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(IncompleteOutputError, match=r"run: model.pt does not match its checksum"):
        load_model(tmp_path / "run")
    write_manifest(tmp_path / "run", "run")  # sealed as it is: the loader still refuses it
    with pytest.raises(CheckpointError, match=r"model.pt: cannot be loaded safely \(not a checkpoint of plain tensors[^\n]*\)$"):
        load_model(tmp_path / "run")
    (tmp_path / "run" / "model.pt").unlink()
    with pytest.raises(IncompleteOutputError, match=r"run: incomplete run directory: model.pt is missing"):
        load_model(tmp_path / "run")
    with pytest.raises(CheckpointError, match="run directory not found"):
        load_model(tmp_path / "nowhere")


@pytest.mark.parametrize("text, message", [
    ("[experiment]\nmodel = 'lstm'\n", "model = 'lstm': choose one of mmg, nn, hybrid"),
    ("[experiment]\nmodel = 'hybrid'\n[training]\nepochs = 'many'\n", r"\[training\] epochs: expected an integer"),
    ("[experiment]\nmodel = 'hybrid'\n[training]\nlearning_rat = 0.1\n", r"\[training\] unknown key 'learning_rat'"),
    ("[experiment]\nmodel = 'hybrid'\n[gate]\nalpha = 1.5\n", r"\[gate\] alpha must be in \(0, 1\)"),
    ("[experiment]\nmodel = 'hybrid'\n[identify]\nparameters = ['X_zz']\n", "unknown ship parameter 'X_zz'"),
    ("[experiment\nmodel = 'hybrid'\n", "not valid TOML"),
    ("[experimnt]\nmodel = 'hybrid'\n", r"unknown section\(s\) \['experimnt'\]"),
])
def test_bad_configs_give_one_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_experiment(path)


def test_paper_configs_are_valid():
    root = Path(__file__).resolve().parents[2] / "configs" / "experiments"
    names = {p.stem for p in root.glob("*.toml")}
    assert {"mmg_paper", "mmg_lab", "nn_D1", "nn_D2", "hybrid_D1", "hybrid_D2"} <= names
    for path in root.glob("*.toml"):
        load_experiment(path)


@pytest.mark.slow
def test_gradient_identification_recovers_a_perturbed_coefficient():
    """Data from a ship whose N_r differs from the definition; identify N_r and N_v back."""
    rng = np.random.default_rng(1)
    truth = MMG(load_ship("esso_osaka", {"N_r": -0.07}))
    runs = []
    for k in range(3):
        steps = 181
        n_cmd = rng.uniform(8, 14, 13).repeat(15)[:steps]
        d_cmd = np.radians(rng.uniform(-30, 30, 13)).repeat(15)[:steps]
        inputs = np.stack([n_cmd, d_cmd, np.zeros(steps), np.zeros(steps)], -1)
        x0 = torch.tensor([0.0, 0.35, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64)
        with torch.no_grad():
            states = integrate(truth, x0, torch.tensor(inputs), 1.0, "euler").numpy()
        runs.append(Run(f"ident_{k}", Path(f"ident_{k}.csv"), np.arange(steps, dtype=float), states, inputs,
                        np.zeros((steps, 2)), 1.0))
    exp = parse_experiment({"experiment": {"model": "mmg", "dataset": "D2"}, "data": {"exclude_suspect": False},
                            "training": {"batch_size": 64, "dtype": "float64", "patience": 100},
                            "identify": {"parameters": ["N_r", "N_v"], "epochs": 25, "learning_rate": 0.05,
                                         "bounds": {"N_r": [-0.3, 0.1], "N_v": [-0.5, 0.1]}}})
    trainer = Trainer(exp, progress=False, log=lambda m: None).fit(runs)
    found = trainer.summary_.identified
    assert trainer.summary_.identified_initial["N_r"] == pytest.approx(-0.04849)
    assert found["N_r"] == pytest.approx(-0.07, abs=0.004)  # started at -0.04849
    assert found["N_v"] == pytest.approx(-0.1458, abs=0.01)  # stays where the truth has it


def test_force_correction_is_the_papers_network_and_members_average():
    torch.manual_seed(0)
    net = ForceCorrection((64, 64), torch.float64, members=3)
    net.set_standardization(torch.arange(9.0), torch.full((9,), 2.0), torch.tensor([1.0, -2.0, 0.5]),
                            torch.tensor([10.0, 20.0, 5.0]))
    assert sum(p.numel() for p in net.parameters()) == 3 * 4995  # paper Eq. (25), per member
    s = torch.randn(7, 9, dtype=torch.float64)
    force, z = net.evaluate(s)
    assert force.shape == (7, 3) and z.shape == (7, 64)
    by_hand = []
    for k in range(3):  # 9-64-64-3, tanh, Eqs. (8)-(10)
        h = (s - net.input_mean) / net.input_std
        h = torch.tanh(h @ net.weights[0][k] + net.biases[0][k])
        h = torch.tanh(h @ net.weights[1][k] + net.biases[1][k])
        by_hand.append((h @ net.weights[2][k] + net.biases[2][k]) * net.output_std + net.output_mean)
    torch.testing.assert_close(force, torch.stack(by_hand).mean(0))
    per_member = net.evaluate(s.expand(3, 7, 9), per_member=True)[0]
    torch.testing.assert_close(per_member, torch.stack(by_hand))



@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_one_member_without_gradient_is_the_member_axis_path_to_the_bit(dtype):
    """Without gradient a one-member network runs as 2-d products (fewer operations per
    call of a small eager batch): the same bits as the member-axis path (with gradient),
    for features and forces, standardised or not, any leading shape."""
    torch.manual_seed(1)
    net = ForceCorrection((128, 128), dtype, members=1)
    net.set_standardization(torch.linspace(-1, 1, 9), torch.linspace(0.5, 2, 9), torch.tensor([1.0, -2.0, 0.5]),
                            torch.tensor([10.0, 20.0, 5.0]))
    for shape in [(9,), (2, 9), (5, 3, 9), (827, 9)]:
        s = torch.randn(*shape, dtype=torch.float64)
        for standardized in (False, True):
            with torch.enable_grad():
                force, z = net.evaluate(s, standardized=standardized)
            with torch.no_grad():
                fast_force, fast_z = net.evaluate(s, standardized=standardized)
            assert fast_force.shape == force.shape and fast_z.shape == z.shape
            assert torch.equal(fast_force, force) and torch.equal(fast_z, z)


@pytest.mark.slow
def test_val_loss_multistep_is_the_final_models_validation_loss_at_the_objective_horizon(trained):
    """summary.val_loss_multistep (the sweep objective): L_v of the final (gated) model on
    validation windows of each [evaluation] horizon the validation blocks hold (windows of
    h / dt samples, as the test windows), averaged; with objective_s, on validation windows of
    that many seconds."""
    from sysid.errors import ConfigError, DataError
    from sysid.identify.trainer import multistep_loss, split_windows
    runs, trainer = trained
    exp = trainer.experiment
    t = exp.training
    model = trainer.model_
    train, _, _, _ = split_windows(runs, t.steps, t.stride_s, t.val_fraction, False, torch.float32,
                                   t.block_s, exp.experiment.seed)
    from sysid.channel_names import VELOCITY_INDEX
    w_v = 1.0 / train.states[:, :, list(VELOCITY_INDEX)].reshape(-1, 3).var(0)
    losses = {}
    for horizon in exp.evaluation.horizons:
        try:
            val = split_windows(runs, int(round(horizon / runs[0].dt)) - 1, t.stride_s, t.val_fraction, False,
                                torch.float32, t.block_s, exp.experiment.seed)[1]
        except (DataError, ConfigError):   # no window that long, or longer than a 30-s block
            continue
        with torch.no_grad():
            losses[horizon] = float(multistep_loss(model, val, w_v)[0])
    assert set(losses) == set(trainer.validation_sets_) and 30.0 in losses
    assert trainer.summary_.val_loss_multistep == pytest.approx(np.mean(list(losses.values())), rel=1e-5)
    # the rollouts' errors the verdict's validation scores reuse: those of a fresh rollout
    from sysid.dynamics.rollouts import rollout_errors
    assert list(trainer.validation_errors_) == list(trainer.validation_sets_)
    for horizon, windows in trainer.validation_sets_.items():
        # the same rollouts; a rerun here may split the products over other threads (float32 sums)
        torch.testing.assert_close(trainer.validation_errors_[horizon], rollout_errors(model, windows),
                                   rtol=1e-5, atol=1e-7)

    longer = Trainer(small_experiment(objective_s=20.0), progress=False, log=lambda m: None).fit(runs)
    _, val20, _, _ = split_windows(runs, 20, t.stride_s, t.val_fraction, False, torch.float32, t.block_s,
                                   exp.experiment.seed)
    with torch.no_grad():
        expected20 = float(multistep_loss(longer.model_, val20, w_v)[0])
    assert longer.summary_.val_loss_multistep == pytest.approx(expected20, rel=1e-5)
    assert longer.summary_.val_loss_multistep < losses[30.0]  # errors grow with the horizon


@pytest.mark.parametrize("kind", ["shared", "identified", "nn", "features"])
def test_seed_ensemble_no_grad_rate_is_the_rate_of_its_mean_force(kind):
    """The ensemble's no-grad right-hand side (the members' FNNs as one batched product on
    the member axis, the MMG from the native kernel) against `forward`'s mean force through
    the equations of motion: the same dx/dt to round-off and the same gate decisions, for
    hybrids of one MMG, hybrids whose identified hull coefficients differ (their mass terms
    shared), NN-only members, and gates in the features (each member's own features)."""
    from sysid.dynamics.equations import state_derivative
    from sysid.hybrid.ensemble import SeedEnsemble
    from sysid.hybrid.correction import correction_inputs
    from sysid.hybrid.force_models import CorrectedModel
    from sysid.mmg.wind import relative_wind

    gen = torch.Generator().manual_seed(1)
    state = torch.randn(40, 6, generator=gen, dtype=torch.float64) * torch.tensor([1, 2, 1, 0.3, 1, 0.01]) \
        + torch.tensor([0, 6, 0, 0, 0, 0])
    inputs = torch.randn(40, 4, generator=gen, dtype=torch.float64).abs() * torch.tensor([2, 0.3, 8, 3])

    def member(seed: int, overrides: dict | None = None) -> CorrectedModel:
        torch.manual_seed(seed)
        net = ForceCorrection((16, 16), torch.float64)
        net.set_standardization(torch.full((9,), 0.1 * seed), torch.full((9,), 3.0 + seed), torch.zeros(3),
                                torch.tensor([1e5, 1e5, 1e7]))
        space = "features" if kind == "features" else "inputs"
        model = CorrectedModel(MMG(load_ship("esso_osaka", overrides)), net, None, kind != "nn", space)
        bank = torch.randn(200, 9, dtype=torch.float64)
        if space == "features":  # near the features of the first 20 rows below: both decisions occur
            with torch.no_grad():
                wind = torch.stack(relative_wind(state[:20, 1], state[:20, 3], state[:20, 4], inputs[:20, 2],
                                                 inputs[:20, 3]), -1)
                near = correction_inputs(state[:20], inputs[:20], wind).repeat(10, 1)
                bank = net.features(near * (1 + 0.01 * torch.randn(200, 9, dtype=torch.float64)))
        model.gate = KNNGate(3, 0.9, bank.shape[1], torch.float64).fit(bank)
        model.gate_enabled = True
        return model

    overrides = [None, {"N_r": -0.07}, {"Y_v": -0.3}] if kind == "identified" else [None] * 3
    ensemble = SeedEnsemble([member(k, o) for k, o in enumerate(overrides)])
    with torch.no_grad():
        forces = ensemble(state, inputs)
        expected = state_derivative(state, forces.total, ensemble.coefficients)
        rate = ensemble.no_grad_rate(state)
        assert rate is not None
        dx, on = rate(state, inputs)
        assert ensemble.eager_rate(state, inputs)[0].equal(dx)
    torch.testing.assert_close(dx, expected, rtol=1e-10, atol=1e-12)
    assert torch.equal(on, forces.gate_on) and 0 < int(on.sum()) < len(on)
    heavier = SeedEnsemble([member(0), member(1, {"m_x": 0.05})])  # other mass terms: no shared rate
    assert heavier.no_grad_rate(state) is None


def test_seed_ensemble_of_hybrids_is_their_mmg_plus_the_mean_gated_correction():
    """Hybrids sharing one MMG: the ensemble computes F_MMG once; its forces equal the mean
    of the members' own forces (each member called alone), gate decisions by majority.
    Members whose MMG coefficients differ (identified) average their whole forces."""
    from sysid.hybrid.ensemble import SeedEnsemble
    from sysid.hybrid.force_models import CorrectedModel

    def member(seed: int, overrides: dict | None = None) -> CorrectedModel:
        torch.manual_seed(seed)
        net = ForceCorrection((16, 16), torch.float64)
        net.set_standardization(torch.zeros(9), torch.full((9,), 3.0), torch.zeros(3), torch.tensor([1e5, 1e5, 1e7]))
        model = CorrectedModel(MMG(load_ship("esso_osaka", overrides)), net, None, True, "inputs")
        model.gate = KNNGate(3, 0.9, 9, torch.float64).fit(torch.randn(200, 9, dtype=torch.float64))
        model.gate_enabled = True
        return model

    gen = torch.Generator().manual_seed(1)
    state = torch.randn(40, 6, generator=gen, dtype=torch.float64) * torch.tensor([1, 2, 1, 0.3, 1, 0.01]) \
        + torch.tensor([0, 6, 0, 0, 0, 0])
    inputs = torch.randn(40, 4, generator=gen, dtype=torch.float64).abs() * torch.tensor([2, 0.3, 8, 3])
    for members, shared in (([member(0), member(1), member(2)], True),
                            ([member(0), member(1, {"N_r": -0.07})], False)):
        ensemble = SeedEnsemble(members)
        assert ensemble._shared_mmg is shared
        parts = [m(state, inputs) for m in members]
        forces = ensemble(state, inputs)
        torch.testing.assert_close(forces.total, torch.stack([p.total for p in parts]).mean(0), rtol=1e-12, atol=1e-9)
        torch.testing.assert_close(forces.correction, torch.stack([p.correction for p in parts]).mean(0))
        majority = torch.stack([p.gate_on for p in parts]).double().mean(0) >= 0.5
        assert torch.equal(forces.gate_on, majority) and 0 < int(majority.sum()) < len(majority)
