"""The simulation around the indices: straight-running revolutions against the closed form
of the standard MMG, the rudder's mean over a rate-limited step against quadrature, the
kNN gate's share along a maneuver that leaves the training data, the spread over an
ensemble's members, and (slow) the compiled loop against the eager one."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from sysid import MMG, load_ship
from sysid.config.choices import Method
from sysid.hybrid.correction import ForceCorrection, correction_inputs
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.hybrid.force_models import CorrectedModel
from sysid.hybrid.knn_gate import KNNGate
from sysid.maneuvers import (BASELINE_LABEL, Conditions, CrashStop, ManeuverError, ManeuverModel, TurningCircle,
                             ZigZag, default_conditions, physics_baseline, run_baseline, run_maneuvers,
                             simulate_maneuvers, straight_running_rps)
from sysid.maneuvers.controllers import rate_limited
from sysid.maneuvers.indices import INDEX_COLUMNS
from sysid.maneuvers.outputs import beside_baseline, criteria_table, indices_table
from sysid.maneuvers.simulate import gate_off_share, simulate_rows
from sysid.maneuvers.straight import surge_acceleration
from sysid.mmg.wind import relative_wind


def test_straight_running_rps_is_the_closed_form_of_the_standard_mmg():
    """v = r = 0, rudder amidships: (1 - t_P) rho D^4 K_T(J) n^2 = R'_0 0.5 rho L d U^2 with
    J = U (1 - w_P0) / (n D), a quadratic in n."""
    ship = load_ship("kvlcc2_l7")
    p = ship.parameters
    U = 1.1
    a = U * (1 - p["w_P0"]) / p["D"]
    R = 0.5 * p["L_pp"] * p["d"] * U**2 * p["R_0"] / ((1 - p["t_P"]) * p["D"] ** 4)
    k0, k1, k2 = p["k0"], p["k1"], p["k2"]
    n = (-k1 * a + math.sqrt(k1**2 * a**2 - 4 * k0 * (k2 * a**2 - R))) / (2 * k0)
    model = MMG(ship)
    assert straight_running_rps(model, U) == pytest.approx(n, rel=1e-10)
    assert abs(surge_acceleration(model, U, np.array([n]))[0]) < 1e-12


def test_an_nn_only_model_outside_its_data_at_rest_says_why_it_has_no_straight_running():
    """NN-only with its gate fitted on straight running at 11.8 rps: with the propeller
    stopped the state lies outside the training data, the FNN is off and no force acts
    (du/dt = 0 exactly), which the error names."""
    bank = torch.zeros(400, 6, dtype=torch.float64)
    bank[:, 1] = torch.linspace(1.17248 - 0.05, 1.17248 + 0.05, 400)
    model = _hybrid_without_correction(load_ship("kvlcc2_l7"), bank)
    model.physics = False   # NN-only: F = gate * F_NN
    with pytest.raises(ManeuverError, match=r"du/dt = 0 m/s\^2; at 0 rps the kNN gate is off: .*NN-only has no force"):
        straight_running_rps(model, 1.17248)


def test_straight_running_without_a_root_is_one_clear_error():
    with pytest.raises(ManeuverError, match="no propeller revolutions"):
        straight_running_rps(MMG(load_ship("kvlcc2_l7")), 1.1, max_rps=2.0)


@pytest.mark.parametrize("angle, order", [(0.0, 0.5), (0.3, 0.32), (-0.1, 0.0), (0.2, 0.2)])
def test_rudder_mean_over_a_step_is_the_integral_of_the_rate_limited_ramp(angle, order):
    rate_dt = 0.05  # rad per step
    fine = np.linspace(0.0, 1.0, 200001)
    path = angle + np.clip(order - angle, -rate_dt * fine, rate_dt * fine)  # moves at the rate, stops at the order
    mean, end = rate_limited(*(torch.tensor([v], dtype=torch.float64) for v in (angle, order, rate_dt)))
    assert float(mean) == pytest.approx(np.trapezoid(path, fine), abs=1e-9)
    assert float(end) == pytest.approx(path[-1], abs=1e-15)


def _brute_force_distances(hybrid, result) -> np.ndarray:
    """The mean distance of each step of `result` to its k nearest rows of the gate's bank, by
    numpy over the whole bank (the independent truth of the gate's own distances)."""
    bank = hybrid.gate.bank.numpy()
    wind = torch.stack(relative_wind(*(torch.tensor(c) for c in (result.states[:, 1], result.states[:, 3],
                                                                   result.states[:, 4], result.inputs[:, 2],
                                                                   result.inputs[:, 3]))), -1)
    z = hybrid.gate_coordinates(correction_inputs(torch.tensor(result.states), torch.tensor(result.inputs),
                                                  wind)).detach().numpy()
    return np.sort(np.linalg.norm(z[:, None] - bank[None], axis=-1), 1)[:, :hybrid.gate.k].mean(1)


def _hybrid_without_correction(ship, bank_states: torch.Tensor) -> CorrectedModel:
    """A hybrid whose FNN gives zero force (so its motion is the MMG's) and whose kNN gate
    (inputs space, k = 5) was fitted on `bank_states` in straight running."""
    mmg = MMG(ship)
    net = ForceCorrection((8,), torch.float64)
    with torch.no_grad():
        net.weights[-1].zero_()
        net.biases[-1].zero_()
    model = CorrectedModel(mmg, net, None, physics=True, gate_space="inputs")
    n = straight_running_rps(mmg, float(bank_states[0, 1]))
    inputs = torch.zeros(len(bank_states), 4, dtype=torch.float64)
    inputs[:, 0] = n
    wind = torch.stack(relative_wind(bank_states[:, 1], bank_states[:, 3], bank_states[:, 4], inputs[:, 2],
                                     inputs[:, 3]), -1)
    coordinates = model.gate_coordinates(correction_inputs(bank_states, inputs, wind))
    model.gate, model.gate_enabled = KNNGate(5, 0.99, coordinates.shape[1], torch.float64).fit(coordinates), True
    return model


def test_gate_share_says_a_maneuver_runs_outside_the_training_data():
    ship = load_ship("kvlcc2_l7")
    U0 = 1.17248
    bank = torch.zeros(400, 6, dtype=torch.float64)
    bank[:, 1] = torch.linspace(U0 - 0.05, U0 + 0.05, 400)  # trained on straight running only
    hybrid = _hybrid_without_correction(ship, bank)
    conditions, _ = default_conditions(MMG(ship), ship, duration=40.0, dt=0.2)
    turn = [TurningCircle(35.0)]
    theirs, ours = simulate_maneuvers(MMG(ship), turn, conditions)[0], simulate_maneuvers(hybrid, turn, conditions)[0]
    np.testing.assert_allclose(ours.states, theirs.states, rtol=0, atol=1e-12)  # F_NN = 0: the MMG's motion
    assert theirs.gate_off_share is None
    assert ours.gate_off_share > 0.9  # the turn leaves straight running within seconds
    scan = gate_off_share(hybrid, torch.tensor(ours.states[:-1]), torch.tensor(ours.inputs[:-1]))
    assert ours.gate_off_share == scan  # the loop's decisions are the gate's own scan's
    row = indices_table([ours], float(ship["L_pp"]), U0, None).iloc[0]
    assert bool(row["mostly_outside"]) and row["gate_off_share"] == ours.gate_off_share


def test_each_steps_knn_distance_is_the_brute_force_one_and_decides_the_gate():
    """Every step's d_kNN (and the gate's threshold) against a brute-force numpy kNN over
    the gate's bank: the mean distance to the k nearest bank vectors; the threshold the
    alpha-quantile of the bank's leave-one-out distances; the gate on exactly where d_kNN
    is at most it. The trajectory table carries both per step, the indices table the
    largest distance and the threshold."""
    from sysid.maneuvers.outputs import trajectory_table
    ship = load_ship("kvlcc2_l7")
    U0 = 1.17248
    bank_states = torch.zeros(400, 6, dtype=torch.float64)
    bank_states[:, 1] = torch.linspace(U0 - 0.05, U0 + 0.05, 400)
    hybrid = _hybrid_without_correction(ship, bank_states)
    conditions, _ = default_conditions(MMG(ship), ship, duration=30.0, dt=0.2)
    inputs = torch.zeros(400, 4, dtype=torch.float64)   # straight running with the rudder up to 5 deg
    inputs[:, 0], inputs[:, 1] = conditions.rps, math.radians(5.0) * torch.sin(torch.arange(400.0) * 0.7)
    wind = torch.stack(relative_wind(bank_states[:, 1], bank_states[:, 3], bank_states[:, 4], inputs[:, 2],
                                     inputs[:, 3]), -1)
    hybrid.gate.fit(hybrid.gate_coordinates(correction_inputs(bank_states, inputs, wind)))
    result = simulate_maneuvers(hybrid, [TurningCircle(35.0)], conditions)[0]
    bank, k = hybrid.gate.bank.numpy(), hybrid.gate.k
    brute = _brute_force_distances(hybrid, result)
    loo = np.sort(np.linalg.norm(bank[:, None] - bank[None], axis=-1), 1)[:, 1:k + 1].mean(1)
    threshold = np.sort(loo)[math.ceil(hybrid.gate.alpha * len(loo)) - 1]
    np.testing.assert_allclose(result.knn_distance, brute, rtol=1e-9, atol=1e-12)
    assert result.knn_threshold == pytest.approx(threshold, rel=1e-7)  # |a|^2 + |b|^2 - 2 a.b: round-off
    np.testing.assert_array_equal(result.gate_on[:-1], (brute[:-1] <= threshold).astype(float))
    assert math.isnan(result.gate_on[-1])  # the last state starts no step
    assert 0.0 < result.gate_off_share < 1.0 and result.gate_off_share == pytest.approx(1 - result.gate_on[:-1].mean())
    table = trajectory_table([result])
    np.testing.assert_array_equal(table["knn_distance"].to_numpy(), result.knn_distance)
    row = indices_table([result], float(ship["L_pp"]), U0, None).iloc[0]
    assert row["knn_distance_max"] == pytest.approx(brute.max()) and row["knn_threshold"] == pytest.approx(threshold)
    mmg = simulate_maneuvers(MMG(ship), [TurningCircle(35.0)], conditions)[0]
    assert mmg.gate_on is None and mmg.knn_distance is None and "gate_on" not in trajectory_table([mmg])


@pytest.mark.parametrize("seeds", [False, True])
def test_a_hybrid_without_correction_has_the_indices_of_its_physics_baseline(seeds):
    """F_NN = 0 (last layer zeroed): the hybrid's motion (alone, or a folder of two such
    seeds) is its MMG's, so beside its physics baseline every index is the same to
    round-off and every difference is zero; the baseline is the MMG of the subject's ship,
    labelled as `sysid compare` labels it."""
    ship = load_ship("kvlcc2_l7")
    bank = torch.zeros(400, 6, dtype=torch.float64)
    bank[:, 1] = torch.linspace(1.12, 1.22, 400)
    if seeds:
        members = [(f"zero seed{i}", _hybrid_without_correction(ship, bank[i::2])) for i in range(2)]
        model = SeedEnsemble([m for _, m in members])
        subject = ManeuverModel("zero", model, ship, model.kind, members, "seeds")
    else:
        subject = ManeuverModel("zero", _hybrid_without_correction(ship, bank), ship, "hybrid")
    physics = physics_baseline(subject)
    assert physics.label == BASELINE_LABEL == "MMG (ship file)" and physics.kind == "mmg"
    assert isinstance(physics.model, MMG) and physics.model.ship is ship
    maneuvers = [TurningCircle(35.0), ZigZag(10.0, 10.0), CrashStop()]
    conditions = Conditions(1.17248, 11.8, 15.7, 0.2, 120.0)
    ours = run_maneuvers(subject, maneuvers[:2], conditions)
    theirs, left_out = run_baseline(physics, maneuvers, conditions)
    assert left_out == ["crash_stop"]  # kvlcc2_l7's propeller is for ahead motion only
    assert [r.model for r in theirs] == [BASELINE_LABEL] * 2
    for mine, base in zip(ours, theirs):
        assert mine.maneuver == base.maneuver
        for name, value in mine.indices.as_dict().items():
            other = getattr(base.indices, name)
            assert (math.isnan(value) and math.isnan(other)) or value == pytest.approx(other, rel=1e-10, abs=1e-10)
    assert ours[0].indices.tactical_diameter_m > 7.0 and ours[1].indices.first_overshoot_deg > 0  # reached
    table = indices_table([*ours, *theirs], 7.0, 1.17248, None)
    assert list(table.model) == ["zero", "zero", BASELINE_LABEL, BASELINE_LABEL]
    both = beside_baseline(table, "zero")
    assert {"advance_m", "tactical_diameter_m", "first_overshoot_deg", "second_overshoot_deg"} <= set(both["index"])
    np.testing.assert_allclose(both["difference"], 0.0, atol=1e-9)
    assert set(both["unit"]) == {"m", "deg", "-"}
    assert list(criteria_table([*ours, *theirs], 7.0, 1.17248, None).model.unique()) == ["zero", BASELINE_LABEL]
    assert physics_baseline(ManeuverModel("mmg", MMG(ship), ship, "mmg")) is None  # an MMG is its own physics


def test_beside_baseline_keeps_a_nan_and_differences_what_both_reached():
    """An index one model reached and the other not: both shown, the difference NaN; so too
    where one of them diverged."""
    import pandas as pd
    table = pd.DataFrame([{"maneuver": "turning_35_starboard", "model": m, **{c: math.nan for c in INDEX_COLUMNS},
                           "advance_m": a, "tactical_diameter_m": d} for m, a, d in
                          (("run", 20.0, 30.0), (BASELINE_LABEL, 18.5, math.nan))])
    table["diverged"] = False
    both = beside_baseline(table, "run").set_index("index")
    assert list(both.index) == ["advance_m", "tactical_diameter_m"]
    assert both.loc["advance_m", "difference"] == 1.5 and both.loc["advance_m", "unit"] == "m"
    assert math.isnan(both.loc["tactical_diameter_m", "difference"]) and both.loc["tactical_diameter_m", "learned"] == 30
    table.loc[1, "diverged"] = True  # the baseline's indices are not valid: no difference, the values kept
    both = beside_baseline(table, "run").set_index("index")
    assert both.loc["advance_m", "diverged"] == BASELINE_LABEL and math.isnan(both.loc["advance_m", "difference"])
    assert both.loc["advance_m", "baseline"] == 18.5


def test_ensemble_indices_carry_the_members_spread():
    ships = [load_ship("kvlcc2_l7", {"N_r": v}) for v in (-0.049, -0.055)]
    members = [MMG(s) for s in ships]
    subject = ManeuverModel("two", SeedEnsemble(members), ships[0], "mmg", [("a", members[0]), ("b", members[1])],
                            "ensemble members")
    conditions = Conditions(1.17248, 11.8, 15.7, 0.2, 60.0)
    result = run_maneuvers(subject, [TurningCircle(35.0)], conditions)[0]
    alone = [simulate_maneuvers(m, [TurningCircle(35.0)], conditions)[0].indices.tactical_diameter_m for m in members]
    row = indices_table([result], 7.0, 1.17248, None).iloc[0]
    assert row["n_members"] == 2
    assert row["tactical_diameter_m_std"] == pytest.approx(abs(alone[0] - alone[1]) / math.sqrt(2), rel=1e-12)
    assert min(alone) < result.indices.tactical_diameter_m < max(alone)  # the mean-force model lies between


@pytest.mark.parametrize("gated", [False, True])
def test_rows_under_their_own_conditions_equal_each_maneuver_run_alone(gated):
    """`simulate_rows`: zig-zags and a turn of different approach speed, revolutions,
    rudder rate, wind and duration as rows of one rollout, each as `simulate_maneuvers`
    runs it alone (the kNN gate deciding row by row when `gated`)."""
    ship = load_ship("kvlcc2_l7")
    bank = torch.zeros(400, 6, dtype=torch.float64)
    bank[:, 1] = torch.linspace(1.0, 1.3, 400)
    model = _hybrid_without_correction(ship, bank) if gated else MMG(ship)
    maneuvers = [ZigZag(20.0, 20.0, "starboard"), ZigZag(10.0, 10.0, "port"), TurningCircle(35.0, "port")]
    conditions = [Conditions(1.17, 11.8, 15.7, 0.2, 50.0, 0.0, 0.0),
                  Conditions(1.05, 10.9, 9.0, 0.2, 34.0, 0.8, 2.0),
                  Conditions(1.25, 12.5, 20.0, 0.2, 20.0, 0.3, 5.5)]
    rows = simulate_rows(model, maneuvers, conditions)
    for maneuver, condition, row in zip(maneuvers, conditions, rows):
        alone = simulate_maneuvers(model, [maneuver], condition)[0]
        assert row.states.shape == alone.states.shape == (condition.steps + 1, 6)
        np.testing.assert_allclose(row.states, alone.states, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(row.inputs, alone.inputs, rtol=1e-13, atol=1e-13)
        assert row.gate_off_share == alone.gate_off_share and (row.gate_off_share is not None) == gated
        for k, v in alone.indices.as_dict().items():
            assert row.indices.as_dict()[k] == pytest.approx(v, rel=1e-12, nan_ok=True), k
    assert rows[1].indices.first_overshoot_deg > 0  # the port zig-zag reversed within its 34 s
    with pytest.raises(ManeuverError, match="one time step"):
        simulate_rows(model, maneuvers[:2], [conditions[0], Conditions(1.05, 10.9, 9.0, 0.1, 34.0)])


def test_crash_stop_needs_astern_thrust():
    ship = load_ship("kvlcc2_l7")
    with pytest.raises(ManeuverError, match="ahead motion only"):
        simulate_maneuvers(MMG(ship), [CrashStop()], Conditions(1.17, 11.8, 15.7, 0.2, 10.0))


@pytest.mark.slow
def test_compiled_loop_equals_the_eager_one(tmp_path, monkeypatch):
    """One compile of the maneuver loop (about a minute), then every maneuver, dt and
    duration through it: the same states as the eager loop to round-off."""
    monkeypatch.setenv("SYSID_COMPILE", "1")
    monkeypatch.setenv("SYSID_CACHE", str(tmp_path))
    ship = load_ship("esso_osaka")
    maneuvers = [TurningCircle(35.0), ZigZag(20.0, 20.0, "port"), CrashStop(reversal_s=5.0)]
    conditions = Conditions(0.35, 8.85, 24.1, 0.1, 70.0)  # 700 steps: two calls of the loop
    eager = simulate_maneuvers(MMG(ship), maneuvers, conditions)
    compiled = simulate_maneuvers(MMG(ship), maneuvers, conditions, compiled=True)
    assert len(list(tmp_path.glob("maneuver-rk4-*.pt2"))) == 1
    for a, b in zip(eager, compiled):
        np.testing.assert_allclose(b.states, a.states, rtol=0, atol=1e-10)
        np.testing.assert_allclose(b.inputs, a.inputs, rtol=0, atol=1e-12)
    other = simulate_maneuvers(MMG(ship), maneuvers[:1], Conditions(0.35, 8.85, 24.1, 0.25, 30.0), compiled=True)
    assert other[0].states.shape == (121, 6) and len(list(tmp_path.glob("*.pt2"))) == 1  # no second compile


def test_the_loop_is_chosen_from_the_step_count_and_the_cache_alone(tmp_path, monkeypatch):
    """`choose_loop` reads no clock and no load (both made to fail here): the same steps and
    cache give the same loop, whatever the cache recorded a compile to cost. Cold cache:
    eager below `MANEUVER_REPAY_STEPS` eager steps per loop to compile, compiled from it on;
    a model whose loop is in the cache (its package on disk) counts warm: every model warm,
    compiled at any step count. Forced by compiled=True/False; eager with compilation off."""
    import os
    import time
    from sysid.fast.payoff import MANEUVER_REPAY_STEPS
    from sysid.fast.compiled import package_path, record_seconds
    from sysid.maneuvers import closed_loop
    from sysid.maneuvers.simulate import choose_loop
    monkeypatch.setenv("SYSID_CACHE", str(tmp_path))
    monkeypatch.setenv("SYSID_COMPILE", "1")
    monkeypatch.setattr(closed_loop, "_compiled", {})  # loops compiled by earlier tests of this process

    def no_clock(*args):
        raise AssertionError("the loop choice read a clock or the load")
    monkeypatch.setattr(time, "perf_counter", no_clock)
    monkeypatch.setattr(os, "getloadavg", no_clock)
    esso, kvlcc2 = MMG(load_ship("esso_osaka")), MMG(load_ship("kvlcc2_l7"))
    maneuvers = [TurningCircle(35.0), ZigZag(20.0, 20.0)]
    dt = 0.1

    def conditions(steps):
        return Conditions(0.35, 8.85, 24.1, dt, steps * dt)

    below, at = conditions(MANEUVER_REPAY_STEPS - 1), conditions(MANEUVER_REPAY_STEPS)
    assert (below.steps, at.steps) == (MANEUVER_REPAY_STEPS - 1, MANEUVER_REPAY_STEPS)
    for recorded in (3600.0, 0.0):  # what the cache says a compile cost does not decide
        for _ in range(5):
            record_seconds("maneuver-rk4", "compile", recorded)
        first = choose_loop([esso], maneuvers, below)
        assert not first.compiled and f"{MANEUVER_REPAY_STEPS - 1} steps" in first.reason
        assert choose_loop([esso], maneuvers, below) == first  # same inputs, same path and words
        assert choose_loop([esso], maneuvers, at).compiled
    assert f"took {0:.0f} s here" in first.reason  # the recorded cost is quoted, not used
    assert not choose_loop([esso, kvlcc2], maneuvers, conditions(MANEUVER_REPAY_STEPS - 1)).compiled
    assert choose_loop([esso, kvlcc2], maneuvers, conditions(MANEUVER_REPAY_STEPS)).compiled  # 2 x steps, 2 loops
    short = conditions(30)
    assert not choose_loop([esso], maneuvers, short).compiled
    package_path(*closed_loop._loop_module(esso, Method.RK4, torch.float64)).touch()  # esso's loop: warm
    warm = choose_loop([esso], maneuvers, short)
    assert warm.compiled and "in the cache" in warm.reason
    assert not choose_loop([esso, kvlcc2], maneuvers, short).compiled  # kvlcc2's loop is still cold
    half = conditions(MANEUVER_REPAY_STEPS // 2)  # 2 models x half = the steps that repay one cold loop
    assert choose_loop([esso, kvlcc2], maneuvers, half).compiled
    assert not choose_loop([esso], maneuvers, short, False).compiled
    assert choose_loop([kvlcc2], maneuvers, short, True).compiled
    monkeypatch.setenv("SYSID_COMPILE", "0")
    off = choose_loop([esso], maneuvers, at)
    assert not off.compiled and "compilation is off" in off.reason


def test_the_eager_loop_gives_the_gate_decision_of_each_step_start():
    """The gate's decision recorded at each step's start (from the rule's first stage)
    equals the model's own `gate_decision` at the recorded states and held inputs."""
    from sysid.maneuvers.closed_loop import run_eager
    from sysid.maneuvers.controllers import initial_orders, order_parameters
    ship = load_ship("esso_osaka")
    torch.manual_seed(0)
    net = ForceCorrection([16], torch.float64)
    mmg = MMG(ship)
    states = torch.zeros(400, 6, dtype=torch.float64)
    states[:, 1] = 0.35 + 0.02 * torch.randn(400, dtype=torch.float64)
    states[:, 3] = 0.01 * torch.randn(400, dtype=torch.float64)
    states[:, 5] = 0.005 * torch.randn(400, dtype=torch.float64)
    inputs = torch.zeros(400, 4, dtype=torch.float64)
    inputs[:, 0] = 8.85
    inputs[:, 1] = 0.1 * torch.randn(400, dtype=torch.float64)
    wind = torch.stack(relative_wind(states[:, 1], states[:, 3], states[:, 4], inputs[:, 2], inputs[:, 3]), -1)
    gate = KNNGate(k=5, features=9, dtype=torch.float64).fit(correction_inputs(states, inputs, wind))
    hybrid = CorrectedModel(mmg, net, gate, gate_space="inputs")
    maneuvers = [TurningCircle(35.0), ZigZag(10.0, 10.0, "port")]
    conditions = Conditions(0.35, 8.85, 24.1, 0.5, 60.0)
    x0 = torch.zeros(2, 6, dtype=torch.float64)
    x0[:, 1] = 0.35
    record = run_eager(hybrid, x0, initial_orders(maneuvers), order_parameters(maneuvers, conditions),
                       conditions.steps, conditions.dt, conditions.method)
    starts = torch.cat((x0[None], record[:-1, :, :6]))
    with torch.no_grad():
        expected = hybrid.gate_decision(starts, record[..., 8:12])
    assert 0 < int(expected.sum()) < expected.numel()  # the run leaves the bank: both decisions occur
    assert torch.equal(record[..., 12] > 0.5, expected)


def test_a_maneuver_that_blows_up_is_named_with_its_time_and_a_normal_one_is_not():
    """N_r > 0 destabilises yaw: the turn spins up until the speed passes 3 U0 and the state
    goes non-finite. Without a training range the rule is non-finite or speed > 3 U0; the
    time is the first step at which the simulated speed passes 3 U0 (read off the states)."""
    conditions = Conditions(1.17248, 11.8, 15.7, 0.2, 100.0)
    turn = [TurningCircle(35.0), ZigZag(10.0, 10.0)]
    normal = simulate_maneuvers(MMG(load_ship("kvlcc2_l7")), turn, conditions)
    unstable = simulate_maneuvers(MMG(load_ship("kvlcc2_l7", {"N_r": 0.3})), turn, conditions)
    assert not any(r.diverged for r in normal)
    for r in unstable:
        speed = np.hypot(r.states[:, 1], r.states[:, 3])
        first = int(np.argmax(~(speed <= 3 * 1.17248)))   # NaN counts as beyond
        assert np.isfinite(r.states[:first]).all() and first > 0
        assert r.diverged_at_s == pytest.approx(r.t[first], abs=1e-12) and r.diverged_at_s < 100.0
        assert "speed" in r.divergence or "non-finite" in r.divergence
    table = indices_table(normal + unstable, 7.0, 1.17248, None)
    assert table["diverged"].tolist() == [False, False, True, True]
    assert np.isnan(table["diverged_at_s"][:2]).all()
    assert table["diverged_at_s"][2:].tolist() == [r.diverged_at_s for r in unstable]
    imo = [c for c in table.columns if c.startswith("imo_")]
    assert (table.loc[2:, imo].fillna("not assessed") == "not assessed").all().all()  # no verdict on a blown-up run


def test_a_maneuver_beyond_the_training_range_of_r_diverged():
    """With a training range, |r| beyond factor x the training logs' largest |r| diverged: a
    normal 35-deg turn against a range of straight running (|r| <= 0.01 rad/s, 3 x: 0.03)."""
    from sysid.evaluation.divergence import PhysicalRange
    conditions = Conditions(1.17248, 11.8, 15.7, 0.2, 60.0)
    limits = PhysicalRange(1.2, 0.01)
    r = simulate_maneuvers(MMG(load_ship("kvlcc2_l7")), [TurningCircle(35.0)], conditions, limits=limits)[0]
    first = int(np.argmax(np.abs(r.states[:, 5]) > 0.03))
    assert first > 0 and r.diverged_at_s == pytest.approx(r.t[first], abs=1e-12)
    assert r.divergence.startswith("|r|")
    wide = simulate_maneuvers(MMG(load_ship("kvlcc2_l7")), [TurningCircle(35.0)], conditions,
                              limits=PhysicalRange(1.2, 0.05))[0]
    assert not wide.diverged   # its largest |r| is 0.077 rad/s < 3 x 0.05


def test_choosing_the_loop_loads_no_compiler(tmp_path):
    """`choose_loop` with a cold cache reads the cache's fingerprint without importing
    `torch._inductor` (seconds at start-up, which an eager run would pay for nothing)."""
    import os
    import subprocess
    import sys
    code = ("import sys; from sysid import MMG, load_ship; from sysid.maneuvers import Conditions, TurningCircle; "
            "from sysid.maneuvers.simulate import choose_loop; "
            "c = choose_loop([MMG(load_ship('esso_osaka'))], [TurningCircle(35.0)], Conditions(0.35, 8.85, 24.1)); "
            "print(c.compiled, 'torch._inductor' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "SYSID_CACHE": str(tmp_path), "SYSID_COMPILE": "1"})
    assert done.returncode == 0, done.stderr[-1000:]
    assert done.stdout.split() == ["False", "False"]  # 6000 steps, cold: eager; no compiler loaded


def test_the_held_orders_are_the_controllers_own_to_the_bit():
    """`ManeuverOrders.held` (what the eager loop takes once per run) gives the bits of
    `ManeuverOrders.forward` step after step: a zig-zag that reverses, a turning circle and
    a crash stop ramping its revolutions, along a swinging heading."""
    from sysid.maneuvers.controllers import ManeuverOrders, initial_orders, order_parameters
    maneuvers = [ZigZag(10.0, 10.0, "port"), TurningCircle(35.0), CrashStop(reversal_s=3.0)]
    conditions = Conditions(0.35, 8.85, 24.1, 0.1, 10.0)
    parameters, dt = order_parameters(maneuvers, conditions), torch.tensor(0.1, dtype=torch.float64)
    controller, held = ManeuverOrders(), ManeuverOrders.held(parameters, dt)
    ahead_only = ManeuverOrders.held(parameters[:2], dt)  # no ramp: the revolutions taken once
    state = torch.zeros(3, 6, dtype=torch.float64)
    orders = initial_orders(maneuvers)
    reversed_once = False
    for k in range(80):
        state[:, 4] = 0.4 * math.sin(0.1 * k)  # [rad] heading swinging past the check angles
        t = dt * k
        expected = controller(state, orders, parameters, t, dt)
        got = held(state, orders, t)
        assert all(torch.equal(a, b) for a, b in zip(got, expected))
        assert all(torch.equal(a, b[:2]) for a, b in zip(ahead_only(state[:2], orders[:2], t), expected))
        reversed_once |= bool(expected[1][0, 1] != orders[0, 1])
        orders = expected[1]
    assert reversed_once and float(expected[0][2, 0]) == pytest.approx(-conditions.rps)  # reversed; astern reached


def _features_hybrid(seed: int = 2) -> CorrectedModel:
    """An Esso Osaka hybrid with a 9-32-32-3 FNN (initialised from `seed`) and its kNN gate
    in the 32 features (more than `BOX_DIMENSIONS`: principal boxes), fitted on straight
    running and gentle turns."""
    torch.manual_seed(seed)
    mmg = MMG(load_ship("esso_osaka"))
    net = ForceCorrection((32, 32), torch.float64)
    net.set_standardization(torch.tensor([0.3, 0.0, 0.0, 0.0, 8.8, 0.0, 0.0, 0.0, 0.0]),
                            torch.tensor([0.1, 0.02, 0.01, 0.3, 1.0, 1.0, 1.0, 0.7, 0.7]),
                            torch.zeros(3), torch.tensor([2.0, 2.0, 10.0]))
    states = torch.zeros(2000, 6, dtype=torch.float64)
    states[:, 1] = 0.35 + 0.03 * torch.randn(2000, dtype=torch.float64)
    states[:, 3] = 0.01 * torch.randn(2000, dtype=torch.float64)
    states[:, 4] = 2 * math.pi * torch.rand(2000, dtype=torch.float64)
    states[:, 5] = 0.01 * torch.randn(2000, dtype=torch.float64)
    inputs = torch.zeros(2000, 4, dtype=torch.float64)
    inputs[:, 0] = 8.85
    inputs[:, 1] = 0.3 * torch.randn(2000, dtype=torch.float64)
    wind = torch.stack(relative_wind(states[:, 1], states[:, 3], states[:, 4], inputs[:, 2], inputs[:, 3]), -1)
    with torch.no_grad():
        features = net.features(correction_inputs(states, inputs, wind))
    return CorrectedModel(mmg, net, KNNGate(k=5, alpha=0.99, features=32, dtype=torch.float64).fit(features))


@pytest.mark.parametrize("kind", ["hybrid", "mmg", "ensemble"])
def test_the_eager_loop_equals_the_torch_step_with_the_whole_bank_scan(kind):
    """The eager loop (native MMG kernel, anchored kNN gate, FNN and orders looked up once)
    against the step it replaced, run here: the model's own torch MMG, the gate's
    whole-bank scan and `ManeuverOrders.forward` at every step. The same gate decision at
    every step start and the same states to round-off (the native kernel and F_NN added
    through the mass terms reorder the sums; the gate and the FNN give the same bits). An
    ensemble of hybrids of one MMG: the mean of its members' native rates against its
    `forward` (F_MMG once, the members' gated F_NN averaged, the majority's gate)."""
    from sysid.device import compute_threads
    from sysid.dynamics.integrators import step_loop
    from sysid.maneuvers.closed_loop import ClosedLoopStep, run_eager
    from sysid.maneuvers.controllers import initial_orders, order_parameters
    from sysid.mmg import native
    model = {"hybrid": _features_hybrid, "mmg": lambda: MMG(load_ship("esso_osaka")),
             "ensemble": lambda: SeedEnsemble([_features_hybrid(seed) for seed in (2, 3, 4)])}[kind]()
    maneuvers = [TurningCircle(35.0), ZigZag(20.0, 20.0, "port")]
    conditions = Conditions(0.35, 8.85, 24.1, 0.2, 60.0)
    x0 = torch.zeros(2, 6, dtype=torch.float64)
    x0[:, 1] = 0.35
    orders, parameters = initial_orders(maneuvers), order_parameters(maneuvers, conditions)
    assert model.no_grad_rate(x0) is not None  # the native kernel computes this MMG
    record = run_eager(model, x0, orders, parameters, conditions.steps, conditions.dt, conditions.method)
    step, dt = ClosedLoopStep(model, conditions.method), torch.tensor(conditions.dt, dtype=torch.float64)

    def advance(k, carry):
        x, o, u, g = step(carry[0], carry[1], parameters, dt * k, dt)
        return torch.cat((x, o, u, g), -1), (x, o)
    with native.torch_path(), torch.no_grad(), compute_threads(1):
        expected = torch.stack(step_loop(advance, (x0, orders), conditions.steps))
    if kind != "mmg":
        on = expected[..., 12]
        assert 0 < int(on.sum()) < on.numel()  # the turn leaves the bank: both decisions occur
    else:
        assert bool(torch.isnan(expected[..., 12]).all())
    torch.testing.assert_close(record[..., 12], expected[..., 12], rtol=0, atol=0, equal_nan=True)
    torch.testing.assert_close(record[..., 6:12], expected[..., 6:12], rtol=0, atol=1e-12)
    torch.testing.assert_close(record[..., :6], expected[..., :6], rtol=1e-10, atol=1e-12)


def test_the_terminal_names_the_largest_distance_of_indices_csv(capsys):
    """`sysid maneuver`'s line per maneuver gives indices.csv's knn_distance_max, the brute-force
    kNN's largest along the maneuver; a NaN row (a diverged step) is skipped, not printed as the
    largest (the terminal took Python's max of all rows but the last: NaN when the first was)."""
    from sysid.cli.maneuver_commands import _print_gate
    ship = load_ship("kvlcc2_l7")
    bank_states = torch.zeros(200, 6, dtype=torch.float64)
    bank_states[:, 1] = torch.linspace(1.1, 1.25, 200)
    hybrid = _hybrid_without_correction(ship, bank_states)
    conditions, _ = default_conditions(MMG(ship), ship, duration=20.0, dt=0.2)
    result = simulate_maneuvers(hybrid, [TurningCircle(35.0)], conditions)[0]
    brute = _brute_force_distances(hybrid, result)
    result.knn_distance[0] = math.nan   # as a diverged step's
    largest = float(np.max(brute[1:]))
    row = indices_table([result], float(ship["L_pp"]), 1.17248, None).iloc[0]
    assert row["knn_distance_max"] == pytest.approx(largest, rel=1e-9)
    _print_gate([result], hybrid)
    assert f"largest d_kNN {largest:.4g}" in capsys.readouterr().out
