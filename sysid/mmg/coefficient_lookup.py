"""Coefficient values as vectors and matrices for the force products: looked up from a
values view (`sysid.mmg.coefficients.Coefficients.values_view`) in the states' dtype and
device, cached in the view while every value is a constant.

Kept apart from `sysid.mmg.coefficients` (which reads ship definitions) so that the force
families import it without importing the ship-file layer.
"""
from __future__ import annotations

from types import SimpleNamespace

import torch
from torch._C._functorch import is_functorch_wrapped_tensor


def view_of(c, like: torch.Tensor | None = None) -> SimpleNamespace:
    """`c` as a values view: itself if it is one, else its ``values_view`` (a
    `Coefficients` or `PackedCoefficients`) for states like `like`."""
    return c if type(c) is SimpleNamespace else c.values_view(None if like is None else like.dtype)


def _cached(c, names, like: torch.Tensor) -> torch.Tensor | None:
    """The vector or matrix of `names` (a module-level tuple: keyed by its identity) cached
    in the values view `c` for `like`'s dtype and device, or None."""
    if type(c) is not SimpleNamespace:
        return None
    found = c.__dict__.get("_vectors", _EMPTY).get(id(names))
    if found is not None and found[0] is names and found[1] is like.dtype and found[2] == like.get_device():
        return found[3]
    return None


_EMPTY: dict = {}


def coefficient_vector(c: SimpleNamespace, names: tuple, like: torch.Tensor) -> torch.Tensor:
    """(k,) the values of `names` in `like`'s dtype and device (a name may be a tuple of
    names: their product, in that order; None: 0; a float: itself): one tensor, cached in the view while
    every value is a constant (keyed by the identity of `names`, a constant tuple); stacked
    anew (through autograd) otherwise."""
    found = _cached(c, names, like)
    if found is not None:
        return found
    compiling = torch.compiler.is_compiling()
    zero = torch.zeros((), dtype=like.dtype, device=like.device)

    def value(name):
        if name is None:
            return zero
        if isinstance(name, float):
            return torch.full((), name, dtype=like.dtype, device=like.device)  # an op, not a lifted constant
        if isinstance(name, tuple):
            out = value(name[0])
            for other in name[1:]:
                out = out * value(other)
            return out
        return torch.as_tensor(getattr(c, name), device=like.device).to(like.dtype)
    values = [value(n) for n in names]
    stacked = torch.stack(values)
    # only plain constants are kept (a traced value, e.g. under torch.export, never is)
    if (not compiling and type(stacked) is torch.Tensor
            and not any(v.requires_grad or is_functorch_wrapped_tensor(v) for v in values)):
        _keep(c, names, like, stacked)
    return stacked


def _keep(c, names, like: torch.Tensor, value: torch.Tensor) -> None:
    if type(c) is SimpleNamespace:
        cache = c.__dict__.setdefault("_vectors", {})
        if len(cache) > 512:  # names built anew per call (not module constants): keep none
            cache.clear()
        cache[id(names)] = (names, like.dtype, like.get_device(), value)


def coefficient_matrix(c: SimpleNamespace, rows: tuple, like: torch.Tensor) -> torch.Tensor:
    """(k, m) from k rows of m names (as `coefficient_vector`), cached alike."""
    found = _cached(c, rows, like)
    if found is not None:
        return found
    flat = coefficient_vector(c, tuple(n for row in rows for n in row), like).view(len(rows), -1)
    if not torch.compiler.is_compiling() and type(flat) is torch.Tensor and not flat.requires_grad \
            and not is_functorch_wrapped_tensor(flat):
        _keep(c, rows, like, flat)
    return flat


class Rows(tuple):
    """Rows of names: a matrix in `coefficient_vectors` (see `coefficient_matrix`)."""


def coefficient_vectors(c: SimpleNamespace, groups: tuple, like: torch.Tensor) -> tuple:
    """`coefficient_vector` of each names tuple of `groups` (a module-level tuple;
    `coefficient_matrix` of each `Rows`), cached together: one look-up for all."""
    found = _cached(c, groups, like)
    if found is not None:
        return found
    vectors = tuple(coefficient_matrix(c, names, like) if isinstance(names, Rows) else
                    coefficient_vector(c, names, like) for names in groups)
    if not torch.compiler.is_compiling() and all(type(v) is torch.Tensor and not v.requires_grad
                                                 and not is_functorch_wrapped_tensor(v) for v in vectors):
        _keep(c, groups, like, vectors)
    return vectors
