"""Export a trained model for real-time use: one integration step as a ``.pt2`` file.

The file holds ``step(state (B, 6), inputs (B, 4)) -> state dt later`` of an MMG, NN-only
or hybrid model, kNN gate included, with the integration rule and dt fixed. It loads with
torch alone (no sysid, no training code):

- compiled (default): an AOTInductor package, native code, tens of microseconds per step::

      step = torch._inductor.aoti_load_package("model.pt2")
      x = step(x, u)                      # step.get_metadata(): dt, units, frames

  The package checks nothing by default: a tensor of another dtype, another number of rows
  or another memory layout than contiguous (a column of a column-major array, ``.T``) is
  read as if it were the exported one and gives wrong states without an error. With the
  environment variable ``AOTI_RUNTIME_CHECK_INPUTS=1`` (set before the first call) it
  refuses them; `ExportedStep` refuses another dtype or number of rows always and makes
  its inputs contiguous.

- portable (``compiled=False``): a `torch.export` program, any platform and later torch,
  tens of times slower than the package (it checks its inputs' shapes and dtype)::

      step = torch.export.load("model.pt2").module()
      x = step(x, u)                      # torch.export.load(p, extra_files={"sysid.json": ""})

With ``gate=True`` (``sysid export --with-gate``) the file returns the kNN gate's decision
too: ``x, gate_on = step(x, u)``, gate_on (B,) 1 where the FNN acted over the step, 0 where
the state lay outside the training data (`GatedStep`).

`load_step` opens either kind; `ExportedStep.predict` rolls one out over recorded inputs.
"""
from __future__ import annotations

import io
import json
import shutil
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import torch
from torch import nn

from sysid.fast.compiled import (cached_package, export_program, load_package, package_metadata,
                            step_label, step_metadata)
from sysid.config.choices import Method
from sysid.dynamics.integrators import run_steps
from sysid.fast.prepared import prepared
from sysid.dynamics.integrators import STEP_RULES
from sysid.fast.stepper import Derivative, Step
from sysid.store.files import atomic_path
from sysid.errors import DataError

METADATA_FILE = "sysid.json"  # the metadata inside a portable export (extra file)


def _examples(batch: int, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.zeros(batch, 6, dtype=dtype), torch.zeros(batch, 4, dtype=dtype)


PROBE_STEPS = 100
PROBE_SPEED = 20.0  # m/s; no ship model goes faster (`preprocessing.schema.PROCESSED_PLAUSIBLE_ABS`)


def straight_run(batch: int, dtype: torch.dtype, steps: int = PROBE_STEPS) -> tuple[torch.Tensor, torch.Tensor]:
    """A plain run to probe a step with: x0 (B, 6) ahead at 0.4 m/s, and inputs (steps + 1,
    B, 4) held: 10 rps, rudder 0.1 rad, true wind 1 m/s from 0.5 rad."""
    x = torch.tensor([[0.0, 0.4, 0.0, 0.0, 0.0, 0.0]], dtype=dtype).expand(batch, 6).contiguous()
    u = torch.tensor([[10.0, 0.1, 1.0, 0.5]], dtype=dtype).expand(steps + 1, batch, 4).contiguous()
    return x, u


def check_step_stable(step: Callable, batch: int, dtype: torch.dtype, method: Method, dt: float) -> None:
    """`DataError` when `PROBE_STEPS` steps of the straight run leave every ship's speed
    (non-finite, or beyond `PROBE_SPEED`): the explicit step is unstable at this dt."""
    x, u = straight_run(batch, dtype)
    with torch.no_grad():
        speed = run_steps(step, x, u)[..., [1, 3]].abs().amax()
    if not bool(speed <= PROBE_SPEED):  # NaN too
        raise DataError(f"--dt {dt:g} s ({method.value}): {PROBE_STEPS} steps of a straight run at 0.4 m/s "
                        f"reach a speed of {float(speed):.3g} m/s: explicit steps this long are unstable "
                        "for this model; choose a shorter --dt (nothing written)")


class GatedStep(nn.Module):
    """``forward(state (B, 6), inputs (B, 4))`` -> (the state dt later (B, 6), the kNN gate's
    decision at the step's start (B,): 1 where the FNN acts, 0 where the state and inputs lie
    outside the training data (a hybrid's step is its MMG's there, an NN-only model's has no
    force), 1 for a model without a gate). The state is `Step`'s to round-off."""

    def __init__(self, force_model: nn.Module, method: Method, dt: float):
        super().__init__()
        self.derivative = Derivative(force_model)
        self.method = method
        self.dt = float(dt)

    def forward(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        first: list = []   # the gate's decision from the rule's first stage (the step's start)

        def rate(x):
            if first:
                return self.derivative(x, inputs)
            dx, on = self.derivative.with_gate(x, inputs)
            first.append(on)
            return dx
        following = STEP_RULES[self.method](rate, state, self.dt)
        on = first[0]
        return following, torch.ones_like(state[:, 0]) if on is None else on.to(state.dtype)


GATE_OUTPUT = "state after dt (batch, 6), gate_on (batch,): 1 the FNN acted, 0 outside the training data"


def export_model(model: nn.Module, path: str | Path, method: Method = Method.EULER,
                 dt: float = 1.0, batch: int = 1, dtype: torch.dtype = torch.float64,
                 compiled: bool = True, log: Callable[[str], None] | None = None, gate: bool = False) -> Path:
    """Write one integration step of `model` to the ``.pt2`` file `path`.

    Parameters
    ----------
    model : MMG, NN-only or hybrid force model (CPU), kNN gate included (as an
        `IndexedGate`: the same decisions from a pruned scan; coefficients packed, `sysid.fast.prepared`).
    method, dt : the step rule and its length [s] (the paper's: Euler, 1 s); a dt at which
        the step runs a straight run off is refused (`check_step_stable`, `DataError`).
    batch : number of ships per call (shapes are fixed at export).
    dtype : float64 (as evaluated) or float32.
    compiled : AOTInductor package (native, fast; same torch and platform to load) or a
        portable `torch.export` program.
    gate : the file returns the kNN gate's decision beside the state (`GatedStep`).
    """
    path = Path(path)
    step = Step(prepared(model, batch), method, dt)
    check_step_stable(step, batch, dtype, step.method, dt)
    examples = _examples(batch, dtype)
    metadata = step_metadata(model, method, dt, batch, dtype)
    module: nn.Module = step
    label = step_label(method)
    if gate:
        module, label = GatedStep(step.force_model, step.method, dt), f"gated-{label}"
        metadata["outputs"] = GATE_OUTPUT
        metadata["signature"] = metadata["signature"].replace("-> state after dt", "-> (state after dt, gate_on)")
    with atomic_path(path, ".pt2") as tmp:  # a link at `path` is replaced, never written through
        if compiled:
            shutil.copyfile(cached_package(module, examples, label, metadata, log), tmp)
        else:
            metadata["format"] = "torch.export"
            program = io.BytesIO()  # written here, not by torch's native writer (a full disk aborts that)
            torch.export.save(export_program(module, examples), program,
                              extra_files={METADATA_FILE: json.dumps(metadata)})
            tmp.write_bytes(program.getbuffer())
    return path


def is_compiled_package(path: str | Path) -> bool:
    """True for an AOTInductor package, False for a `torch.export` program."""
    with zipfile.ZipFile(path) as z:
        return any("aotinductor" in name for name in z.namelist())


@dataclass
class ExportedStep:
    """An exported step loaded back: ``step(x (B, 6), u (B, 4))``, its metadata, `predict`;
    ``gated`` (a file exported with the gate's decision): ``outputs(x, u)`` -> (state, gate_on)."""

    step: Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
    metadata: dict[str, str]
    outputs_: Callable[[torch.Tensor, torch.Tensor], tuple[torch.Tensor, torch.Tensor]] | None = None

    @property
    def gated(self) -> bool:
        return self.outputs_ is not None

    def outputs(self, state: torch.Tensor, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(state dt later (B, 6), the kNN gate's decision at the step's start (B,), 1/0) of a
        file exported with the gate (`gated`); ValueError otherwise."""
        if self.outputs_ is None:
            raise ValueError("exported step: this file returns the state alone; export it with --with-gate "
                             "(export_model(..., gate=True)) for the kNN gate's decision")
        self.check("state", state, (self.batch, 6))
        self.check("inputs", inputs, (self.batch, 4))
        return self.outputs_(state, inputs)

    @property
    def dt(self) -> float:
        return float(self.metadata["dt_s"])

    @property
    def batch(self) -> int:
        return int(self.metadata.get("batch", 1))

    @property
    def dtype(self) -> torch.dtype:
        return getattr(torch, self.metadata.get("dtype", "float64"))

    def check(self, name: str, tensor: torch.Tensor, shape: tuple[int, ...]) -> None:
        """ValueError unless `tensor` has the `shape` and dtype the file was exported for (a
        compiled package reads any other as if it were, silently; `load_package` makes
        every input contiguous)."""
        if tuple(tensor.shape) != shape or tensor.dtype != self.dtype:
            raise ValueError(f"exported step: {name} is {tuple(tensor.shape)} {str(tensor.dtype)[6:]}; the file "
                             f"takes {shape} {str(self.dtype)[6:]} (its batch and dtype are fixed at export: "
                             "x.to(dtype), or export again with --batch / --float32)")

    def __call__(self, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        """The state (B, 6) dt later from `state` (B, 6) with `inputs` (B, 4) held over the
        step; refused (ValueError) unless both are of the exported batch and dtype."""
        self.check("state", state, (self.batch, 6))
        self.check("inputs", inputs, (self.batch, 4))
        return self.step(state, inputs)

    def predict(self, x0: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        """States (T, B, 6) from x0 (B, 6) and inputs (T, B, 4) held over each step."""
        self.check("x0", x0, (self.batch, 6))
        self.check("inputs", inputs, (inputs.shape[0], self.batch, 4))
        with torch.no_grad():
            return run_steps(self.step, x0, inputs)


def load_step(path: str | Path) -> ExportedStep:
    """Load a file written by `export_model` (either kind, with or without the gate's decision)."""
    if is_compiled_package(path):
        metadata = package_metadata(path)
        if "outputs" not in metadata:
            return ExportedStep(load_package(path), metadata)
        package = torch._inductor.aoti_load_package(str(path))
        runner = getattr(getattr(package, "loader", None), "run", None)

        def both(*tensors):   # the runner reads its inputs as contiguous (`load_package`)
            out = (runner([t.contiguous() for t in tensors]) if runner is not None
                   else package(*(t.contiguous() for t in tensors)))
            return out[0], out[1]
        return ExportedStep(lambda x, u: both(x, u)[0], metadata, both)
    extra = {METADATA_FILE: ""}
    program = torch.export.load(str(path), extra_files=extra).module()
    metadata = json.loads(extra[METADATA_FILE] or "{}")
    if "outputs" not in metadata:
        return ExportedStep(program, metadata)

    def pair(x, u):
        out = program(x, u)
        return out[0], out[1]
    return ExportedStep(lambda x, u: pair(x, u)[0], metadata, pair)


def step_latency(exported: ExportedStep, calls: int = 2000) -> tuple[float, float]:
    """(median seconds per step call, seconds per 100-step prediction) at the exported shape."""
    batch = int(exported.metadata.get("batch", 1))
    dtype = getattr(torch, exported.metadata.get("dtype", "float64"))
    x, inputs = straight_run(batch, dtype)
    u = inputs[0]
    times = []
    step = exported.step   # the file's own call, as a controller makes it (the inputs are checked here, once)
    exported.check("state", x, (batch, 6))
    exported.check("inputs", u, (batch, 4))
    with torch.no_grad():
        step(x, u)
        for _ in range(calls):
            start = time.perf_counter()
            step(x, u)
            times.append(time.perf_counter() - start)
        start = time.perf_counter()
        exported.predict(x, inputs)
        prediction = time.perf_counter() - start
    times.sort()
    return times[len(times) // 2], prediction
