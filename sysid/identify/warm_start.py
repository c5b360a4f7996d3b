"""Stages 2 and 4 of training: the FNN's standardisation and its warm start.

Input statistics come from the correction inputs s (N, 9) at the training windows' step
starts (relative wind computed from the recorded state and true wind, as the model sees
it); output statistics from the residual force the data imply,
M * (v[k+1] - v[k]) / dt + C(v[k]) - F_MMG(x[k]) (for NN-only without F_MMG), the force
that makes one Euler step land on the record [N, N, N m]. The warm start regresses every FNN
member on that standardised residual (one-step fit) with Adam.
"""
from __future__ import annotations

import torch

from sysid.config.experiment import Experiment
from sysid.dynamics.equations import required_force
from sysid.dynamics.rollouts import WindowSet
from sysid.errors import TrainingError
from sysid.hybrid.correction import ForceCorrection, correction_inputs
from sysid.hybrid.force_models import CorrectedModel
from sysid.identify.adam import Adam
from sysid.identify.journal import TrainingJournal
from sysid.identify.losses import VEL


def implied_residual(model: CorrectedModel, windows: WindowSet, pairs: int = 2
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Correction inputs s (N, 9), residual force (N, 3) and F_MMG (N, 3) at step starts."""
    # the first `pairs` steps of each window: with 2-s strides that covers each step once
    states, inputs = windows.states[:pairs + 1], windows.inputs[:pairs + 1]
    x, nxt, inp = states[:-1].reshape(-1, 6), states[1:].reshape(-1, 6), inputs[:-1].reshape(-1, 4)
    with torch.no_grad():
        acc = (nxt[:, VEL] - x[:, VEL]) / windows.dt
        need = required_force(x, acc, model.coefficients)
        forces = model.mmg(x, inp)
        f_mmg = forces.mmg if model.physics else torch.zeros_like(need)
        s = correction_inputs(x, inp, forces.relative_wind)
    return s, need - f_mmg, f_mmg


def standardize(model: CorrectedModel, train: WindowSet, stride_s: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Stage 2: the FNN's input statistics and the output statistics of the implied residual
    force, on the first steps of the training windows slid by `stride_s` [s]; returns the
    correction inputs s (N, 9) and the residual (N, 3) for the warm start."""
    net = model.correction_net
    stride = max(1, int(round(stride_s / train.dt)))
    s, residual, _ = implied_residual(model, train, stride)
    net.set_standardization(s.mean(0), s.std(0), residual.mean(0), residual.std(0))
    return s, residual




class OneStepRegression:
    """The warm start's regression of a `ForceCorrection` in closed form: the loss, the
    mean over members, rows and outputs of (y - target)^2 plus lambda_L2 |theta|^2 (the
    weights' `weight_norm`, per member), its gradient written out (`gradient`) and Adam
    (`adam_step`: `sysid.identify.adam.Adam`, the training loop's, with its defaults) on
    all parameters held as one flat vector ``theta`` (the layers' weights, then their
    biases; `write_back` copies it into the network). No autograd graph is built.

    net : the network (K members, L layers), its parameters copied in.
    lambda_L2 : weight of |theta|^2; lr : Adam's learning rate.
    """

    def __init__(self, net: ForceCorrection, lambda_L2: float, lr: float):
        self.net, self.lambda_L2 = net, float(lambda_L2)
        self.parameters = [*net.weights, *net.biases]
        self.theta = torch.cat([q.detach().reshape(-1) for q in self.parameters])
        self.grad = torch.zeros_like(self.theta)
        self.theta.grad = self.grad  # `gradient` writes into it; `adam_step` reads it there
        self.adam = Adam([self.theta], lr)
        sizes, shapes = [q.numel() for q in self.parameters], [q.shape for q in self.parameters]
        self.views = [v.view(shape) for v, shape in zip(self.theta.split(sizes), shapes)]
        self.grads = [v.view(shape) for v, shape in zip(self.grad.split(sizes), shapes)]
        # the views `gradient` reads, made once (they follow ``theta`` and ``grad`` in place)
        L = len(self.views) // 2
        weights, biases = self.views[:L], self.views[L:]
        self._hidden = [(w, b.unsqueeze(1)) for w, b in zip(weights[:-1], biases[:-1])]  # W_i, b_i (K, 1, n)
        self._hidden_T = [w.mT for w in weights[:-1]]
        self._output = (weights[-1].mT, biases[-1].unsqueeze(-1))  # W^T (K, 3, n), b (K, 3, 1)
        self._weights, self._d_weights, self._d_biases = weights, self.grads[:L], self.grads[L:]
        self._beta = 2.0 * self.lambda_L2 / net.members

    def gradient(self, z: torch.Tensor, target_T: torch.Tensor, loss: bool = False) -> torch.Tensor | None:
        """The loss's gradient at ``theta`` into ``grad``, for standardised inputs z (K, B, 9)
        and the standardised targets transposed, target_T (3, B); the loss itself (a scalar)
        when `loss`, else None.

        A forward pass keeps the activations h_i = tanh(h_{i-1} W_i + b_i) (K, B, n_i); then
        g = 2 (y - target) / (K B 3) goes back through the layers: dW_i = h_{i-1}^T g_i,
        db_i = sum over rows of g_i, g_{i-1} = (g_i W_i^T) (1 - h_{i-1}^2); the weight norm
        adds 2 lambda_L2 W_i / K. The output layer (3 columns) is computed transposed,
        y^T = W^T h^T, which the matrix library does several times faster than h W. Equal
        to autograd's gradient to float round-off.
        """
        layers, (w_T, b_col) = self._hidden, self._output
        beta = self._beta
        h = [z]
        for w_i, b_row in layers:
            # tanh a = 2 sigmoid(2 a) - 1 (torch's sigmoid is several times faster than its
            # tanh): 2 a by the product's own factors (exact: a power of two), then -1 + 2 s
            a = torch.baddbmm(b_row, h[-1], w_i, beta=2.0, alpha=2.0).sigmoid_()
            h.append(torch.add(_MINUS_ONE, a, alpha=2.0, out=a))
        g_T = torch.baddbmm(b_col, w_T, h[-1].mT).sub_(target_T)  # y^T - target^T (K, 3, B)
        value = None
        if loss:
            value = g_T.square().mean() + self.lambda_L2 * sum((v * v).sum() for v in self._weights) / self.net.members
        g_T.mul_(2.0 / g_T.numel())  # dL/dy, transposed
        d_weights, d_biases = self._d_weights, self._d_biases
        d_weights[-1].copy_(torch.baddbmm(w_T, g_T, h[-1], beta=beta).mT)  # dW^T = g^T h, transposed back
        torch.sum(g_T, 2, out=d_biases[-1])
        g = torch.bmm(g_T.mT, w_T)  # (K, B, n) at the last hidden layer, before its tanh'
        for i in range(len(layers) - 1, -1, -1):
            g.mul_(torch.addcmul(_ONE, h[i + 1], h[i + 1], value=-1.0))
            torch.baddbmm(layers[i][0], h[i].mT, g, beta=beta, out=d_weights[i])
            torch.sum(g, 1, out=d_biases[i])
            if i:
                g = torch.bmm(g, self._hidden_T[i])
        return value

    def adam_step(self) -> None:
        """One update of ``theta`` with ``grad`` by `sysid.identify.adam.Adam`, the training
        loop's (torch.optim.Adam's operations, so the same numbers to the last bit)."""
        self.adam.step()

    def write_back(self) -> None:
        """``theta`` into the network's parameters."""
        with torch.no_grad():
            for q, v in zip(self.parameters, self.views):
                q.copy_(v)


_ONE = torch.ones(())
_MINUS_ONE = -torch.ones(())


def warm_start(net: ForceCorrection, s: torch.Tensor, residual: torch.Tensor, device, experiment: Experiment,
               journal: TrainingJournal) -> None:
    """Stage 4: every FNN member regresses the standardised residual force (one step),
    ``[training] warm_start_epochs`` epochs of minibatches of 256 in a seeded order, Adam
    with learning rate 3e-3 (`OneStepRegression`)."""
    t = experiment.training
    target = (residual - net.output_mean) / net.output_std
    z = net.standardize_inputs(s).expand(net.members, *s.shape)  # (K, N, 9), fixed over the warm start
    regression = OneStepRegression(net, t.lambda_L2, 3e-3)
    gen = torch.Generator().manual_seed(experiment.experiment.seed + 2)
    bar = journal.epochs(range(t.warm_start_epochs), "warm start", t.warm_start_epochs, 0)
    journal.warm_start_begins(bar, t.warm_start_epochs, len(s))
    with torch.no_grad():
        for epoch in bar:
            order = torch.randperm(len(s), generator=gen).to(device)
            z_epoch, target_T = z[:, order], target[order].T  # the epoch's order, gathered once
            loss = None
            for lo in range(0, len(s), 256):
                # the epoch's last minibatch: its loss is the epoch's
                loss = regression.gradient(z_epoch[:, lo:lo + 256], target_T[:, lo:lo + 256], lo + 256 >= len(s))
                regression.adam_step()
            assert loss is not None
            if not torch.isfinite(loss):
                raise TrainingError(f"{experiment.source}: [training] the warm-start loss became "
                                    f"{loss.item()}; no run written")
            journal.warm_start_epoch(bar, epoch + 1, t.warm_start_epochs, loss.item())
    regression.write_back()
