"""Identification with known truth through raw logs: KVLCC2 maneuvers simulated at 10 Hz ->
raw 10 Hz logs with the synthesiser's noise (two GNSS antennas, FOG with drift,
anemometers; `preprocessing.synth`) -> the `sysid preprocess` pipeline -> processed 1 Hz
runs -> hull derivatives identified from 20-30 % perturbed starts -> sigma and coverage.

The maneuvers are those of benchmarks/identification_kvlcc2.py, integrated by RK4 with
dt = 0.1 s; the rudder moves only at whole seconds, so the identification model (RK4,
dt = 1 s, inputs held over each second) differs from the truth only by its step length.
Unlike the 1 Hz benchmark, the noise here has passed through the preprocessing's smoothing
(correlated in time) and the ship file's assumed sensor layout.

``--bias replay`` (default) then subtracts the processing's deterministic bias, measured by
replaying the identified model under the logged 10 Hz inputs through noise-free raw logs and
the same pipeline and identifying again (`sysid.identify.pipeline_replay`); ``--bias none`` keeps the
estimate as identified.

``--start estimated`` (default) fits each window's start state (u, v_m, r) along with the
coefficients, the recorded first sample being one more measurement of it
(`sysid.identify.levenberg_marquardt`); ``--start recorded`` integrates every window from its recorded first
sample as if it were exact (the multi-step loss of training; biased here, see
benchmarks/identification_results.md).

    python benchmarks/identification_kvlcc2_rawlogs.py [--seeds 10] [--window 10] [--names ...]
        [--start estimated|recorded] [--bias replay|none]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import torch

from preprocessing.synth import SynthSettings
from sysid import MMG, integrate, load_ship
from sysid.mmg.wind import relative_wind
from sysid.identify.pipeline_replay import noise_free, processed_windows, processing_bias
from sysid.identify.levenberg_marquardt import fit_uncertainty, identify_levenberg_marquardt
from sysid.identify.uncertainty import velocity_weights

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
    return processed_windows(records, ship.sensors, window, lambda i: SynthSettings(seed=1000 * seed + i))


def _model(ship, values: dict[str, float]) -> MMG:
    """The ship's MMG model with `values` set (they may leave the ship file's ranges)."""
    model = MMG(ship)
    model.coefficients.assign(values)
    return model


def run_case(ship, records, names, seed: int, window: int, start_states: str = "estimated",
             bias: str = "replay") -> dict:
    """One noise seed: identify `names` from a perturbed start; sigma in both forms.
    start_states: "estimated" (fitted per window) or "recorded" (the first samples, exact);
    bias: "replay" (subtract the processing bias measured by `processing_bias`) or "none"."""
    windows = preprocessed_windows(ship, records, window, seed)
    weights = velocity_weights(windows.states)
    start = onehz.perturbed_start(ship, names, seed)

    def identify(w, values):
        return identify_levenberg_marquardt(_model(ship, values), w, names, weights, "rk4", start_states)

    fit = identify(windows, start)
    fitted = _model(ship, fit.coefficients)
    out = {"truth": np.array([ship[n] for n in names]), "iterations": fit.iterations,
           "windows": windows.states.shape[1]}
    for form in ("sandwich", "gauss_newton"):
        out[form] = fit_uncertainty(fitted, windows, names, fit, weights, "rk4", covariance=form)
    out["identified"] = out["sandwich"].estimate
    out["bias"] = np.zeros(len(names))
    if bias == "replay":
        found, _ = processing_bias(fitted, lambda w: identify(w, fit.coefficients).coefficients, records,
                                   windows.first, ship.sensors, window, [noise_free])
        out["bias"] = np.array([found[n] for n in names])
    out["estimate"] = out["identified"] - out["bias"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--window", type=int, default=10)
    parser.add_argument("--names", default="R_0,Y_v,Y_r,N_v,N_r,Y_vvv,N_vvr")
    parser.add_argument("--start", choices=("estimated", "recorded"), default="estimated",
                        help="each window's start state: fitted, or the recorded first sample")
    parser.add_argument("--bias", choices=("replay", "none"), default="replay",
                        help="subtract the processing bias measured by a noise-free replay, or not")
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
        case = run_case(ship, records, names, seed, args.window, args.start, args.bias)
        cases.append(case)
        z = np.abs(case["estimate"] - case["truth"]) / case["sandwich"].std_error
        print(f"seed {seed}: {case['windows']} windows, {case['iterations']} LM iterations, "
              f"max |estimate - truth| / sigma = {z.max():.2f}, {time.perf_counter() - started:.0f} s", flush=True)
    print()
    print(f"{len(cases)} noise seeds (raw logs -> preprocess), {args.window}-s windows, "
          f"start states {args.start}, processing bias {args.bias}, starts perturbed by 20-30 %")
    bias = np.mean([c["bias"] / c["identified"] for c in cases], 0)
    if args.bias == "replay":
        print("processing bias subtracted (mean over seeds, % of the identified value): "
              + ", ".join(f"{n} {100 * b:+.2f}" for n, b in zip(names, bias)))
    print(onehz.coverage_table(cases, names))


if __name__ == "__main__":
    main()
