"""Identification with known truth: KVLCC2 L7 hull derivatives from simulated maneuvers.

The "ship" is the standard MMG model of configs/ships/kvlcc2_l7.toml. It performs a 35-deg
turn to each side, 10/10 and 20/20 zigzags and a random-rudder run (1 Hz inputs held over
each second, RK4 with dt = 1 s, so the identification model can be exactly right). White
noise is added to the recorded u, v_m, r (processed 1 Hz states; this benchmark does not go
through raw 10 Hz logs and `sysid preprocess`). The records are cut into non-overlapping
windows; the hull derivatives are identified from starts perturbed by 20-30 % (random sign)
by the package's Levenberg-Marquardt on the multi-step residuals (`sysid.identify.levenberg_marquardt`,
start states recorded), and each estimate gets its sigma from `coefficient_uncertainty`.
Over many noise seeds the script prints, per coefficient, the truth, the mean estimate,
the mean sigma, the spread of the estimates and how often truth lies inside +- 2 sigma
(both covariance forms).

    python benchmarks/identification_kvlcc2.py [--seeds 12] [--window 10] [--names Y_v,Y_r,...]

Results measured on this project's machine: benchmarks/identification_results.md.
"""
from __future__ import annotations

import argparse
import math
import time
from types import SimpleNamespace

import numpy as np
import torch

from sysid import MMG, integrate, load_ship
from sysid.identify.levenberg_marquardt import identify_levenberg_marquardt
from sysid.identify.uncertainty import coefficient_uncertainty

SHIP = "kvlcc2_l7"
U0, NPS = 2.29 * 0.512, 17.95        # m/s, rps: shipmmg's example operating point
RUDDER_RATE = math.radians(15.8)     # rad/s, model-scale steering rate
NOISE = (0.004, 0.003, 0.0008)       # std of recorded u [m/s], v_m [m/s], r [rad/s]
HULL = ("R_0", "X_vv", "X_vr", "X_rr", "X_vvvv", "Y_v", "Y_r", "Y_vvv", "Y_vvr", "Y_vrr", "Y_rrr",
        "N_v", "N_r", "N_vvv", "N_vvr", "N_vrr", "N_rrr")


def _step(model, state, inputs, method):
    """One step of 1 s with the inputs held: state (6,), inputs (4,) -> (6,)."""
    with torch.no_grad():
        return integrate(model, state, torch.stack([inputs, inputs]), 1.0, method)[1]


def _run(model, rudder_law, duration: int, method: str = "rk4") -> tuple[torch.Tensor, torch.Tensor]:
    """Closed-loop 1 Hz simulation: rudder_law(k, state, delta_now) -> commanded delta [rad].
    Returns states (T, 6) and inputs (T, 4) at t = 0, 1, ... duration-1 s."""
    state = torch.tensor([0.0, U0, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64)
    delta = 0.0
    states, inputs = [], []
    for k in range(duration):
        command = rudder_law(k, state, delta)
        delta += float(np.clip(command - delta, -RUDDER_RATE, RUDDER_RATE))
        row = torch.tensor([NPS, delta, 0.0, 0.0], dtype=torch.float64)
        states.append(state)
        inputs.append(row)
        state = _step(model, state, row, method)
    return torch.stack(states), torch.stack(inputs)


def _zigzag(angle_deg: float):
    angle = math.radians(angle_deg)
    side = {"sign": 1.0}

    def law(k, state, delta):
        psi = float(state[4])
        if side["sign"] > 0 and psi > angle:
            side["sign"] = -1.0
        elif side["sign"] < 0 and psi < -angle:
            side["sign"] = 1.0
        return side["sign"] * angle
    return law


def _random_rudder(seed: int):
    rng = np.random.default_rng(seed)
    plan = []
    while len(plan) < 1000:
        plan += [math.radians(rng.uniform(-30, 30))] * int(rng.integers(5, 15))
    return lambda k, state, delta: plan[k]


def maneuvers(ship, durations: dict[str, int] | None = None,
              method: str = "rk4") -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
    """Noise-free records of the true ship: name -> (states (T, 6), inputs (T, 4)) at 1 Hz,
    integrated by `method` with dt = 1 s."""
    durations = durations or {"turning35_stbd": 120, "turning35_port": 120, "zigzag10": 160,
                              "zigzag20": 160, "random": 300}
    model = MMG(ship)
    laws = {"turning35_stbd": lambda k, s, d: math.radians(35), "turning35_port": lambda k, s, d: -math.radians(35),
            "zigzag10": _zigzag(10), "zigzag20": _zigzag(20), "random": _random_rudder(7)}
    return {name: _run(model, laws[name], durations[name], method) for name in durations}


def windows_from(records, window: int, noise=NOISE, seed: int = 0) -> SimpleNamespace:
    """Consecutive windows of `window` steps (sharing only their boundary sample) from noisy
    copies of the records:
    states (window+1, W, 6), inputs (window+1, W, 4), dt = 1 s."""
    g = torch.Generator().manual_seed(seed)
    states, inputs = [], []
    for clean, controls in records.values():
        noisy = clean.clone()
        noisy[:, [1, 3, 5]] += torch.tensor(noise) * torch.randn(len(clean), 3, generator=g, dtype=torch.float64)
        for start in range(0, len(clean) - window, window):
            states.append(noisy[start:start + window + 1])
            inputs.append(controls[start:start + window + 1])
    return SimpleNamespace(states=torch.stack(states, 1), inputs=torch.stack(inputs, 1), dt=1.0)


def identify(ship, windows, names, start: dict[str, float], weights, iterations: int = 40,
             method: str = "rk4") -> tuple[dict[str, float], int]:
    """Levenberg-Marquardt on the multi-step residuals from `start`, every window integrated
    from its recorded first sample (`sysid.identify.levenberg_marquardt`, ``start_states="recorded"``);
    returns the estimate and the number of iterations taken."""
    fit = identify_levenberg_marquardt(MMG(ship.with_overrides(start, "start")), windows, names, weights, method,
                                       start_states="recorded", iterations=iterations)
    return fit.coefficients, fit.iterations


def perturbed_start(ship, names, seed: int) -> dict[str, float]:
    """Each truth value scaled by 1 +- U(0.2, 0.3), random sign."""
    rng = np.random.default_rng(1000 + seed)
    return {n: ship[n] * (1 + rng.choice([-1, 1]) * rng.uniform(0.2, 0.3)) for n in names}


def run_case(names, seed: int, window: int = 20, records=None, noise=NOISE, method: str = "rk4") -> dict:
    """One noise seed: identify `names` from a perturbed start, with both sigma forms."""
    ship = load_ship(SHIP)
    records = records if records is not None else maneuvers(ship, method=method)
    windows = windows_from(records, window, noise, seed)
    weights = torch.tensor(noise, dtype=torch.float64) ** -2
    start = perturbed_start(ship, names, seed)
    estimate, iterations = identify(ship, windows, names, start, weights, method=method)
    fitted = MMG(ship)
    fitted.coefficients.assign(estimate)  # it may leave the ship file's ranges where data say little
    out = {"truth": np.array([ship[n] for n in names]), "start": np.array([start[n] for n in names]),
           "iterations": iterations, "windows": windows.states.shape[1]}
    for form in ("sandwich", "gauss_newton"):
        res = coefficient_uncertainty(fitted, windows, names, weights, method, covariance=form)
        out[form] = res
    out["estimate"] = out["sandwich"].estimate
    return out


def coverage_table(cases, names) -> str:
    """Markdown: truth, mean estimate, spread of the estimates, median sigma and +-2 sigma
    coverage (both forms; runs with an infinite sigma, a singular direction, are left out of
    the coverage and counted apart), and in how many runs the coefficient was flagged."""
    truth = cases[0]["truth"]
    est = np.array([c["estimate"] for c in cases])
    rows = ["| coefficient | truth | mean estimate | sd of estimates | median σ sandwich | cover ±2σ sandwich "
            "| median σ Gauss-Newton | cover ±2σ Gauss-Newton | flagged undetermined (runs) |",
            "|---|---|---|---|---|---|---|---|---|"]
    for i, name in enumerate(names):
        cells = [name, f"{truth[i]:.4g}", f"{est[:, i].mean():.4g}", f"{est[:, i].std(ddof=1):.2g}"]
        for form in ("sandwich", "gauss_newton"):
            sig = np.array([c[form].std_error[i] for c in cases])
            finite = np.isfinite(sig)
            inside = np.abs(est[finite, i] - truth[i]) <= 2 * sig[finite]
            cover = f"{inside.mean():.0%}" if finite.any() else "-"
            if not finite.all():
                cover += f" ({(~finite).sum()} singular)"
            cells += [f"{np.median(sig):.2g}", cover]
        cells.append(str(sum(bool(c["sandwich"].undetermined[i]) for c in cases)))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=12)
    parser.add_argument("--window", type=int, default=10, help="window length [steps of 1 s]")
    parser.add_argument("--names", default=",".join(HULL), help="comma-separated coefficients to identify")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    names = [n.strip() for n in args.names.split(",") if n.strip()]
    ship = load_ship(SHIP)
    records = maneuvers(ship)
    cases = []
    for seed in range(args.seeds):
        started = time.perf_counter()
        case = run_case(names, seed, args.window, records)
        cases.append(case)
        determined = ~case["sandwich"].undetermined
        z = np.abs(case["estimate"] - case["truth"]) / case["sandwich"].std_error
        worst = np.max(z[determined]) if determined.any() else float("nan")
        print(f"seed {seed}: {case['iterations']} LM iterations, {case['windows']} windows, "
              f"max |estimate - truth| / sigma over determined coefficients = {worst:.2f}, "
              f"{time.perf_counter() - started:.0f} s", flush=True)
    print()
    print(f"{len(cases)} noise seeds, noise std u {NOISE[0]} m/s, v {NOISE[1]} m/s, r {NOISE[2]} rad/s, "
          f"{args.window}-s windows, starts perturbed by 20-30 %")
    print(coverage_table(cases, names))
    print()
    print("correlations (seed 0, sandwich):")
    corr = cases[0]["sandwich"].correlation
    print("        " + " ".join(f"{n:>7}" for n in names))
    for i, n in enumerate(names):
        print(f"{n:>7} " + " ".join(f"{corr[i, j]:7.2f}" for j in range(len(names))))
    print("weak directions (seed 0):", cases[0]["sandwich"].weak_directions)


if __name__ == "__main__":
    main()
