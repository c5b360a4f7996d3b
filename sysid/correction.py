"""The FNN force correction F_NN (paper section 3.4, Eqs. 6-11).

Input s = (u, v_m, r, delta, n_p, omega_u, omega_v, cos psi, sin psi), omega = relative
wind as body-frame components (Eq. 7), standardised with training statistics (Eq. 8);
a 9-64-64-3 tanh network (Table 6); output de-standardised to N, N, N m (Eq. 10).
"""
from __future__ import annotations

from typing import Sequence

import torch
from torch import nn

INPUT_NAMES = ("u", "v_m", "r", "delta", "n_p", "omega_u", "omega_v", "cos_psi", "sin_psi")
OUTPUT_NAMES = ("X_NN", "Y_NN", "N_NN")


def correction_inputs(state: torch.Tensor, inputs: torch.Tensor, relative_wind: torch.Tensor) -> torch.Tensor:
    """s (..., 9) from state (..., 6), inputs (..., 4) and relative wind (..., 2) = (U_A, gamma_A)."""
    psi = state[..., 4]
    U_A, gamma_A = relative_wind[..., 0], relative_wind[..., 1]
    return torch.stack((state[..., 1], state[..., 3], state[..., 5], inputs[..., 1], inputs[..., 0],
                        U_A * torch.cos(gamma_A), U_A * torch.sin(gamma_A),
                        torch.cos(psi), torch.sin(psi)), -1)


class ForceCorrection(nn.Module):
    """F_NN = sigma_F * f_NN((s - mu_s) / sigma_s) + mu_F.

    Parameters
    ----------
    hidden : hidden layer widths (paper: 64, 64).
    dtype : parameter dtype.
    """

    def __init__(self, hidden: Sequence[int] = (64, 64), dtype: torch.dtype = torch.float32):
        super().__init__()
        widths = [len(INPUT_NAMES), *hidden]
        self.hidden = nn.ModuleList(nn.Linear(a, b, dtype=dtype) for a, b in zip(widths[:-1], widths[1:]))
        self.output = nn.Linear(widths[-1], len(OUTPUT_NAMES), dtype=dtype)
        self.register_buffer("input_mean", torch.zeros(len(INPUT_NAMES), dtype=dtype))
        self.register_buffer("input_std", torch.ones(len(INPUT_NAMES), dtype=dtype))
        self.register_buffer("output_mean", torch.zeros(len(OUTPUT_NAMES), dtype=dtype))
        self.register_buffer("output_std", torch.ones(len(OUTPUT_NAMES), dtype=dtype))

    def set_standardization(self, input_mean, input_std, output_mean, output_std) -> "ForceCorrection":
        """Training statistics of s and of the force residual (zero std is replaced by 1)."""
        for name, value in (("input_mean", input_mean), ("input_std", input_std),
                            ("output_mean", output_mean), ("output_std", output_std)):
            value = torch.as_tensor(value, dtype=self.input_mean.dtype)
            if name.endswith("std"):
                value = torch.where(value > 0, value, torch.ones_like(value))
            getattr(self, name).copy_(value)
        return self

    def features(self, s: torch.Tensor) -> torch.Tensor:
        """Activations before the output layer (..., 64): the kNN gate's feature space."""
        z = ((s.to(self.input_mean.dtype) - self.input_mean) / self.input_std)
        for layer in self.hidden:
            z = torch.tanh(layer(z))
        return z

    def force(self, z: torch.Tensor) -> torch.Tensor:
        """F_NN (..., 3) [N, N, N m] from features."""
        return self.output(z) * self.output_std + self.output_mean

    def forward(self, s: torch.Tensor) -> torch.Tensor:
        return self.force(self.features(s))
