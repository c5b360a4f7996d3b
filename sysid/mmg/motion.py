"""The state and inputs one MMG forward reads, and the speed terms several force families share.

`Motion` is computed once per forward (`motion_of`): the body velocities, heading and inputs
as (...,) channels, the speed U = hypot(u, v) [m/s] with the simulator's low-speed guard, the
drift angle, and the forward's constants (`constants`: 0-d tensors in the states' dtype,
made once per dtype and device, so no Python float becomes a tensor inside a forward).
"""
from __future__ import annotations

import math
from typing import NamedTuple, TypeVar

import torch
from torch._C._functorch import is_functorch_wrapped_tensor

from sysid.mmg.guards import SPEED_GUARD, TINY, safe_atan2

LOW_SPEED = 1e-7  # m/s, the simulator's U below the speed guard

class Constants(NamedTuple):
    """The constants a forward compares or selects with, as tensors (see `constants`)."""

    zero: torch.Tensor
    one: torch.Tensor
    tiny: torch.Tensor           # TINY, the simulator's machine-epsilon guard
    minus_tiny: torch.Tensor
    speed_guard: torch.Tensor    # m/s, SPEED_GUARD
    low_speed: torch.Tensor      # m/s, LOW_SPEED
    stopped_ratio: torch.Tensor  # -, J_s at n = 0 (times sign(u))
    two_pi: torch.Tensor
    minus_four: torch.Tensor
    cos_sin_phase: torch.Tensor  # (2,) = (pi/2, 0): (cos x, sin x) = sin(x + phase)


_VALUES = Constants(0.0, 1.0, TINY, -TINY, SPEED_GUARD, LOW_SPEED, 1e4, 2.0 * math.pi, -4.0, (0.5 * math.pi, 0.0))


def _made(value, like: torch.Tensor) -> torch.Tensor:
    """`value` (a float or a tuple of floats) as a tensor by operations (no tensor constant)."""
    if isinstance(value, tuple):
        return torch.stack([_made(v, like) for v in value])
    return torch.full((), value, dtype=like.dtype, device=like.device)


_TENSORS: dict[tuple, Constants] = {}


def constants(like: torch.Tensor) -> Constants:
    """The forward's `Constants` as tensors of `like`'s dtype and device: made once, or,
    while compiling, by operations of the traced code (never lifted tensor constants)."""
    if torch.compiler.is_compiling():
        return Constants(*[_made(value, like) for value in _VALUES])
    key = (like.dtype, like.device)
    found = _TENSORS.get(key)
    if found is None:
        with torch.inference_mode(False), torch.no_grad():
            found = Constants(*[torch.tensor(value, dtype=like.dtype, device=like.device) for value in _VALUES])
        _TENSORS[key] = found
    return found


class Motion(NamedTuple):
    """One forward's channels, each (..., 1) (a lane each: products with (k,) coefficient
    vectors give (..., k) lanes without reshaping): u, v [m/s] (midship), r [rad/s],
    psi [rad], n [rps], delta [rad], U_T [m/s], zeta [rad] (None where a caller has no such
    input), and what several families derive from them."""

    u: torch.Tensor
    v: torch.Tensor
    r: torch.Tensor
    psi: torch.Tensor | None
    n: torch.Tensor | None
    delta: torch.Tensor | None
    U_T: torch.Tensor | None
    zeta: torch.Tensor | None
    U: torch.Tensor          # m/s, hypot(u, v)
    slow: torch.Tensor       # U < SPEED_GUARD
    U_guarded: torch.Tensor  # m/s, U, or LOW_SPEED below the guard
    beta_hat: torch.Tensor   # rad, atan2(v, u) in (-pi, pi] (= -beta; 0 at rest)
    k: Constants             # `constants` of the states' dtype
    smooth: bool             # a derivative may pass: the guards' gradient-safe forms


def needs_smooth(c, *tensors) -> bool:
    """True where a derivative may pass through the forward (compiling, a functorch
    transform, or autograd on a state, input or coefficient): the guards' gradient-safe
    forms are used then; otherwise their plain forms (the same values, fewer operations)."""
    if torch.compiler.is_compiling() or getattr(c, "wrapped", False):
        return True
    grad = torch.is_grad_enabled()
    if grad and getattr(c, "requires_grad", False):
        return True
    for t in tensors:
        if t is not None and ((grad and t.requires_grad) or is_functorch_wrapped_tensor(t)):
            return True
    return False


def motion_from(u, v, r, c, n=None, delta=None, psi=None, U_T=None, zeta=None,
                smooth: bool | None = None) -> Motion:
    """`Motion` from separate channels, each (..., 1); `c` is a values view (for
    `needs_smooth`, unless `smooth` is given)."""
    k = constants(u)
    if smooth is None:
        smooth = needs_smooth(c, u, v, r, n, delta, psi, U_T, zeta)
    U = torch.hypot(u, v)
    slow = U < k.speed_guard
    beta_hat = safe_atan2(v, u) if smooth else torch.atan2(v, u)
    return Motion(u, v, r, psi, n, delta, U_T, zeta, U, slow, torch.where(slow, k.low_speed, U),
                  beta_hat, k, smooth)


_SIX, _FOUR, _TWO = [1] * 6, [1] * 4, [1] * 2
_Named = TypeVar("_Named", bound=tuple)  # a named tuple of tensors (or None)


def motion_of(state: torch.Tensor, inputs: torch.Tensor, c) -> Motion:
    """`Motion` of state (..., 6) = (x, u, y, v, psi, r) and inputs (..., 4) = (n, delta,
    U_T, zeta)."""
    _, u, _, v, psi, r = state.split_with_sizes(_SIX, -1)  # (split(1) costs twice as much)
    n, delta, U_T, zeta = inputs.split_with_sizes(_FOUR, -1)
    return motion_from(u, v, r, c, n, delta, psi, U_T, zeta, needs_smooth(c, state, inputs))


def motion_of_channels(u, v, r, c, n=None, delta=None, psi=None, U_T=None, zeta=None) -> Motion:
    """`Motion` from channels (...,) (the functions of the public interface)."""
    lane = lambda x: None if x is None else x[..., None]  # noqa: E731
    return motion_from(lane(u), lane(v), lane(r), c, lane(n), lane(delta), lane(psi), lane(U_T), lane(zeta))


def as_lanes(values: _Named) -> _Named:
    """A named tuple of (...,) tensors (or None) as (..., 1) lanes."""
    return type(values)(*(None if x is None else x[..., None] for x in values))


def as_channels(values: _Named) -> _Named:
    """A named tuple of (..., 1) lanes (or None) as (...,) channels."""
    return type(values)(*(None if x is None else x.squeeze(-1) for x in values))
