"""torchdiffeq's public `odeint`, imported without loading scipy.

torchdiffeq imports ``scipy.integrate`` at its top level for one solver of its table,
``method="scipy_solver"`` (its module ``torchdiffeq._impl.scipy_wrapper``); with
scipy.optimize, scipy.special and scipy.linalg that is about 0.4 s CPU per process, and sysid
integrates with torchdiffeq's "euler" and "rk4" only. torchdiffeq is imported here with that
one module standing in for a class (`_DeferredScipySolver`) that imports the real solver, and
scipy with it, when it is constructed: ``method="scipy_solver"`` still works, every other
solver is torchdiffeq's own code, unchanged. Where torchdiffeq is imported already, or a
version of it imports something else from that module, it is imported as it is.
"""
from __future__ import annotations

import importlib
import sys
import types

__all__ = ["odeint"]

_SCIPY_WRAPPER = "torchdiffeq._impl.scipy_wrapper"


def _scipy_solver() -> type:
    """torchdiffeq's ``ScipyWrapperODESolver`` (its module, and scipy, imported now)."""
    return importlib.import_module(_SCIPY_WRAPPER).ScipyWrapperODESolver


class _Deferred(type):
    def __getattr__(cls, name: str):  # class attributes (``valid_callbacks``) are the real class's
        return getattr(_scipy_solver(), name)


class _DeferredScipySolver(metaclass=_Deferred):
    """torchdiffeq's ``ScipyWrapperODESolver`` in its solver table: constructing it, or reading an
    attribute of the class, imports the real one."""

    def __new__(cls, *args, **kwargs):
        return _scipy_solver()(*args, **kwargs)


def _import_torchdiffeq() -> types.ModuleType:
    """torchdiffeq, imported with `_DeferredScipySolver` in its scipy wrapper's place when not
    imported yet."""
    if "torchdiffeq" in sys.modules or _SCIPY_WRAPPER in sys.modules:
        return importlib.import_module("torchdiffeq")
    stand_in = types.ModuleType(_SCIPY_WRAPPER)
    stand_in.ScipyWrapperODESolver = _DeferredScipySolver  # type: ignore[attr-defined]
    sys.modules[_SCIPY_WRAPPER] = stand_in
    try:
        return importlib.import_module("torchdiffeq")
    except ImportError:  # a torchdiffeq that needs more of the module: imported as it is
        for name in [m for m in sys.modules if m == "torchdiffeq" or m.startswith("torchdiffeq.")]:
            del sys.modules[name]
        sys.modules.pop(_SCIPY_WRAPPER, None)
        return importlib.import_module("torchdiffeq")
    finally:
        # later imports of the module (the deferred class's) load the real one
        if sys.modules.get(_SCIPY_WRAPPER) is stand_in:
            del sys.modules[_SCIPY_WRAPPER]


odeint = _import_torchdiffeq().odeint
