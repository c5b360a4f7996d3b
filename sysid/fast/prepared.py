"""A force model prepared for compilation: the same numbers, shaped for compiled code.

`prepared(model, batch)` returns a shallow copy (the model itself is untouched) whose MMG
coefficients are packed into one tensor (`sysid.mmg.coefficients.PackedCoefficients`: one
constant instead of about a hundred, which a compiled loop would otherwise pass on every
step) and whose fitted kNN gate is an `IndexedGate` (`sysid.fast.knn_index.with_indexed_gate`);
the members of an ensemble are prepared each.
"""
from __future__ import annotations

import copy

from torch import nn

from sysid.fast.knn_index import with_indexed_gate
from sysid.mmg.model import MMG
from sysid.mmg.coefficients import Coefficients, PackedCoefficients


def _with_module(module: nn.Module, name: str, replacement: nn.Module) -> nn.Module:
    """A shallow copy of `module` with its submodule `name` replaced."""
    out = copy.copy(module)
    out._modules = dict(module._modules)
    out._modules[name] = replacement
    return out


def packed(model: nn.Module) -> nn.Module:
    """`model` (an MMG, or a model holding one as ``mmg``) with packed coefficients."""
    if isinstance(model, MMG) and isinstance(model.coefficients, Coefficients):
        return _with_module(model, "coefficients", PackedCoefficients(model.coefficients))
    mmg = getattr(model, "mmg", None)
    if isinstance(mmg, MMG):
        return _with_module(model, "mmg", packed(mmg))
    return model


def prepared(model: nn.Module, batch: int) -> nn.Module:
    """`model` ready to compile for `batch` rows: packed coefficients, indexed kNN gate; a
    mean-of-members ensemble (``members``) with each member prepared."""
    members = getattr(model, "members", None)
    if isinstance(members, nn.ModuleList):
        return _with_module(model, "members", nn.ModuleList([prepared(m, batch) for m in members]))
    return packed(with_indexed_gate(model, batch))


def indexed(model: nn.Module, batch: int, anchored: bool = False) -> nn.Module:
    """`model` with its fitted kNN gate (each member's, for an ensemble) replaced by an
    `IndexedGate` for `batch` rows, coefficients as they are: what eager steps run (the
    same decisions; packed coefficients only pay inside compiled code). `anchored`: each
    gate a fresh `sysid.fast.knn_index.AnchoredGate` (the eager steps of one rollout)."""
    members = getattr(model, "members", None)
    if isinstance(members, nn.ModuleList):
        return _with_module(model, "members", nn.ModuleList([indexed(m, batch, anchored) for m in members]))
    return with_indexed_gate(model, batch, anchored)
