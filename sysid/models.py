"""MMG-only, NN-only and hybrid force models behind one interface.

Each maps (state (..., 6), inputs (..., 4)) to a `ForceBreakdown` and carries
``coefficients`` (the mass terms of the equations of motion), so integration, training,
evaluation and plots never ask which one they hold.
"""
from __future__ import annotations

import torch
from torch import nn

from sysid.correction import ForceCorrection, correction_inputs
from sysid.mmg.model import MMG, ForceBreakdown
from sysid.mmg.wind import relative_wind
from sysid.ood import KNNGate

KINDS = ("mmg", "nn", "hybrid")


class CorrectedModel(nn.Module):
    """F = F_MMG + gate * F_NN (hybrid) or F = gate * F_NN (NN-only, ``physics=False``).

    Parameters
    ----------
    mmg : the physical model (for NN-only it still supplies masses and relative wind).
    correction : the FNN term.
    gate : optional kNN OOD gate; F_NN is zeroed where the input is out of distribution.
    physics : include F_MMG (hybrid) or not (NN-only).
    """

    def __init__(self, mmg: MMG, correction: ForceCorrection, gate: KNNGate | None = None,
                 physics: bool = True):
        super().__init__()
        self.mmg = mmg
        self.correction_net = correction
        self.gate = gate
        self.physics = physics
        self.gate_enabled = gate is not None

    @property
    def coefficients(self):
        return self.mmg.coefficients

    @property
    def kind(self) -> str:
        return "hybrid" if self.physics else "nn"

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        if self.physics:
            forces = self.mmg(state, inputs)
        else:
            wind = relative_wind(state[..., 1], state[..., 3], state[..., 4], inputs[..., 2], inputs[..., 3])
            rel = torch.stack(wind, -1)
            zero = torch.zeros(state.shape[:-1] + (3,), dtype=state.dtype, device=state.device)
            forces = ForceBreakdown(zero, zero, zero, zero, zero, rel)
        s = correction_inputs(state, inputs, forces.relative_wind)
        z = self.correction_net.features(s)
        f_nn = self.correction_net.force(z).to(state.dtype)
        if self.gate is not None and self.gate_enabled and self.gate.bank.shape[0] > 0:
            distance, on = self.gate(z)
            f_nn = torch.where(on[..., None], f_nn, torch.zeros_like(f_nn))
            forces.ood_distance, forces.gate_on = distance.to(state.dtype), on
        forces.correction = f_nn
        return forces
