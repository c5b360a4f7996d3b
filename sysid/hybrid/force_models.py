"""Force models behind one interface, and the one factory that builds them from a config.

A force model maps (state (..., 6), inputs (..., 4)) to a `ForceBreakdown` [N, N, N m] and
carries ``coefficients`` (the mass terms of the equations of motion), so integration,
training, evaluation and plots never ask which one they hold: `MMG` (physics only),
`CorrectedModel` with ``physics=False`` (NN-only) or ``physics=True`` (hybrid).
"""
from __future__ import annotations

from typing import Callable, Protocol, runtime_checkable

import torch
from torch import nn

from sysid.hybrid.correction import ForceCorrection, correction_inputs
from sysid.hybrid import layers
from sysid.hybrid.fused_rate import NNPlan, Plan, hybrid_rate, nn_rate
from sysid.config.choices import GateSpace, ModelKind
from sysid.config.experiment import Experiment, ship_overrides
from sysid.mmg.coefficients import Coefficients
from sysid.mmg.model import MMG, ForceBreakdown
from sysid.mmg.tangents import supported
from sysid.mmg import native
from sysid.mmg.vjp import RATE_ROWS, force_rate, rate_of_force, training_rate as mmg_training_rate
from sysid.mmg.coefficient_lookup import Rows, coefficient_matrix
from sysid.mmg.wind import relative_wind
from sysid.hybrid.knn_gate import KNNGate
from sysid.mmg.ship import load_ship


@runtime_checkable
class ForceModel(Protocol):
    """What integration, training and evaluation need of a model."""

    coefficients: Coefficients

    def __call__(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown: ...


class CorrectedModel(nn.Module):
    """F = F_MMG + gate * F_NN (hybrid) or F = gate * F_NN (NN-only, ``physics=False``).

    Parameters
    ----------
    mmg : the physical model (for NN-only it still supplies masses and relative wind).
    correction : the FNN term.
    gate : optional kNN OOD gate; F_NN is zeroed where the input is out of distribution.
    physics : include F_MMG (hybrid) or not (NN-only).
    gate_space : where the gate measures kNN distances: features (the paper's: the 64
        activations before the output layer) or inputs (the standardised input s-bar).
    """

    def __init__(self, mmg: MMG, correction: ForceCorrection, gate: KNNGate | None = None,
                 physics: bool = True, gate_space: GateSpace | str = GateSpace.FEATURES):
        super().__init__()
        self.mmg = mmg
        self.correction_net = correction
        self.gate = gate
        self.physics = physics
        self.gate_space = GateSpace.parse(gate_space)
        self.gate_enabled = gate is not None

    def gate_coordinates(self, s: torch.Tensor, z: torch.Tensor | None = None) -> torch.Tensor:
        """The vectors the kNN gate compares: features z (..., 64) or standardised s (..., 9)."""
        if self.gate_space is GateSpace.INPUTS:
            net = self.correction_net
            return (s.to(net.input_mean.dtype) - net.input_mean) / net.input_std
        return self.correction_net.features(s) if z is None else z

    @property
    def gate_width(self) -> int:
        """F of the vectors the kNN gate compares: 9 standardised inputs, or the width of
        the FNN's last hidden layer (its features)."""
        net = self.correction_net
        return net.input_mean.shape[0] if self.gate_space is GateSpace.INPUTS else net.weights[-1].shape[1]

    @property
    def coefficients(self):
        return self.mmg.coefficients

    @property
    def kind(self) -> ModelKind:
        return ModelKind.HYBRID if self.physics else ModelKind.NN

    def _correction(self, state: torch.Tensor, inputs: torch.Tensor, relative_wind: torch.Tensor,
                    per_member: bool = False):
        """(F_NN (..., 3) with the gate applied, kNN distance or None, gate decision or None)."""
        s = correction_inputs(state, inputs, relative_wind)
        f_nn, z = self.correction_net.evaluate(s, per_member=per_member)
        f_nn = f_nn.to(state.dtype)
        if self.gate is not None and self.gate_enabled and self.gate.bank.shape[0] > 0:
            distance, on = self.gate(self.gate_coordinates(s, z))
            return torch.where(on[..., None], f_nn, torch.zeros_like(f_nn)), distance.to(state.dtype), on
        return f_nn, None, None

    def gate_decision(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor | None:
        """(...,) True where the kNN gate applies F_NN at state (..., 6) with inputs (..., 4)
        (what `forward` decides); None without a fitted gate."""
        if self.gate is None or not self.gate_enabled or self.gate.bank.shape[0] == 0:
            return None
        wind = relative_wind(state[..., 1], state[..., 3], state[..., 4], inputs[..., 2], inputs[..., 3])
        s = correction_inputs(state, inputs, torch.stack(wind, -1))
        z = None if self.gate_space is GateSpace.INPUTS else self.correction_net.features(s)
        return self.gate(self.gate_coordinates(s, z))[1]

    def forward(self, state: torch.Tensor, inputs: torch.Tensor, per_member: bool = False) -> ForceBreakdown:
        """Forces at state (..., 6) with inputs (..., 4); with `per_member` (training) the
        leading axis of both is the FNN's K members and F_NN is each member's own."""
        if self.physics:
            forces = self.mmg(state, inputs)
        else:
            wind = relative_wind(state[..., 1], state[..., 3], state[..., 4], inputs[..., 2], inputs[..., 3])
            rel = torch.stack(wind, -1)
            zero = torch.zeros(state.shape[:-1] + (3,), dtype=state.dtype, device=state.device)
            forces = ForceBreakdown(zero, zero, zero, zero, zero, rel)
        f_nn, distance, on = self._correction(state, inputs, forces.relative_wind, per_member)
        if on is not None:
            forces.ood_distance, forces.gate_on = distance, on
        forces.correction = f_nn
        return forces

    def force_channels(self, state: torch.Tensor, inputs: torch.Tensor):
        """(X, Y, N) of F_MMG + F_NN (hybrid) or F_NN (NN-only), each (...,) [N, N, N m],
        and the relative wind: `forward`'s total without its (..., 3) stacks."""
        return self.gated_force_channels(state, inputs)[:2]

    def gated_force_channels(self, state: torch.Tensor, inputs: torch.Tensor):
        """`force_channels` and the kNN gate's decision (...,) (True: F_NN applied; None
        without a fitted gate), from one evaluation of the FNN and the gate."""
        if self.physics:
            total, wind = self.mmg.force_channels(state, inputs)
        else:
            total, wind = None, relative_wind(state[..., 1], state[..., 3], state[..., 4],
                                              inputs[..., 2], inputs[..., 3])
        f_nn, _, on = self._correction(state, inputs, torch.stack(wind, -1))
        f_nn = f_nn.unbind(-1)
        if total is None:  # 0 + F_NN = F_NN
            return f_nn, wind, on
        return tuple(t + f for t, f in zip(total, f_nn)), wind, on

    def eager_rate(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None] | None:
        """(dx/dt (..., 6), the kNN gate's decision (...,) or None without a fitted gate)
        at state (..., 6) with inputs (..., 4) without gradient, where `no_grad_rate`
        applies (NN-only, or a hybrid whose MMG the native kernel computes); else None (then
        `gated_force_channels` and the equations of motion, which this equals to round-off)."""
        if torch.is_grad_enabled():
            return None
        rate = self.no_grad_rate(state)
        return rate(state, inputs) if rate is not None else None

    def no_grad_rate(self, like: torch.Tensor, per_member: bool = False):
        """A function (state (..., 6), inputs (..., 4)) -> (dx/dt (..., 6), the kNN gate's
        decision (...,) or None), to call without gradient on tensors of `like`'s dtype and
        device while the model stays as it is (the steps of one rollout); None where it
        does not apply: a hybrid whose MMG the native kernel (`sysid.mmg.native`) does not
        compute, tensors it does not take. dx/dt of F_MMG and the FNN's inputs s come from
        one native call, the (gated) F_NN is added through the mass terms (dx/dt is linear
        in the force: ``+ F_NN @ force_rate``); NN-only: s from torch, dx/dt of F_NN
        (`sysid.mmg.vjp.rate_of_force`); everything looked up once. With `per_member`
        the leading axis of state and inputs is the FNN's K members (`PerMember`), each
        member's own F_NN (None with a fitted gate: training has none)."""
        gated = self.gate is not None and self.gate_enabled and self.gate.bank.shape[0] > 0
        if per_member and gated:
            return None
        families = native.families_of(self.mmg) if self.physics else None
        with torch.no_grad():
            c = self.mmg.coefficients.values_view(like.dtype)
            if self.physics and (families is None
                                 or not native.applies(like, like.new_empty(like.shape[:-1] + (4,)), c)):
                return None
            mass = force_rate(c, like)  # (3, 6)
        correction = self.correction_net
        net: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor | None]]
        if per_member and correction.members != 1:  # the training layers' forward (`sysid.hybrid.layers`)
            weights, biases = list(correction.weights), list(correction.biases)

            def members_net(s: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
                z = correction.standardize_inputs(s)
                f, _ = layers.forward_members(z.reshape(z.shape[0], -1, z.shape[-1]), weights, biases,
                                              correction.output_std, correction.output_mean)
                return f.view(*s.shape[:-1], f.shape[-1]), None
            net = members_net
        else:  # one member: its rows, any leading axes
            net = correction.frozen()
        gate, inputs_space = self.gate, self.gate_space is GateSpace.INPUTS
        mean, std = self.correction_net.input_mean, self.correction_net.input_std

        def rate(state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
            if families is None:  # NN-only: s through torch, dx/dt of F_NN alone
                wind = relative_wind(state[..., 1], state[..., 3], state[..., 4], inputs[..., 2], inputs[..., 3])
                s = correction_inputs(state, inputs, torch.stack(wind, -1))
            else:
                out = native.rate(state, inputs, c, families)
                s = out[..., 9:]
            f_nn, z = net(s)
            f_nn = f_nn.to(state.dtype)
            on = None
            if gated:
                on = gate((s.to(mean.dtype) - mean) / std if inputs_space else z)[1]
                f_nn = torch.where(on[..., None], f_nn, torch.zeros_like(f_nn))
            if families is None:
                return rate_of_force(state, f_nn, c), on
            return torch.addmm(out[..., :6].reshape(-1, 6), f_nn.reshape(-1, 3), mass).view(state.shape), on
        return rate

    def training_rate(self, per_member: bool = False):
        """The right-hand side a training rollout differentiates, or None where it does not
        apply (then `forward` is differentiated through autograd): a function of (state
        (..., 6), inputs (..., 4)) giving (dx/dt (..., 6), F_NN (..., 3), F_MMG (..., 3)), the
        MMG, the FNN's inputs and the equations of motion in one autograd Function with a
        hand-derived VJP (`sysid.mmg.vjp`), the FNN's layers in another
        (`sysid.hybrid.layers`); for one network (K = 1), or K members each on its own rows
        (`per_member`), where the native kernel applies, all of it in one
        (`sysid.hybrid.fused_rate`). The same numbers as `forward` and the
        equations of motion, to round-off.

        NN-only (no active gate, gradients on): `_nn_training_rate`. It applies to a
        hybrid without an active gate, with gradients on, whose MMG
        `sysid.mmg.tangents.supported` covers (the Esso Osaka's families, fixed
        coefficients) or the native kernel computes (`sysid.mmg.native.families_of`: the
        standard families too, fixed coefficients; a step the kernel does not apply to goes
        through autograd over `forward`)."""
        gated = self.gate is not None and self.gate_enabled and self.gate.bank.shape[0] > 0
        if not torch.is_grad_enabled() or gated:
            return None
        if not self.physics:
            return self._nn_training_rate(per_member)
        coefficients, net = self.mmg.coefficients, self.correction_net
        if supported(self.mmg):
            rate = self._training_rate(coefficients, net, "wind" in self.mmg.families, per_member)
        else:
            families = native.families_of(self.mmg)
            if families is None or any(p.requires_grad for p in coefficients.parameters()):
                return None
            rate = self._native_training_rate(coefficients, net, families, per_member)
        families = native.families_of(self.mmg)
        if (net.members != 1 and not per_member) or families is None:
            return rate
        return self._fused_training_rate(coefficients, net, families, rate)

    def _nn_training_rate(self, per_member: bool):
        """`training_rate` of NN-only (F = F_NN) as one autograd Function
        (`sysid.hybrid.fused_rate.nn_rate`) for one network (K = 1) or K members each on its
        own rows (`per_member`: states (K, ..., 6)); None for the mean of K members. Where the
        rollout's tensors do not fit it (checked at its first call of each dtype: the state's,
        the inputs' and the FNN's dtype alike; constant mass terms), autograd through `forward`
        and the equations of motion. One rollout: parameters and coefficients stay as they are
        between its calls."""
        coefficients, net = self.mmg.coefficients, self.correction_net
        if net.members != 1 and not per_member:
            return None
        parameters = [p for pair in zip(net.weights, net.biases) for p in pair]
        plans: dict[torch.dtype, NNPlan] = {}

        def rate(state: torch.Tensor, inputs: torch.Tensor):
            plan = plans.get(state.dtype)
            if plan is None:  # the rollout's first call: the checks, then the lookups, once
                c = coefficients.values_view(state.dtype)
                rates = coefficient_matrix(c, _EOM_ROWS, state)
                if (rates.requires_grad or inputs.dtype != state.dtype
                        or not all(t.dtype == state.dtype for t in (*parameters, net.input_mean, net.output_std))
                        or not (net.members == 1 or (state.dim() > 1 and state.shape[0] == net.members))):
                    forces = self(state, inputs, per_member=per_member)
                    return rate_of_force(state, forces.total, c), forces.correction, forces.mmg
                plan = plans[state.dtype] = NNPlan(rates, net.input_mean, net.input_std, net.output_std,
                                                   net.output_mean, parameters)
            return nn_rate(state, inputs, plan)
        return rate

    @staticmethod
    def _fused_training_rate(coefficients, net, families: int, otherwise):
        """`training_rate` of one network (K = 1), or of K members each on its own rows, as one
        autograd Function (`sysid.hybrid.fused_rate`) where the native kernel applies to the
        rollout's tensors (checked at its first call of each dtype; the FNN's tensors of the
        state's dtype; K members: states (K, ..., 6)), else `otherwise`. One rollout: the
        parameters, the coefficients and the way tensors reach the kernel stay as they are
        between its calls (a training rollout's)."""
        parameters = [p for pair in zip(net.weights, net.biases) for p in pair]
        plans: dict[torch.dtype, Plan] = {}

        def rate(state: torch.Tensor, inputs: torch.Tensor):
            plan = plans.get(state.dtype)
            if plan is None:  # the rollout's first call: the checks, then the lookups, once
                c = coefficients.values_view(state.dtype)
                if not (native.applies(state, inputs, c, differentiated=True)
                        and all(t.dtype == state.dtype for t in (*parameters, net.input_mean, net.output_std))
                        and (net.members == 1 or (state.dim() > 1 and state.shape[0] == net.members))):
                    return otherwise(state, inputs)
                kernel = native.TrainingKernel(c, families, net.input_mean, net.input_std, state.dtype)
                plan = plans[state.dtype] = Plan(kernel, force_rate(c, state), net.output_std, net.output_mean,
                                                 parameters)
            return hybrid_rate(state, inputs, plan)
        return rate

    @staticmethod
    def _training_rate(coefficients, net, wind: bool, per_member: bool):
        """The Esso Osaka's `training_rate`: the native kernel, else the torch VJP."""
        def rate(state: torch.Tensor, inputs: torch.Tensor):
            c = coefficients.values_view(state.dtype)
            rate_mmg, f_mmg, z = mmg_training_rate(state, inputs, c, wind, net.input_mean, net.input_std)
            f_nn = net.evaluate_standardized(z, per_member=per_member).to(state.dtype)
            return torch.addmm(rate_mmg.reshape(-1, 6), f_nn.reshape(-1, 3), force_rate(c, state)).view(
                state.shape), f_nn, f_mmg
        return rate

    def _native_training_rate(self, coefficients, net, families: int, per_member: bool):
        """`training_rate` of the other families the native kernel covers (`native.families_of`):
        the kernel where it applies to a step's tensors, else autograd through `forward`."""
        def rate(state: torch.Tensor, inputs: torch.Tensor):
            c = coefficients.values_view(state.dtype)
            mean, std = net.input_mean, net.input_std
            if mean.dtype == state.dtype == std.dtype and native.applies(state, inputs, c, differentiated=True):
                rate_mmg, f_mmg, z = mmg_training_rate(state, inputs, c, families, mean, std)
                f_nn = net.evaluate_standardized(z, per_member=per_member).to(state.dtype)
                return torch.addmm(rate_mmg.reshape(-1, 6), f_nn.reshape(-1, 3), force_rate(c, state)).view(
                    state.shape), f_nn, f_mmg
            forces = self(state, inputs, per_member=per_member)
            return rate_of_force(state, forces.total, c), forces.correction, forces.mmg
        return rate


_EOM_ROWS = Rows(RATE_ROWS)  # (16, 6): `sysid.mmg.vjp.rate_of_force`'s matrix of the equations of motion


class PerMember(nn.Module):
    """A `CorrectedModel` whose K FNN members each predict their own copy of the batch:
    inputs and states (K, ..., ·), forces (K, ..., 3). Used by training only."""

    def __init__(self, model: CorrectedModel):
        super().__init__()
        self.model = model

    @property
    def coefficients(self):
        return self.model.coefficients

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> ForceBreakdown:
        return self.model(state, inputs, per_member=True)

    def eager_rate(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, None] | None:
        """`CorrectedModel.eager_rate` of the members (states and inputs (K, ..., ·)), each
        member's own F_NN: without gradient, the native kernel's MMG where it applies; else None."""
        if torch.is_grad_enabled():
            return None
        rate = self.model.no_grad_rate(state, per_member=True)
        return rate(state, inputs) if rate is not None else None

    def training_rate(self):
        """`CorrectedModel.training_rate` of the members, each on its own copy of the batch."""
        return self.model.training_rate(per_member=True)


def build_mmg(exp: Experiment, dtype: torch.dtype = torch.float64) -> MMG:
    """The experiment's MMG: its ship with ``[mmg] overrides``; the ``[identify]``
    parameters trainable within their bounds."""
    ship = load_ship(exp.experiment.ship, ship_overrides(exp))
    identify = list(exp.identify.parameters)
    bounds = {k: tuple(v) for k, v in exp.identify.bounds.items() if k in identify}
    return MMG(ship, trainable=identify, bounds=bounds or None, dtype=dtype)


def build_model(exp: Experiment, dtype: torch.dtype = torch.float64) -> nn.Module:
    """An untrained model with the experiment's structure (MMG, NN-only or hybrid)."""
    mmg = build_mmg(exp, dtype)
    if exp.experiment.model is ModelKind.MMG:
        return mmg
    net = ForceCorrection(exp.network.hidden, dtype, exp.network.members)
    return CorrectedModel(mmg, net, None, physics=exp.experiment.model is ModelKind.HYBRID, gate_space=exp.gate.space)


def correction_of(model: nn.Module) -> ForceCorrection | None:
    """The FNN term of a model, or None for MMG-only."""
    return model.correction_net if isinstance(model, CorrectedModel) else None


def gate_off_meaning(model: nn.Module) -> str:
    """What a step with the kNN gate off is, in words, for the model's kind: a hybrid's
    (or its ensemble's) the MMG's alone; an NN-only model's no force at all (no physics
    under its FNN: the ship keeps its velocity)."""
    if str(getattr(model, "kind", "mmg")) == ModelKind.NN:
        return "the FNN is switched off and NN-only has no force at all there (no physics under it)"
    return "the FNN is switched off and the model predicts as its physics MMG there"
