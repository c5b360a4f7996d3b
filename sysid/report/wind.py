"""Relative wind seen by the recorded state, for the "measured" line of Figs. 6 and 8."""
from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from sysid.mmg.wind import relative_wind


def measured_relative_wind(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """(U_A [m/s], gamma_A [rad]) from the trace's observed u, v_m, psi and true wind."""
    cols = ["obs_u", "obs_v", "obs_psi", "wind_velo_true", "wind_dir_true"]
    values = torch.as_tensor(frame[cols].to_numpy(dtype=float))
    wind = relative_wind(*values.unbind(-1))
    return wind.U_A.numpy(), wind.gamma_A.numpy()
