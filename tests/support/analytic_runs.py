"""A small analytic processed run (no dataset needed): 120 s at 10 Hz, ahead at ~0.5 m/s with a
gentle sinusoidal yaw, wind 2 m/s."""
import numpy as np
import pandas as pd

from preprocessing import synth


def analytic_run(seconds: float = 120.0) -> pd.DataFrame:
    t = np.round(np.arange(0.0, seconds + 1e-9, 0.1), 6)
    w = 2 * np.pi / 40.0
    run = pd.DataFrame({c: np.zeros_like(t) for c in synth.schema.PROCESSED})
    run["t"] = t
    run["u_velo"] = 0.5 + 0.05 * np.sin(w * t)
    run["vm_velo"] = 0.02 * np.sin(w * t)
    run["r_angvelo"] = 0.03 * np.sin(w * t)
    run["psi_hat"] = 0.3
    run["n_prop"] = 10.0
    run["delta_rudder"] = 0.1 * np.sin(w * t)
    run["wind_velo_true"] = 2.0 + 0.2 * np.sin(0.3 * t)
    run["wind_dir_true"] = 1.0 + 0.1 * np.sin(0.2 * t)
    return run
