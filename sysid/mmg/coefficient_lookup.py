"""Coefficient values as vectors and matrices for the force products: looked up from a
values view (`sysid.mmg.coefficients.Coefficients.values_view`) in the states' dtype and
device, cached in the view while every value is a constant (never while a forward is
captured for compiled code or a value is wrapped by a `torch.func` transform:
`sysid.mmg.capture`).

Kept apart from `sysid.mmg.coefficients` (which reads ship definitions) so that the force
families import it without importing the ship-file layer.
"""
from __future__ import annotations

from types import SimpleNamespace

import torch

from sysid.mmg.capture import captured, transformed


def view_of(c, like: torch.Tensor | None = None) -> SimpleNamespace:
    """`c` as a values view: itself if it is one, else its ``values_view`` (a
    `Coefficients` or `PackedCoefficients`) for states like `like`."""
    return c if type(c) is SimpleNamespace else c.values_view(None if like is None else like.dtype)


def _cached(c, key: tuple, like: torch.Tensor):
    """What is cached under `key` (a look-up's kind and its names) in the values view `c`
    for `like`'s dtype and device, or None."""
    if type(c) is not SimpleNamespace:
        return None
    found = c.__dict__.get("_vectors", _EMPTY).get(key)
    if found is not None and found[0] is like.dtype and found[1] == like.get_device():
        return found[2]
    return None


_EMPTY: dict = {}


def coefficient_vector(c: SimpleNamespace, names: tuple, like: torch.Tensor) -> torch.Tensor:
    """(k,) the values of `names` in `like`'s dtype and device (a name may be a tuple of
    names: their product, in that order; None: 0; a float: itself): one tensor, cached in the view while
    every value is a constant (keyed by `names`); stacked anew (through autograd) otherwise."""
    key = ("vector", names)
    found = _cached(c, key, like)
    if found is not None:
        return found
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
    if (not captured() and type(stacked) is torch.Tensor
            and not any(v.requires_grad or transformed(v) for v in values)):
        _keep(c, key, like, stacked)
    return stacked


def _keep(c, key: tuple, like: torch.Tensor, value) -> None:
    if type(c) is SimpleNamespace:
        cache = c.__dict__.setdefault("_vectors", {})
        if len(cache) > 512:  # names of ever new values (not module constants): keep none
            cache.clear()
        cache[key] = (like.dtype, like.get_device(), value)


def coefficient_matrix(c: SimpleNamespace, rows: tuple, like: torch.Tensor) -> torch.Tensor:
    """(k, m) from k rows of m names (as `coefficient_vector`), cached alike."""
    key = ("matrix", rows)
    found = _cached(c, key, like)
    if found is not None:
        return found
    flat = coefficient_vector(c, tuple(n for row in rows for n in row), like).view(len(rows), -1)
    if not captured() and type(flat) is torch.Tensor and not flat.requires_grad and not transformed(flat):
        _keep(c, key, like, flat)
    return flat


class Rows(tuple):
    """Rows of names: a matrix in `coefficient_vectors` (see `coefficient_matrix`); never
    equal to a plain tuple of the same names (a cache key tells a matrix from products)."""

    def __eq__(self, other):
        return type(other) is Rows and tuple.__eq__(self, other)

    def __ne__(self, other):
        return not self == other

    __hash__ = tuple.__hash__


def coefficient_vectors(c: SimpleNamespace, groups: tuple, like: torch.Tensor) -> tuple:
    """`coefficient_vector` of each names tuple of `groups` (a module-level tuple;
    `coefficient_matrix` of each `Rows`), cached together: one look-up for all."""
    key = ("vectors", groups)
    found = _cached(c, key, like)
    if found is not None:
        return found
    vectors = tuple(coefficient_matrix(c, names, like) if isinstance(names, Rows) else
                    coefficient_vector(c, names, like) for names in groups)
    if not captured() and all(type(v) is torch.Tensor and not v.requires_grad and not transformed(v)
                              for v in vectors):
        _keep(c, key, like, vectors)
    return vectors
