"""Processed runs written by tests: the dataset's columns from simulated states and inputs."""
import pandas as pd
import torch

from sysid.data.recordings import COLUMNS
from sysid.mmg.wind import relative_wind


def write_processed_csv(path, t, states, inputs):
    """A processed run (the dataset's columns) from t (N,) [s], states (N, 6) and inputs
    (N, 4); the relative wind computed from them. Returns `path`."""
    rel = torch.stack(relative_wind(*(torch.tensor(c) for c in (states[:, 1], states[:, 3], states[:, 4],
                                                                 inputs[:, 2], inputs[:, 3]))), -1).numpy()
    values = {"t": t, "x": states[:, 0], "u": states[:, 1], "y": states[:, 2], "v": states[:, 3],
              "psi": states[:, 4], "r": states[:, 5], "n_prop": inputs[:, 0], "delta_rudder": inputs[:, 1],
              "wind_velo_relative": rel[:, 0], "wind_dir_relative": rel[:, 1],
              "wind_velo_true": inputs[:, 2], "wind_dir_true": inputs[:, 3]}
    pd.DataFrame({column: values[short] for column, short in COLUMNS.items()}).to_csv(path, index=False)
    return path
