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
GATE_SPACES = ("features", "inputs")


class CorrectedModel(nn.Module):
    """F = F_MMG + gate * F_NN (hybrid) or F = gate * F_NN (NN-only, ``physics=False``).

    Parameters
    ----------
    mmg : the physical model (for NN-only it still supplies masses and relative wind).
    correction : the FNN term.
    gate : optional kNN OOD gate; F_NN is zeroed where the input is out of distribution.
    physics : include F_MMG (hybrid) or not (NN-only).
    gate_space : where the gate measures kNN distances: "features" (the paper's: the 64
        activations before the output layer) or "inputs" (the standardised input s-bar).
    """

    def __init__(self, mmg: MMG, correction: ForceCorrection, gate: KNNGate | None = None,
                 physics: bool = True, gate_space: str = "features"):
        super().__init__()
        if gate_space not in GATE_SPACES:
            raise ValueError(f"gate space {gate_space!r}: choose one of {', '.join(GATE_SPACES)}")
        self.mmg = mmg
        self.correction_net = correction
        self.gate = gate
        self.physics = physics
        self.gate_space = gate_space
        self.gate_enabled = gate is not None

    def gate_coordinates(self, s: torch.Tensor, z: torch.Tensor | None = None) -> torch.Tensor:
        """The vectors the kNN gate compares: features z (..., 64) or standardised s (..., 9)."""
        if self.gate_space == "inputs":
            net = self.correction_net
            return (s.to(net.input_mean.dtype) - net.input_mean) / net.input_std
        return self.correction_net.features(s) if z is None else z

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
        f_nn, z = self.correction_net.evaluate(s)
        f_nn = f_nn.to(state.dtype)
        if self.gate is not None and self.gate_enabled and self.gate.bank.shape[0] > 0:
            distance, on = self.gate(self.gate_coordinates(s, z))
            f_nn = torch.where(on[..., None], f_nn, torch.zeros_like(f_nn))
            forces.ood_distance, forces.gate_on = distance.to(state.dtype), on
        forces.correction = f_nn
        return forces
