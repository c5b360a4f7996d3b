"""The FNN force correction F_NN (paper section 3.4, Eqs. 6-11).

Input s = (u, v_m, r, delta, n_p, omega_u, omega_v, cos psi, sin psi), omega = relative
wind as body-frame components (Eq. 7), standardised with training statistics (Eq. 8);
a 9-64-64-3 tanh network (Table 6); output de-standardised to N, N, N m (Eq. 10).
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import torch
from torch import nn

from sysid.hybrid.layers import forces as network_forces

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
    """F_NN = sigma_F * f_NN((s - mu_s) / sigma_s) + mu_F, as the mean of K members.

    Each member is the paper's network (9-64-64-3, tanh); K = 1 is the paper's model. The
    members differ by their random initialisation and are trained side by side, each on its
    own loss (``per_member=True``); the correction is their mean, which averages out the
    variance of a single small network trained on little data.

    Parameters
    ----------
    hidden : hidden layer widths (paper: 64, 64).
    dtype : parameter dtype.
    members : K, the number of networks averaged.
    """

    def __init__(self, hidden: Sequence[int] = (64, 64), dtype: torch.dtype = torch.float32,
                 members: int = 1):
        super().__init__()
        if members < 1:
            raise ValueError(f"members must be >= 1, got {members}")
        self.members = int(members)
        widths = [len(INPUT_NAMES), *hidden, len(OUTPUT_NAMES)]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for n_in, n_out in zip(widths[:-1], widths[1:]):
            bound = 1.0 / math.sqrt(n_in)  # nn.Linear's default initialisation
            self.weights.append(nn.Parameter(torch.empty(members, n_in, n_out, dtype=dtype).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(torch.empty(members, n_out, dtype=dtype).uniform_(-bound, bound)))
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

    def _layer(self, z: torch.Tensor, i: int) -> torch.Tensor:
        w = self.weights[i]
        b = self.biases[i].reshape(self.members, *([1] * (z.dim() - 2)), -1)
        # (K, ..., i) @ (K, i, o) as one batched product over the flattened middle axes
        return torch.bmm(z.reshape(self.members, -1, w.shape[1]), w).reshape(*z.shape[:-1], w.shape[2]) + b

    def evaluate(self, s: torch.Tensor, standardized: bool = False,
                 per_member: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """(F_NN, features) for inputs s.

        F_NN [N, N, N m] (or the standardised output y of Eq. 10 when `standardized`);
        features are the activations before the output layer (64), the kNN gate's space
        (the first member's when several are averaged). With `per_member` (training), s is
        (K, ..., 9) and each member's force (K, ..., 3) and features come back.
        """
        if self.members == 1 and not per_member and not torch.is_grad_enabled():
            return self._single(s, standardized)
        z = self.standardize_inputs(s)
        if not per_member:
            z = z.expand(self.members, *z.shape)
        y, z = self.layers(z)
        force = y if standardized else y * self.output_std + self.output_mean
        if per_member:
            return force, z
        return force.mean(0), z[0]

    def _single(self, s: torch.Tensor, standardized: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """`evaluate` of one member without gradient (`frozen`)."""
        return self.frozen(standardized)(s)

    def frozen(self, standardized: bool = False) -> Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]:
        """s (..., 9) -> `evaluate(s, standardized)` (F_NN or y (..., 3), features (..., 64))
        with the parameters and statistics looked up once: for calls without gradient while
        the parameters stay where they are (the steps of one rollout). One member runs as
        2-d products without the member axis: the same numbers (a product of batch 1 is the
        2-d product) in a third of the operations; several members as `evaluate` does."""
        if self.members != 1:
            return lambda s: self.evaluate(s, standardized)
        layers = [(w[0], b[0]) for w, b in zip(self.weights, self.biases)]
        hidden, (w_out, b_out) = layers[:-1], layers[-1]
        mean, std, dtype = self.input_mean, self.input_std, self.input_mean.dtype
        scale, shift = self.output_std, self.output_mean

        def evaluate(s: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            z = (s.to(dtype) - mean) / std
            flat = z.reshape(-1, z.shape[-1])
            for w, b in hidden:
                flat = torch.tanh(torch.mm(flat, w) + b)
            y = torch.mm(flat, w_out) + b_out
            force = y if standardized else y * scale + shift
            return force.reshape(*z.shape[:-1], -1), flat.reshape(*z.shape[:-1], -1)
        return evaluate

    def evaluate_standardized(self, z: torch.Tensor, per_member: bool = False) -> torch.Tensor:
        """F_NN [N, N, N m] for inputs already standardised, z = (s - mu_s) / sigma_s (Eq. 8):
        `evaluate`'s force without its features (what a training step differentiates); with
        `per_member`, z is (K, ..., 9) and each member's force (K, ..., 3) comes back, else the
        members' mean. The layers run as one autograd Function with a hand-written backward
        (`sysid.hybrid.layers`: 2-d products for one member, batched ones on (K, rows, width)
        for several; tanh as 2 sigmoid(2 a) - 1), the same numbers as `layers` to round-off."""
        k, width = self.members, z.shape[-1]
        weights, biases = list(self.weights), list(self.biases)
        if k == 1:  # (..., 9) or, per member, (1, ..., 9): rows without the member axis
            force = network_forces(z.reshape(-1, width), weights, biases, self.output_std, self.output_mean)
            return force.view(*z.shape[:-1], force.shape[-1])
        if not per_member:
            z = z.expand(k, *z.shape)
        shape = z.shape[:-1]
        force = network_forces(z.reshape(k, -1, width), weights, biases, self.output_std, self.output_mean)
        force = force.view(*shape, force.shape[-1])
        return force if per_member else force.mean(0)

    def standardize_inputs(self, s: torch.Tensor) -> torch.Tensor:
        """s-bar = (s - mu_s) / sigma_s (Eq. 8), (..., 9), in the parameters' dtype."""
        return (s.to(self.input_mean.dtype) - self.input_mean) / self.input_std

    def layers(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(standardised output y (K, ..., 3), features (K, ..., 64)) of every member for
        standardised inputs z (K, ..., 9): the networks without Eqs. 8 and 10."""
        for i in range(len(self.weights) - 1):
            z = torch.tanh(self._layer(z, i))
        return self._layer(z, len(self.weights) - 1), z

    def features(self, s: torch.Tensor) -> torch.Tensor:
        """Activations before the output layer (..., 64)."""
        return self.evaluate(s)[1]

    def forward(self, s: torch.Tensor) -> torch.Tensor:
        """F_NN (..., 3) [N, N, N m], the members' mean."""
        return self.evaluate(s)[0]
