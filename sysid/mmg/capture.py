"""How a forward is being run, which decides the force model's caches and guard forms.

Two questions the physics asks, answered without private torch API or compiler queries:

- `captured()`: the forward is being captured for compiled code. `sysid.fast` (the compiled
  path, `sysid.fast.compiled.export_program`) says so by running the capture inside
  `capturing()`; the force model then makes its constants by operations of the traced code,
  caches nothing and keeps the guards' gradient-safe forms.
- `transformed(t)`: the tensor t is wrapped by a `torch.func` transform (``jacfwd``, ``vmap``,
  ``jvp``): a derivative passes through it, so it is never cached and the guards keep their
  gradient-safe forms.
"""
from __future__ import annotations

import contextlib
from typing import Iterator

import torch
from torch.func import debug_unwrap

_capturing = [False]  # one flag, set only inside `capturing`


def captured() -> bool:
    """True inside `capturing` (a forward captured for compiled code)."""
    return _capturing[0]


@contextlib.contextmanager
def capturing() -> Iterator[None]:
    """Mark the forwards run inside as captured for compiled code (`captured`)."""
    before = _capturing[0]
    _capturing[0] = True
    try:
        yield
    finally:
        _capturing[0] = before


def transformed(t: torch.Tensor) -> bool:
    """True where a `torch.func` transform has wrapped `t` (it is not its own unwrapped tensor)."""
    return debug_unwrap(t, recurse=False) is not t
