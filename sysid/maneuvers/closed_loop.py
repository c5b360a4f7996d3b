"""The ship under maneuver orders, step by step: eager (batched over maneuvers) or as one
compiled loop (cached on disk, compiled once per model and integration rule).

`ClosedLoopStep` asks `ManeuverOrders` for the inputs held over the step (from the state at
its start) and takes one step of the integration rule (`sysid.dynamics.integrators`) on
the model's right-hand side (`sysid.fast.stepper.Derivative`). `ClosedLoopRollout` runs up
to `CAPACITY` such steps in one `while_loop`, writing each step's state, controller state
and inputs, and the kNN gate's decision at its start, into a record in place (as
`sysid.fast.stepper.Rollout` does for recorded inputs); the step dt, the start time and the
maneuver's parameters are inputs, so one compiled package serves every maneuver, dt and
duration of a model.
"""
from __future__ import annotations

import functools
import hashlib
import logging
import math
from pathlib import Path
from typing import Callable

import torch
from torch import nn

from sysid.device import compute_threads
from sysid.dynamics.integrators import STEP_RULES, Method, run_in_chunks, step_loop, while_steps
from sysid.fast.stepper import Derivative
from sysid.maneuvers.controllers import COLUMNS, ManeuverOrders

CAPACITY = 512  # steps per call of the compiled loop
LOOP_ROWS = 8  # maneuvers side by side in one compiled loop (IMO's five and a crash stop fit)
RECORD = 6 + 2 + 4 + 1  # per step: state after it, controller state after it, inputs held over it, gate on
_compiled: dict[str, Callable | None] = {}
_log = logging.getLogger(__name__)


class ClosedLoopStep(nn.Module):
    """``forward(state (B, 6), orders (B, 2), parameters (B, P), t (), dt ())`` -> (state
    after the step (B, 6), orders after it (B, 2), inputs held over it (B, 4), the kNN
    gate's decision at the step's start (B, 1): 1 on, 0 off, NaN for a model without a gate)."""

    def __init__(self, force_model: nn.Module, method: Method, rate: Callable | None = None,
                 held: Callable | None = None):
        super().__init__()
        self.derivative = Derivative(force_model)
        self.orders = ManeuverOrders()
        self.method = method
        # eager only, looked up once: (state, inputs) -> (dx/dt, the gate's decision or None);
        # (state, orders, t) -> `orders`' outputs for the loop's parameters and dt (`ManeuverOrders.held`)
        self.rate = rate
        self.held = held

    def forward(self, state, orders, parameters, t, dt):
        if self.held is not None:
            inputs, after = self.held(state, orders, t)
        else:
            inputs, after = self.orders(state, orders, parameters, t, dt)
        first: list = []  # the gate's decision at the step's start, from the rule's first stage

        def rate(x):
            if self.rate is not None:
                dx, on = self.rate(x, inputs)
            elif first:
                return self.derivative(x, inputs)
            else:
                dx, on = self.derivative.with_gate(x, inputs)
            if not first:
                first.append(on)
            return dx

        following = STEP_RULES[self.method](rate, state, dt)
        on = first[0]
        gate = torch.full_like(state[:, :1], math.nan) if on is None else on.to(state.dtype)[:, None]
        return following, after, inputs, gate


class ClosedLoopRollout(nn.Module):
    """Up to `capacity` closed-loop steps in one call.

    ``forward(x0 (B, 6), orders0 (B, 2), parameters (B, P), t0 (), dt (), steps () int64)``
    returns the record (capacity, B, `RECORD`) of steps 1..steps (rows from `steps` on are
    zero) and the last state; `source` (a digest of the controller's code) is part of the
    compiled package's cache key.
    """

    def __init__(self, step: ClosedLoopStep, capacity: int, source: str):
        super().__init__()
        self.step = step
        self.capacity = int(capacity)
        self.source = source

    def forward(self, x0, orders0, parameters, t0, dt, steps):
        record = torch.zeros((self.capacity, x0.shape[0], RECORD), dtype=x0.dtype, device=x0.device)

        def advance(k, x, o):
            x, o, u, g = self.step(x, o, parameters, t0 + k.to(x.dtype) * dt, dt)
            return torch.cat((x, o, u, g), -1), x, o

        last = while_steps(advance, record, (x0, orders0), steps)[1]
        return record, last


@functools.lru_cache(maxsize=None)
def source_digest() -> str:
    """sha256 of the controller and loop code (a compiled loop is rebuilt when it changes)."""
    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for name in ("controllers.py", "closed_loop.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()[:16]


def run_eager(model: nn.Module, x0: torch.Tensor, orders0: torch.Tensor, parameters: torch.Tensor,
              steps: int, dt: float, method: Method) -> torch.Tensor:
    """Record (steps, B, `RECORD`) of `steps` closed-loop steps of all B maneuvers at once
    (`sysid.dynamics.integrators.step_loop`); the kNN gate decides through its leaf index,
    each call first from a bound kept from the call before (`sysid.fast.knn_index.AnchoredGate`);
    the right-hand side is the model's ``no_grad_rate`` where it has one that applies (the
    native kernel's MMG, `sysid.mmg.native`: the same numbers to round-off)."""
    from sysid.fast.prepared import indexed  # the gate's leaf index
    model = indexed(model, x0.shape[0], anchored=True)
    no_grad_rate = getattr(model, "no_grad_rate", None)  # the native kernel's MMG, looked up once
    dt_t = torch.tensor(dt, dtype=x0.dtype)
    step = ClosedLoopStep(model, method, no_grad_rate(x0) if no_grad_rate is not None else None,
                          ManeuverOrders.held(parameters, dt_t))

    def advance(k: int, carry: tuple[torch.Tensor, torch.Tensor]) -> tuple[torch.Tensor, tuple]:
        x, o, u, g = step(carry[0], carry[1], parameters, dt_t * k, dt_t)
        return torch.cat((x, o, u, g), -1), (x, o)
    with torch.no_grad(), compute_threads(1):  # a few rows a step: dispatch, which more threads only slow
        return torch.stack(step_loop(advance, (x0, orders0), steps))


def _notice(message: str) -> None:
    """One stage line of the `sysid` log (`sysid.logs`) when a loop is compiled (not the
    line when it is done)."""
    if "compiling" in message:
        _log.info(message)


def _loop_module(model: nn.Module, method: Method, dtype: torch.dtype):
    """(the `ClosedLoopRollout` compiled for `LOOP_ROWS` maneuvers, its example inputs, label)."""
    from sysid.fast.prepared import prepared
    module = ClosedLoopRollout(ClosedLoopStep(prepared(model, LOOP_ROWS), method), CAPACITY, source_digest())
    rows = LOOP_ROWS
    examples = (torch.zeros(rows, 6, dtype=dtype), torch.zeros(rows, 2, dtype=dtype),
                torch.zeros(rows, len(COLUMNS), dtype=dtype), torch.zeros((), dtype=dtype),
                torch.full((), 0.1, dtype=dtype), torch.tensor(CAPACITY, dtype=torch.int64))
    return module, examples, f"maneuver-{method.name.lower()}"


def loop_is_cached(model: nn.Module, method: Method, dtype: torch.dtype = torch.float64) -> bool:
    """True when `compiled_loop` would not compile: the loop is in this process's memory or
    in the disk cache (a warm start)."""
    from sysid.fast.compiled import fingerprint, package_path
    module, examples, label = _loop_module(model, method, dtype)
    key = fingerprint(module, examples)
    return _compiled.get(key) is not None or package_path(module, examples, label).is_file()


def compiled_loop(model: nn.Module, method: Method, dtype: torch.dtype = torch.float64
                  ) -> Callable[..., torch.Tensor] | None:
    """The compiled `ClosedLoopRollout` of `model` for up to `LOOP_ROWS` maneuvers side by
    side, from this process's memory, the disk cache, or compiled now (one notice line);
    None where compilation is off or fails (the caller runs `run_eager`)."""
    from sysid.fast.compiled import compile_cached, fingerprint  # the compiled path: only where it is chosen
    module, examples, label = _loop_module(model, method, dtype)
    key = fingerprint(module, examples)
    if key not in _compiled:
        _compiled[key] = compile_cached(module, examples, label, log=_notice)
    return _compiled[key]


def run_compiled(loop: Callable[..., torch.Tensor], x0: torch.Tensor, orders0: torch.Tensor,
                 parameters: torch.Tensor, steps: int, dt: float) -> torch.Tensor:
    """Record (steps, B, `RECORD`) of B maneuvers through a compiled loop: `LOOP_ROWS` of
    them side by side (the last group padded with copies of its first row), `CAPACITY`
    steps per call, each call from the last state and controller state of the one before."""
    groups = []
    for lo in range(0, x0.shape[0], LOOP_ROWS):
        rows = [t[lo:lo + LOOP_ROWS] for t in (x0, orders0, parameters)]
        n = rows[0].shape[0]
        if n < LOOP_ROWS:
            rows = [torch.cat((t, t[:1].expand(LOOP_ROWS - n, -1))) for t in rows]
        groups.append(_run_group(loop, rows[0], rows[1], rows[2], steps, dt)[:, :n])
    return torch.cat(groups, 1)


def _run_group(loop, x0, orders0, parameters, steps: int, dt: float) -> torch.Tensor:
    """Record (steps, LOOP_ROWS, `RECORD`) of one group through calls of `CAPACITY` steps
    (`sysid.dynamics.integrators.run_in_chunks`)."""
    dt_t = torch.tensor(dt, dtype=x0.dtype)

    def call(carry, done: int, n: int):
        rec = loop(carry[0], carry[1], parameters, dt_t * done, dt_t, torch.tensor(n, dtype=torch.int64))[:n]
        return rec, (rec[-1, :, :6], rec[-1, :, 6:8])
    return run_in_chunks(call, (x0, orders0), steps, CAPACITY)
