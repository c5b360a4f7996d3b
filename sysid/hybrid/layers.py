"""The FNN's layers of a training step as one autograd Function with a hand-written backward.

For standardised inputs z the network is h_0 = z, h_i = tanh(h_{i-1} W_i + b_i) for the hidden
layers and y = h_{L-1} W_L + b_L, de-standardised to F = y * sigma_F + mu_F [N, N, N m]
(paper Eqs. 9-10). `forces` computes it with the activations h_i kept; its backward is the
chain rule written out:

    g_y = g_F * sigma_F,   dW_i = h_{i-1}^T g_i,   db_i = sum_rows g_i,
    g_{i-1} = (g_i W_i^T) * (1 - h_{i-1}^2)      (tanh' = 1 - tanh^2),

the products and one elementwise pass per layer, in place of autograd's record of each
product, bias, tanh and view. One network (K = 1) runs as 2-d products (`torch.addmm`,
`torch.mm`); K networks side by side (the member axis) as batched ones (`torch.baddbmm`,
`torch.bmm`). The narrow products (the output layer's 3 columns, the 9 inputs' gradient) run
transposed, with the narrow side as the product's rows: several times quicker on this CPU's
BLAS (K = 5, 256 rows: 41-58 against 112-195 us).

tanh is computed as 2 sigmoid(2 a) - 1 (`tanh`), about 4x quicker than `torch.tanh` on this
CPU's float32, the same function: its absolute error against the exact tanh is below 2e-7 in
float32 (1.8e-7 measured, 1.5 ulp of 1; `torch.tanh`'s own is 3e-8) and below 4e-16 in
float64, on a dense grid of a in [-20, 20] (`tests/hybrid/test_layers.py`); it is exactly 0 at
0 and saturates to exactly +-1. The no-gradient forwards (`ForceCorrection.frozen`, `layers`)
keep `torch.tanh`: the two differ at float32 round-off.
"""
from __future__ import annotations

import torch


def tanh(a: torch.Tensor) -> torch.Tensor:
    """tanh(a) as 2 sigmoid(2 a) - 1, a new tensor (see the module docstring for its error)."""
    return torch.sigmoid(a * 2.0).mul_(2.0).sub_(1.0)


def _hidden_(a2: torch.Tensor) -> torch.Tensor:
    """tanh(a) in place of `a2` = 2 a (the pre-activation doubled inside its product; exact):
    -1 + 2 s in one pass (a fused multiply-add: 2 s is exact, so the same numbers as 2 s - 1)."""
    return torch.add(_minus_one(a2), a2.sigmoid_(), alpha=2.0, out=a2)


_MINUS_ONE: dict[tuple, torch.Tensor] = {}


def _minus_one(like: torch.Tensor) -> torch.Tensor:
    """-1 as a 0-d tensor of `like`'s dtype and device (a Python number would be converted at
    every call)."""
    key = (like.dtype, like.device)
    found = _MINUS_ONE.get(key)
    if found is None:
        with torch.inference_mode(False):
            found = _MINUS_ONE[key] = torch.tensor(-1.0, dtype=like.dtype, device=like.device)
    return found


def forward_single(z: torch.Tensor, weights, biases, scale: torch.Tensor, shift: torch.Tensor,
                   out: torch.Tensor, last: tuple | None = None, doubled: list | None = None) -> list[torch.Tensor]:
    """One network's F (rows, n_L) into `out` from z (rows, n_0), without autograd; W_i
    (n_{i-1}, n_i), b_i (n_i,). Returns the activations [z, h_1, ..., h_{L-1}] (`backward`'s).

    The narrow output layer runs transposed, with its n_L = 3 outputs as the product's rows
    (y^T = W_L^T h^T + b_L): several times quicker on this CPU's BLAS than h W_L; `last` is
    (W_L^T contiguous, b_L (n_L, 1)) where the caller keeps them, else they are made here.
    `doubled`: (2 W_i, 2 b_i) of the hidden layers where the caller keeps them (2 a = h 2W + 2b
    in one product without scaling: the same numbers, doubling is exact)."""
    h = [z]
    if doubled is None:
        for w, b in zip(weights[:-1], biases[:-1]):
            h.append(_hidden_(torch.addmm(b, h[-1], w, beta=2.0, alpha=2.0)))
    else:
        for w2, b2 in doubled:
            h.append(_hidden_(torch.addmm(b2, h[-1], w2)))
    w_T, b_col = (weights[-1].mT.contiguous(), biases[-1].unsqueeze(-1)) if last is None else last
    y = torch.addmm(b_col, w_T, h[-1].mT).mT
    torch.addcmul(shift, y, scale, out=out)
    return h


def forward_members(z: torch.Tensor, weights, biases, scale: torch.Tensor,
                    shift: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """(F (K, rows, n_L), the activations [z, h_1, ..., h_{L-1}]) of K networks side by side
    from z (K, rows, n_0), without autograd; W_i (K, n_{i-1}, n_i), b_i (K, n_i)."""
    h = [z]
    for w, b in zip(weights[:-1], biases[:-1]):
        h.append(_hidden_(torch.baddbmm(b.unsqueeze(1), h[-1], w, beta=2.0, alpha=2.0)))
    # the narrow output layer transposed, as `forward_single`: y^T = W_L^T h^T + b_L
    y = torch.baddbmm(biases[-1].unsqueeze(-1), weights[-1].mT.contiguous(), h[-1].mT).mT
    force = z.new_empty(y.shape)  # rows contiguous
    return torch.addcmul(shift, y, scale, out=force), h


def backward(grad: torch.Tensor, h, weights, scale: torch.Tensor, single: bool,
             input_gradient: bool) -> tuple[torch.Tensor | None, list[torch.Tensor]]:
    """(g_z or None, [dW_1, db_1, ..., dW_L, db_L]) for the gradient `grad` of F (rows, n_L) (one
    network, `single`: 2-d tensors; gradients (1, ...) as the module holds them) or (K, rows,
    n_L); `h` and `weights` as the forward used them. g_z only with `input_gradient`."""
    mm = torch.mm if single else torch.bmm
    g = grad * scale
    n = len(weights)
    grads: list[torch.Tensor] = [grad] * (2 * n)
    g_in: torch.Tensor | None = None
    for i in range(n - 1, -1, -1):
        h_in = h[i]
        # narrow products transposed (dW_L = (g^T h)^T, g_z = (W_1 g^T)^T), as in the forwards
        d_w = mm(g.mT, h_in).mT if i == n - 1 else mm(h_in.mT, g)
        grads[2 * i] = d_w.unsqueeze(0) if single else d_w
        grads[2 * i + 1] = g.sum(-2, keepdim=single)  # (1, n_i) or (K, n_i)
        if i > 0:  # (g W^T) (1 - h^2) in place of g W^T
            g_h = mm(g, weights[i].mT)
            g = torch.ops.aten.tanh_backward.grad_input(g_h, h_in, grad_input=g_h)
        elif input_gradient:
            g_in = mm(weights[0], g.mT).mT.contiguous()
    return g_in, grads


class _Layers(torch.autograd.Function):
    """(z, sigma_F, mu_F, W_1, b_1, ..., W_L, b_L) -> F; z (rows, n_0) with one network, else
    (K, rows, n_0); W_i (K, n_{i-1}, n_i), b_i (K, n_i) as the module holds them."""

    @staticmethod
    def forward(ctx, z, scale, shift, *parameters):
        weights, biases = parameters[0::2], parameters[1::2]
        single = z.dim() == 2
        if single:
            weights = [w[0] for w in weights]
            force = z.new_empty(z.shape[0], weights[-1].shape[-1])
            h = forward_single(z, weights, [b[0] for b in biases], scale, shift, force)
        else:
            force, h = forward_members(z, weights, biases, scale, shift)
        ctx.save_for_backward(scale, *h, *weights)
        ctx.single = single
        return force

    @staticmethod
    def backward(ctx, grad):
        saved = ctx.saved_tensors
        n = (len(saved) - 1) // 2
        g_z, grads = backward(grad, saved[1:1 + n], saved[1 + n:], saved[0], ctx.single, ctx.needs_input_grad[0])
        return g_z, None, None, *grads


def forces(z: torch.Tensor, weights, biases, scale: torch.Tensor, shift: torch.Tensor) -> torch.Tensor:
    """F = sigma_F f(z) + mu_F (see the module docstring) of standardised inputs z: (rows,
    n_0) with one network (K = 1; F (rows, n_L)), (K, rows, n_0) with K (F (K, rows, n_L)).
    `weights` (K, n_{i-1}, n_i) and `biases` (K, n_i) of every layer, `scale` = sigma_F and
    `shift` = mu_F (n_L,); differentiable with respect to z and the parameters."""
    if z.dim() != (2 if weights[0].shape[0] == 1 else 3):
        raise ValueError(f"z (rows, n) for one network, (K, rows, n) for K, got {tuple(z.shape)} "
                         f"for K = {weights[0].shape[0]}")
    parameters = [p for pair in zip(weights, biases) for p in pair]
    return _Layers.apply(z, scale, shift, *parameters)
