"""The MMG part of a hybrid right-hand side as one autograd Function with a hand-derived VJP.

`mmg_rate` returns, for state (..., 6) and inputs (..., 4), one tensor (..., 18):

* dx/dt (..., 6) of the equations of motion (paper Eqs. 1, 4) driven by F_MMG alone; the FNN's
  force adds ``F_NN @ FORCE_RATE`` (the equations are linear in the force),
* F_MMG (..., 3) = (X, Y, N) [N, N, N m],
* the FNN's inputs s (..., 9) in `sysid.hybrid.correction.INPUT_NAMES` order (u, v_m, r,
  delta, n_p, omega_u, omega_v, cos psi, sin psi),

computed without autograd: by the native kernel (`sysid.mmg.native`: one call per batch,
where it is built and the tensors are on the CPU) or by `sysid.mmg.tangents` (the values and
their Jacobian with respect to the state, the chain rule written out in torch), the same
numbers to round-off. Its backward is the vector-Jacobian product, one
batched product: what a training step differentiates in place of autograd's record of every
operation of the MMG, the FNN's inputs and the equations of motion. The inputs get no
gradient (recorded, constant); the coefficients none either (`sysid.mmg.tangents.supported`
says where this applies; elsewhere `MMG` runs through autograd).

`identified_rate` is dx/dt (..., 6) of an `MMG` whose identified coefficients are among the
hull's linear ones (`sysid.mmg.tangents.HULL_LINEAR`), differentiable with respect to the
state and those coefficients: dF/dtheta_j is the product (v u, v |u|, v r, r u or r |u|) of
its hull term times the term's other factors, and dx/dt is affine in F (the mass terms,
constants here), so its backward is the state's VJP beside one product per coefficient.
"""
from __future__ import annotations

from types import SimpleNamespace

import torch

from sysid.mmg import native
from sysid.mmg.coefficient_lookup import Rows, coefficient_matrix, coefficient_vector
from sysid.mmg.capture import captured, transformed
from sysid.mmg.tangents import FAMILIES, HULL_LINEAR, basis, forces_with_tangents

# dx/dt (..., 6) as features (..., 16) times a (16, 6) matrix of the mass terms: features
# (X, Y, N, u r, v r, r r, u cos psi, u sin psi, v cos psi, v sin psi, x, u, y, v, psi, r)
# (`sysid.mmg.coefficients.derived_constants`' ``eom_*``)
_NONE6 = (None,) * 6
RATE_ROWS = ((None, "eom_X_u", None, None, None, None),        # X
             (None, None, None, "eom_Y_v", None, "eom_N_v"),   # Y
             (None, None, None, "eom_N_v", None, "eom_N_r"),   # N
             (None, None, None, "eom_ur_v", None, "eom_ur_r"),  # u r
             (None, "eom_vr_u", None, None, None, None),       # v r
             (None, "eom_rr_u", None, None, None, None),       # r r
             (1.0, None, None, None, None, None),              # u cos psi -> x_dot
             (None, None, 1.0, None, None, None),              # u sin psi -> y_dot
             (None, None, 1.0, None, None, None),              # v cos psi -> y_dot
             (-1.0, None, None, None, None, None),             # v sin psi -> x_dot
             _NONE6, _NONE6, _NONE6, _NONE6, _NONE6,           # x, u, y, v, psi
             (None, None, None, None, 1.0, None))              # r -> psi_dot
_RATE = Rows(RATE_ROWS)
FORCE_RATE = Rows(RATE_ROWS[:3])  # (3, 6): dx/dt of a force (X, Y, N)
WIDTH = 18  # dx/dt (6), F_MMG (3), s (9)


def force_rate(c, like: torch.Tensor) -> torch.Tensor:
    """(3, 6): dx/dt = F @ this for a force F (..., 3) = (X, Y, N) [N, N, N m] (the mass
    terms of Eq. 4), in `like`'s dtype."""
    return coefficient_matrix(c, FORCE_RATE, like)


def rate_of_force(state: torch.Tensor, force: torch.Tensor, c) -> torch.Tensor:
    """dx/dt (..., 6) of Eqs. (1), (4) at state (..., 6) driven by `force` (..., 3) = (X, Y,
    N) [N, N, N m], through torch (autograd records it)."""
    _, u, _, v, psi, r = state.split_with_sizes([1] * 6, -1)
    cos_psi, sin_psi = torch.cos(psi), torch.sin(psi)
    a = torch.cat([u, v, r, u, u, v, v], -1)
    b = torch.cat([r, r, r, cos_psi, sin_psi, cos_psi, sin_psi], -1)
    return torch.cat([force, a * b, state], -1) @ coefficient_matrix(c, _RATE, state)


def _rate_with_tangents(state, force, d_force, c):
    """dx/dt (..., 6) of Eqs. (1), (4) driven by `force` and its Jacobian (..., 6, 6) laid out
    [d state, d rate], from the force's (..., 6, 3); also (cos psi, sin psi) (..., 2)."""
    B = basis(state)
    _, u, _, v, psi, r = state.split_with_sizes([1] * 6, -1)
    cos_psi, sin_psi = torch.cos(psi), torch.sin(psi)
    # kinematic features a * b, a = (u, v, r, u, u, v, v), b = (r, r, r, cos, sin, cos, sin)
    a = torch.cat([u, v, r, u, u, v, v], -1)
    b = torch.cat([r, r, r, cos_psi, sin_psi, cos_psi, sin_psi], -1)
    rates = coefficient_matrix(c, _RATE, state)
    rate = torch.cat([force, a * b, state], -1) @ rates
    first, r_in_b = _kinematic_tables(state)
    zero = torch.zeros_like(u)
    # d b = r's tangent (first three) + psi's times (0, 0, 0, -sin, cos, -sin, cos)
    d_b = torch.addcmul(r_in_b, B.E[:, 4:5], torch.cat([zero, zero, zero, -sin_psi, cos_psi, -sin_psi, cos_psi],
                                                      -1).unsqueeze(-2))
    d_kinematic = torch.addcmul(a.unsqueeze(-2) * d_b, b.unsqueeze(-2), first)       # (..., 6, 7)
    d_rate = (torch.cat([d_force, d_kinematic], -1).view(-1, 10) @ rates[:10]).view(*state.shape, 6) + rates[10:]
    return rate, d_rate, torch.cat([cos_psi, sin_psi], -1)


_KINEMATIC: dict[tuple, tuple[torch.Tensor, torch.Tensor]] = {}


def _kinematic_tables(like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(6, 7) tangents (columns) of a = (u, v, r, u, u, v, v) and of r in b = (r, r, r, ...)."""
    key = (like.dtype, like.device)
    found = _KINEMATIC.get(key)
    if found is None:
        with torch.inference_mode(False), torch.no_grad():
            E = torch.eye(6, dtype=like.dtype, device=like.device)
            r_in_b = torch.zeros(6, 7, dtype=like.dtype, device=like.device)
            r_in_b[5, :3] = 1.0
            found = _KINEMATIC[key] = (E[:, [1, 3, 5, 1, 1, 3, 3]].clone(), r_in_b)
    return found


def rate_with_jacobian(state: torch.Tensor, inputs: torch.Tensor, c, wind: bool = True):
    """(out (..., 18) as `mmg_rate` returns it, its Jacobian (..., 6, 18): entry [i, j] is
    d out_j / d state_i), without autograd: through the native kernel where it applies
    (`sysid.mmg.native.applies`), else through torch (`sysid.mmg.tangents`)."""
    if native.applies(state, inputs, c):
        return native.rate_with_jacobian(state, inputs, c, wind)
    t = forces_with_tangents(state, inputs, c, wind)
    rate, d_rate, cos_sin = _rate_with_tangents(state, t.force, t.d_force, c)
    _, u, _, v, _, r = state.split_with_sizes([1] * 6, -1)
    n, delta = inputs[..., :1], inputs[..., 1:2]
    s = torch.cat([u, v, r, delta, n, t.omega, cos_sin], -1)
    B = basis(state)
    d_trig = B.E[:, 4:5] * torch.cat([-cos_sin[..., 1:], cos_sin[..., :1]], -1).unsqueeze(-2)   # (..., 6, 2)
    batch = state.shape[:-1]
    jacobian = torch.cat([d_rate, t.d_force, _first_inputs(state).expand(*batch, 6, 5), t.d_omega, d_trig], -1)
    return torch.cat([rate, t.force, s], -1), jacobian


_FIRST: dict[tuple, torch.Tensor] = {}


def _first_inputs(like: torch.Tensor) -> torch.Tensor:
    """(6, 5) tangents (columns) of the FNN inputs u, v_m, r, delta, n_p."""
    key = (like.dtype, like.device)
    found = _FIRST.get(key)
    if found is None:
        with torch.inference_mode(False), torch.no_grad():
            E = torch.eye(6, dtype=like.dtype, device=like.device)
            found = _FIRST[key] = torch.cat([E[:, [1, 3, 5]], torch.zeros(6, 2, dtype=like.dtype, device=like.device)], -1)
    return found


class _MMGRate(torch.autograd.Function):
    """(state, inputs) -> (..., 18); backward: the output's gradient times the Jacobian."""

    @staticmethod
    def forward(ctx, state, inputs, c, wind):
        out, jacobian = rate_with_jacobian(state, inputs, c, wind)
        ctx.save_for_backward(jacobian)
        return out

    @staticmethod
    def backward(ctx, grad):
        (jacobian,) = ctx.saved_tensors
        return torch.matmul(jacobian, grad.unsqueeze(-1)).squeeze(-1), None, None, None


def mmg_rate(state: torch.Tensor, inputs: torch.Tensor, c, wind: bool = True) -> torch.Tensor:
    """(..., 18) = (dx/dt of F_MMG (6), F_MMG (3), the FNN's inputs s (9)) at state (..., 6)
    with inputs (..., 4) (see the module docstring); differentiable with respect to the
    state by its hand-derived VJP. `c` is the coefficients' values view (constants), `wind`
    adds Fujiwara's wind force."""
    return _MMGRate.apply(state, inputs, c, wind)


class _NativeTrainingRate(torch.autograd.Function):
    """(state, inputs) -> (dx/dt of F_MMG, F_MMG, z) by the native kernel; backward: the
    outputs' gradients times the Jacobian, by the kernel too."""

    @staticmethod
    def forward(ctx, state, inputs, c, families, mean, std):
        ctx.set_materialize_grads(False)
        rate, force, z, jacobian = native.training_rate(state, inputs, c, families, mean, std)
        ctx.save_for_backward(jacobian)
        return rate, force, z

    @staticmethod
    def backward(ctx, grad_rate, grad_force, grad_z):
        (jacobian,) = ctx.saved_tensors
        return native.state_gradient(jacobian, grad_rate, grad_force, grad_z), None, None, None, None, None


def training_rate(state: torch.Tensor, inputs: torch.Tensor, c, families: int, mean: torch.Tensor,
                  std: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(dx/dt of F_MMG (..., 6), F_MMG (..., 3), the FNN's standardised inputs z = (s - mean)
    / std (..., 9), Eq. 8) at state (..., 6) with inputs (..., 4), differentiable with respect
    to the state by the hand-derived VJP: one call of the native kernel forward and one
    backward where it applies (`sysid.mmg.native.applies`; `mean`, `std` (9,) in the state's
    dtype), else `mmg_rate` and the standardisation in torch. `families`: the kernel's
    `sysid.mmg.native.Families` (a bool: the Esso Osaka's, with or without wind); the torch
    path computes the Esso Osaka's only."""
    if mean.dtype == state.dtype == std.dtype and native.applies(state, inputs, c, differentiated=True):
        return _NativeTrainingRate.apply(state, inputs, c, families, mean, std)
    if int(families) & ~int(native.Families.WIND):
        raise ValueError(f"families {native.Families(int(families))!r}: the torch path computes the Esso Osaka's "
                         "only (call where `sysid.mmg.native.applies` holds)")
    rate, force, s = mmg_rate(state, inputs, c, bool(families)).split_with_sizes((6, 3, 9), -1)
    return rate, force, (s.to(mean.dtype) - mean) / std



class _IdentifiedRate(torch.autograd.Function):
    """(state, inputs, theta (k,)) -> dx/dt (..., 6); backward: the state's gradient (the
    Jacobian (..., 6, 6) times the output's gradient) and theta's (the sum over rows of each
    coefficient's hull product times the output's gradient along its slope, `identified_rate`)."""

    @staticmethod
    def forward(ctx, state, inputs, theta, c, wind, columns, slope):
        out, jacobian = rate_with_jacobian(state, inputs, c, wind)
        _, u, _, v, _, r = state.split_with_sizes([1] * 6, -1)
        u_abs = u.abs()
        products = torch.cat([v, v, v, r, r], -1) * torch.cat([u, u_abs, r, u, u_abs], -1)   # (..., 5)
        ctx.save_for_backward(jacobian[..., :6], products[..., list(columns)], slope)
        return out[..., :6]

    @staticmethod
    def backward(ctx, grad):
        jacobian, products, slope = ctx.saved_tensors
        grad_state = torch.matmul(jacobian, grad.unsqueeze(-1)).squeeze(-1) if ctx.needs_input_grad[0] else None
        grad_theta = None
        if ctx.needs_input_grad[2]:
            k = slope.shape[0]  # d rate / d theta_j = products_j slope_j (6,)
            grad_theta = (products.reshape(-1, k) * (grad.reshape(-1, 6) @ slope.T)).sum(0)
        return grad_state, None, grad_theta, None, None, None, None


def _slopes(c, names: tuple, like: torch.Tensor) -> torch.Tensor:
    """(k, 6): d(dx/dt) / d theta_j per unit of coefficient j's hull product: its term's other
    factors (q, L_pp, `HULL_LINEAR`) times the mass terms' row of its force component."""
    factors = coefficient_vector(c, tuple(HULL_LINEAR[n][2] for n in names), like)     # (k,)
    rows = force_rate(c, like)[[HULL_LINEAR[n][1] for n in names]]                   # (k, 6)
    return factors.unsqueeze(-1) * rows


def _reading(names: tuple, families: int) -> tuple[list[int], tuple]:
    """The places in the native kernel's coefficient vector (`sysid.mmg.native.SEGMENTS`) of
    the entries that read one of `names`, and those entries."""
    places, entries, offset = [], [], 0
    for segment in native.SEGMENTS:
        for entry in segment.entries():
            read = entry if isinstance(entry, tuple) else (entry,)
            if segment.used(families) and any(n in read for n in names):
                places.append(offset)
                entries.append(entry)
            offset += 1
    return places, tuple(entries)


_F64 = torch.empty((), dtype=torch.float64)


def _constants_of(live: SimpleNamespace, names: tuple, families: int, like: torch.Tensor):
    """(the values view `live` as constants, the slopes (k, 6) of `_slopes`): `live`'s entries
    with the trainable values detached and a copy of its constant vectors' cache (vectors
    reading a trainable value are made anew in the copy). `live`'s cache, shared by the values
    views until a constant changes, also keeps the slopes and the native kernel's coefficient
    vector, of which only the entries reading a trainable value are made anew (the same
    products as `sysid.mmg.native.coefficient_values` makes)."""
    kept = live.__dict__.get("_vectors")
    c = SimpleNamespace(**live.__dict__)
    for n in names:
        setattr(c, n, getattr(live, n).detach())
    c.requires_grad = False
    c._vectors = dict(kept) if kept is not None else {}
    c.__dict__.pop("_native", None)
    if kept is None:
        return c, _slopes(c, names, like)
    key = ("identified", names, families, like.dtype)
    found = kept.get(key)
    if found is None:
        slope = _slopes(c, names, like)
        base = native.coefficient_values(c, families) if native.available() else None
        kept[key] = (slope, base, *_reading(names, families))
        return c, slope
    slope, base, places, entries = found
    if base is not None:
        vector = base.clone()
        vector[places] = coefficient_vector(c, entries, _F64).detach().to(torch.float64)
        c._native = {int(families): vector}
    return c, slope


def identified_rate(mmg, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor | None:
    """dx/dt (..., 6) of the `MMG` `mmg` at state (..., 6) with inputs (..., 4) through
    `_IdentifiedRate` (the native kernel's or `sysid.mmg.tangents`' values, autograd's to
    round-off), differentiable with respect to the state and the identified coefficients;
    None where it does not apply (then `MMG` runs through autograd): no gradient recorded,
    a family other than `FAMILIES`' or Simpson's quadrature, a trainable coefficient that is
    not one of `HULL_LINEAR` (or none), a torch.func transform or swapped-in coefficients,
    compiled-code capture, or tensors other than the CPU's float32/64."""
    coefficients = mmg.coefficients
    names = tuple(getattr(coefficients, "trainable_names", ()))
    if not torch.is_grad_enabled() or not names or any(n not in HULL_LINEAR for n in names):
        return None
    models = mmg.ship.models
    if any(models.get(k) != v for k, v in FAMILIES.items() if k != "wind") or \
            models.get("wind") not in (None, FAMILIES["wind"]) or mmg.quadrature != "exact":
        return None
    if captured() or transformed(state) or transformed(inputs) or state.device.type != "cpu" or \
            state.dtype not in (torch.float32, torch.float64) or inputs.dtype != state.dtype:
        return None
    live = coefficients.values_view(state.dtype)   # the trainable values through autograd
    if getattr(live, "wrapped", False) or not getattr(live, "requires_grad", False):
        return None
    theta = torch.stack([getattr(live, n) for n in names])
    if transformed(theta):
        return None
    wind = models.get("wind") is not None
    with torch.no_grad():
        c, slope = _constants_of(live, names, int(native.Families.WIND) if wind else 0, state)
    columns = tuple(HULL_LINEAR[n][0] for n in names)
    return _IdentifiedRate.apply(state, inputs, theta, c, wind, columns, slope)
