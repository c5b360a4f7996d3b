"""Identification with known truth through raw logs: KVLCC2 maneuvers simulated at 10 Hz ->
raw 10 Hz logs with the synthesiser's noise (two GNSS antennas, FOG with drift,
anemometers; `preprocessing.synth`) -> the `sysid preprocess` pipeline -> processed 1 Hz
runs -> hull derivatives identified from 20-30 % perturbed starts -> sigma and coverage.

The maneuvers are those of benchmarks/identification_kvlcc2.py, integrated by RK4 with
dt = 0.1 s; the rudder moves only at whole seconds, so the identification model (RK4,
dt = 1 s, inputs held over each second) differs from the truth only by its step length.
Unlike the 1 Hz benchmark, the noise here has passed through the preprocessing's smoothing
(correlated in time) and the ship file's assumed sensor layout.

    python benchmarks/identification_kvlcc2_rawlogs.py [--seeds 10] [--window 10] [--names ...]
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import torch

from preprocessing import writer
from preprocessing.pipeline import Pipeline
from preprocessing.synth import SynthSettings, synthesise
from sysid import MMG, integrate, load_ship
from sysid.data import read_run, sliding_windows, stack_windows
from sysid.mmg.wind import relative_wind
from sysid.uncertainty import coefficient_uncertainty, velocity_weights

sys.path.insert(0, str(Path(__file__).resolve().parent))
import identification_kvlcc2 as onehz  # noqa: E402

SUBSTEPS = 10  # 10 Hz


def simulate_10hz(model, rudder_law, duration: int) -> pd.DataFrame:
    """A processed-schema run (bare names, 10 Hz) of the true ship under a 1 Hz rudder law."""
    state = torch.tensor([0.0, onehz.U0, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64)
    delta, rows, deltas = 0.0, [], []
    for k in range(duration):
        command = rudder_law(k, state, delta)
        delta += float(np.clip(command - delta, -onehz.RUDDER_RATE, onehz.RUDDER_RATE))
        inputs = torch.tensor([[onehz.NPS, delta, 0.0, 0.0]] * (SUBSTEPS + 1), dtype=torch.float64)
        with torch.no_grad():
            traj = integrate(model, state, inputs, 1.0 / SUBSTEPS, "rk4")
        rows.append(traj[:-1])
        deltas += [delta] * SUBSTEPS
        state = traj[-1]
    s = torch.cat(rows).numpy()
    t = np.arange(len(s)) / SUBSTEPS
    zeros = np.zeros(len(s))
    U_A, gamma_A = (a.numpy() for a in relative_wind(*(torch.tensor(c) for c in
                                                       (s[:, 1], s[:, 3], s[:, 4], zeros, zeros))))
    return pd.DataFrame({
        "t": t, "x_position_mid": s[:, 0], "u_velo": s[:, 1], "y_position_mid": s[:, 2],
        "vm_velo": s[:, 3], "psi_hat": s[:, 4], "r_angvelo": s[:, 5], "n_prop": onehz.NPS,
        "delta_rudder": deltas, "wind_velo_relative_mid": U_A, "wind_dir_relative_mid": gamma_A,
        "wind_velo_true": zeros, "wind_dir_true": zeros})


def maneuvers_10hz(ship) -> dict[str, pd.DataFrame]:
    model = MMG(ship)
    laws = {"turning35_stbd": (lambda k, s, d: math.radians(35), 120),
            "turning35_port": (lambda k, s, d: -math.radians(35), 120),
            "zigzag10": (onehz._zigzag(10), 160), "zigzag20": (onehz._zigzag(20), 160),
            "random": (onehz._random_rudder(7), 300)}
    return {name: simulate_10hz(model, law, duration) for name, (law, duration) in laws.items()}


def preprocessed_windows(ship, records: dict[str, pd.DataFrame], window: int, seed: int) -> SimpleNamespace:
    """Raw logs (seeded noise) -> preprocessing pipeline -> 1 Hz runs -> consecutive windows."""
    states, inputs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, run) in enumerate(records.items()):
            raw = synthesise(run, ship.sensors, SynthSettings(seed=1000 * seed + i)).raw
            result = Pipeline(ship.sensors).run(raw, name)
            for path in writer.write_run(tmp, name, result.segments, result.report):
                if path.suffix != ".csv":
                    continue
                processed = read_run(path)
                starts = sliding_windows(len(processed), window + 1, window)
                s, u = stack_windows(processed, starts, window + 1)
                states.append(s)
                inputs.append(u)
    return SimpleNamespace(states=torch.cat(states, 1), inputs=torch.cat(inputs, 1), dt=1.0)


def run_case(ship, records, names, seed: int, window: int) -> dict:
    windows = preprocessed_windows(ship, records, window, seed)
    weights = velocity_weights(windows.states)
    start = onehz.perturbed_start(ship, names, seed)
    estimate, iterations = onehz.identify(ship, windows, names, start, weights, method="rk4")
    fitted = MMG(ship)
    with torch.no_grad():
        for name, value in estimate.items():
            getattr(fitted.coefficients, name).fill_(value)
    out = {"truth": np.array([ship[n] for n in names]), "iterations": iterations,
           "windows": windows.states.shape[1]}
    for form in ("sandwich", "gauss_newton"):
        out[form] = coefficient_uncertainty(fitted, windows, names, weights, "rk4", covariance=form)
    out["estimate"] = out["sandwich"].estimate
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--window", type=int, default=10)
    parser.add_argument("--names", default="R_0,Y_v,Y_r,N_v,N_r,Y_vvv,N_vvr")
    args = parser.parse_args()
    torch.set_num_threads(1)
    names = [n.strip() for n in args.names.split(",") if n.strip()]
    ship = load_ship(onehz.SHIP)
    started = time.perf_counter()
    records = maneuvers_10hz(ship)
    print(f"simulated {sum(len(r) for r in records.values())} rows at 10 Hz in "
          f"{time.perf_counter() - started:.0f} s", flush=True)
    cases = []
    for seed in range(args.seeds):
        started = time.perf_counter()
        case = run_case(ship, records, names, seed, args.window)
        cases.append(case)
        z = np.abs(case["estimate"] - case["truth"]) / case["sandwich"].std_error
        print(f"seed {seed}: {case['windows']} windows, {case['iterations']} LM iterations, "
              f"max |estimate - truth| / sigma = {z.max():.2f}, {time.perf_counter() - started:.0f} s", flush=True)
    print()
    print(f"{len(cases)} noise seeds (raw logs -> preprocess), {args.window}-s windows, "
          f"starts perturbed by 20-30 %")
    print(onehz.coverage_table(cases, names))


if __name__ == "__main__":
    main()
