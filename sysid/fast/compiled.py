"""Ahead-of-time compiled steps, rollouts and right-hand sides, cached on disk; eager fallback.

A `sysid.fast.stepper.Step`, `Rollout` (up to `ROLLOUT_STEPS` steps in one `while_loop`) or
`Derivative` of a model prepared for compilation (`sysid.fast.prepared`: packed coefficients,
leaf-indexed kNN gate) is captured with `torch.export` and compiled by AOTInductor into
one C++ function (a ``.pt2`` package). The package is stored under `cache_dir()` by a
fingerprint of everything that decides its numbers (parameters, kNN bank, options,
shapes, dtype, torch version, the source of the physics), so compilation (a minute or
two on 2 cores) is paid once per model and machine; later processes load it in seconds.
A compiled call has no guards and no Python per operation; a prediction of one ship is
one call per 128 steps (`compiled_rollout`), so no Python runs between steps.

This module and `sysid.fast.codegen_fixes` (two fixes to the C++ wrapper code of loops and
branches, applied while compiling) are the ones that touch `torch._inductor`
(AOTInductor's documented entry points `aoti_compile_and_package` / `aoti_load_package`).
Where they fail (no C++ compiler, an op export cannot capture) `compiled_step` returns
None once with a warning, and callers use the eager step, which gives the same numbers to
round-off.
``SYSID_COMPILE=0`` turns compilation off; ``SYSID_CACHE`` moves the cache.
"""
from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import statistics
import sys
import time
import warnings
import weakref
from pathlib import Path
from typing import Callable, Sequence

import torch
from torch import nn

from sysid.fast import codegen_fixes
from sysid.config.choices import Method
from sysid.dynamics.equations import check_shapes, eager_predict
from sysid.dynamics.integrators import Integrator, IntegratorLike, run_in_chunks, run_steps
from sysid.fast.prepared import prepared
from sysid.mmg.capture import capturing
from sysid.store.files import atomic_path
from sysid.channel_names import INPUTS, STATE
from sysid.fast.stepper import Derivative, Rollout, Step

Compiled = Callable[..., torch.Tensor]
INDUCTOR_OPTIONS = {"force_pointwise_cat": True}  # one row: fuse the small stacks, no buffers
BATCH_OPTIONS: dict = {}  # channels first: each output channel stored in place from the fused loop
PARALLEL_ROWS = 256  # above it a compiled kernel runs on the threads set when it was compiled
CHUNK_ROWS = 65536  # larger batches run through the 65536-row function
ROLLOUT_STEPS = 128  # steps per call of a compiled rollout (longer predictions: several calls)
ROLLOUT_ROWS = 64  # up to this many ships a prediction is one compiled rollout, above it a call per step
_SOURCE_PACKAGES = ("mmg", "dynamics", "hybrid", "fast")  # every module a compiled step can run
_memo: "weakref.WeakKeyDictionary[nn.Module, dict]" = weakref.WeakKeyDictionary()
_failed: set[str] = set()
_log = logging.getLogger(__name__)  # "compiling ..." lines: stage lines of the `sysid` log (`sysid.logs`)


def enabled() -> bool:
    """False when ``SYSID_COMPILE=0`` (or "false", "no", "off")."""
    return os.environ.get("SYSID_COMPILE", "1").strip().lower() not in ("0", "false", "no", "off")


def cache_dir() -> Path:
    """``$SYSID_CACHE`` or ``~/.cache/sysid/compiled``."""
    env = os.environ.get("SYSID_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "sysid" / "compiled"


@functools.lru_cache(maxsize=None)
def _source_digest() -> str:
    """sha256 of the source that computes a step (read once per process)."""
    root = Path(__file__).resolve().parents[1]
    files = sorted(p for pkg in _SOURCE_PACKAGES for p in (root / pkg).glob("*.py"))
    h = hashlib.sha256()
    for path in files:
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _plain(value) -> bool:
    if isinstance(value, (bool, int, float, str)) or value is None:
        return True
    if isinstance(value, (tuple, list)):
        return all(_plain(v) for v in value)
    if isinstance(value, dict):
        return all(_plain(k) and _plain(v) for k, v in value.items())
    return False


def _options(module: nn.Module) -> list:
    """Plain attributes of every submodule (quadrature, bounds, gate space, k, dt, force
    families, ...): what decides the numbers besides the tensors. The train/eval flag is
    left out."""
    out = []
    for name, sub in module.named_modules():
        for key, value in sorted(vars(sub).items()):
            if key == "training" or key.startswith("__"):
                continue
            if _plain(value):
                out.append((name, key, value))
            elif isinstance(value, dict) and all(isinstance(k, str) for k in value):
                # e.g. the MMG's force families: described by type and name
                out.append((name, key, {k: v if _plain(v) else f"{type(v).__qualname__}:{getattr(v, 'name', '')}"
                                        for k, v in sorted(value.items())}))
    return out


def fingerprint(module: nn.Module, example_inputs: Sequence[torch.Tensor], options: dict | None = None) -> str:
    """sha256 of what decides a compiled module's numbers: state, options, shapes, versions."""
    h = hashlib.sha256()
    options = INDUCTOR_OPTIONS if options is None else options
    h.update(f"{torch.__version__} {sys.version_info[:2]} {_source_digest()} {options} "
             f"{codegen_fixes.cache_tag()}".encode())
    h.update(repr(_options(module)).encode())
    for x in example_inputs:
        h.update(f"in {tuple(x.shape)} {x.dtype} {x.device}".encode())
    if example_inputs[0].numel() > 6 * PARALLEL_ROWS:  # kernels this large fix their thread count
        h.update(f"threads {torch.get_num_threads()}".encode())
    for name, t in module.state_dict().items():
        t = t.detach().cpu().contiguous()
        h.update(f"{name} {tuple(t.shape)} {t.dtype}".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()[:32]


def export_program(module: nn.Module, example_inputs: Sequence[torch.Tensor]) -> torch.export.ExportedProgram:
    """`torch.export` capture of `module` at these (static) input shapes, without gradient.

    The force model is told it is captured (`sysid.mmg.capture.capturing`: constants made by
    operations, nothing cached, the guards' gradient-safe forms). Plain attributes the trace
    assigned (caches such as the kNN bank norms, which would hold traced tensors afterwards)
    are put back as they were.
    """
    saved = [(sub, dict(vars(sub))) for sub in module.modules()]
    try:
        with torch.no_grad(), capturing(), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*assigned during export", category=UserWarning)
            return torch.export.export(module, tuple(example_inputs))
    finally:
        for sub, before in saved:
            for key in [k for k in vars(sub) if k not in before]:
                del sub.__dict__[key]
            sub.__dict__.update(before)


def compile_package(program: torch.export.ExportedProgram, path: Path,
                    metadata: dict[str, str] | None = None, inductor_options: dict | None = None) -> Path:
    """AOTInductor-compile an exported program into the ``.pt2`` package `path` (atomic)."""
    path = Path(path)
    options = dict(INDUCTOR_OPTIONS if inductor_options is None else inductor_options)
    if metadata:
        options["aot_inductor.metadata"] = {str(k): str(v) for k, v in metadata.items()}
    with atomic_path(path, ".pt2") as tmp, warnings.catch_warnings(), codegen_fixes.subgraph_fixes():
        warnings.simplefilter("ignore", FutureWarning)  # torch-internal deprecation notices
        torch._inductor.aoti_compile_and_package(program, package_path=str(tmp), inductor_configs=options)
    return path


def load_package(path: str | os.PathLike) -> Compiled:
    """A callable ``f(*tensors) -> tensor`` running an AOTInductor ``.pt2`` package: its
    first output (a `Rollout` also gives its last state, which only keeps its loop alive).

    Calls go straight to the package's C++ runner when it exposes one (about 15 us
    instead of about 35 us through the generic wrapper). The runner reads its inputs as
    contiguous: they are made so here.
    """
    package = torch._inductor.aoti_load_package(str(path))
    runner = getattr(getattr(package, "loader", None), "run", None)
    if runner is None:
        def first(*tensors):
            out = package(*(t.contiguous() for t in tensors))
            return out[0] if isinstance(out, (tuple, list)) else out
        return first
    return lambda *tensors: runner([t.contiguous() for t in tensors])[0]


def package_metadata(path: str | os.PathLike) -> dict[str, str]:
    """The metadata strings stored with a package by `compile_package`."""
    return dict(torch._inductor.aoti_load_package(str(path)).get_metadata())


def cached_package(module: nn.Module, example_inputs: Sequence[torch.Tensor], label: str,
                   metadata: dict[str, str] | None = None,
                   log: Callable[[str], None] | None = None, options: dict | None = None) -> Path:
    """Path of the AOTInductor package of `module` for inputs shaped like `example_inputs`,
    from the disk cache or compiled now and cached (raises where compilation fails)."""
    path = package_path(module, example_inputs, label, options)
    if not path.is_file():
        start = time.perf_counter()
        (log or _log.info)(f"sysid: compiling {label} for {tuple(example_inputs[0].shape)} "
                           f"{example_inputs[0].dtype} (once; cached in {path.parent}) ...")
        compile_package(export_program(module, example_inputs), path, metadata, options)
        seconds = time.perf_counter() - start
        record_seconds(label, "compile", seconds)
        (log or _log.info)(f"sysid: compiled {label} in {seconds:.0f} s")
    return path


TIMINGS = "timings.jsonl"  # in the cache: how long compiling (a cold start) and loading (warm) took here


def record_seconds(label: str, kind: str, seconds: float) -> None:
    """Append what a cold start ("compile") or a warm one ("load") of `label` took on this
    machine to the cache's `TIMINGS` (best effort: a read-only cache records nothing)."""
    try:
        with open(cache_dir() / TIMINGS, "a") as f:
            f.write(json.dumps({"label": label, "kind": kind, "seconds": round(float(seconds), 3)}) + "\n")
    except OSError:
        pass


def recorded_seconds(label: str, kind: str) -> float | None:
    """Median of the last five recorded `kind` ("compile" or "load") times of `label` [s],
    or None when none is recorded."""
    try:
        lines = (cache_dir() / TIMINGS).read_text().splitlines()
    except OSError:
        return None
    values = []
    for line in lines:
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if row.get("label") == label and row.get("kind") == kind:
            values.append(float(row["seconds"]))
    return statistics.median(values[-5:]) if values else None


def package_path(module: nn.Module, example_inputs: Sequence[torch.Tensor], label: str,
                 options: dict | None = None) -> Path:
    """Where the disk cache keeps (or would keep) the package of `module` for these inputs."""
    return cache_dir() / f"{label}-{fingerprint(module, example_inputs, options)}.pt2"


def compile_cached(module: nn.Module, example_inputs: Sequence[torch.Tensor], label: str,
                   metadata: dict[str, str] | None = None,
                   log: Callable[[str], None] | None = None, options: dict | None = None) -> Compiled | None:
    """The compiled `module` (see `cached_package`) as a callable; None, after one
    warning, where compilation fails or is switched off."""
    if not enabled():
        return None
    try:
        path = cached_package(module, example_inputs, label, metadata, log, options)
        start = time.perf_counter()
        loaded = load_package(path)
        record_seconds(label, "load", time.perf_counter() - start)
        return loaded
    except Exception as exc:  # no compiler, export limits: eager gives the same numbers
        message = f"{label}: {type(exc).__name__}: {str(exc)[:300]}"
        if message not in _failed:
            _failed.add(message)
            warnings.warn(f"sysid: cannot compile {message}; using the eager step", RuntimeWarning, stacklevel=2)
        return None


def _state_key(model: nn.Module) -> tuple:
    """Cheap in-process identity of a model's current numbers (tensor storage, version and
    shape), read from each submodule's own tables: a third of the time `parameters()` and
    `buffers()` take (a tensor shared by two submodules is listed twice)."""
    return tuple((t.data_ptr(), t._version, t.shape) for sub in model.modules()
                 for table in (sub._parameters, sub._buffers) for t in table.values() if t is not None)


_SCALARS = (bool, int, float, str, type(None))


def _scalar_options(model: nn.Module) -> tuple:
    """The scalar attributes of every submodule (gate space, k, physics, quadrature, ...;
    enum members such as the gate space are strings):
    the cheap part of `_options`, enough to tell a live model's settings apart."""
    return tuple((id(sub), tuple((k, v) for k, v in vars(sub).items() if isinstance(v, _SCALARS) and k != "training"))
                 for sub in model.modules())


def _memoized(model: nn.Module, key: tuple, build: Callable[[], Compiled | None]) -> Compiled | None:
    """`build()` once per model, key, numbers (`_state_key`) and settings (`_scalar_options`):
    a lookup costs tens of microseconds (the disk cache's `fingerprint` is the full check)."""
    table = _memo.setdefault(model, {})
    key = key + (torch.get_num_threads(), _state_key(model), _scalar_options(model))  # threads: see fingerprint
    if key not in table:
        table[key] = build()
    return table[key]


def compiled_step(model: nn.Module, method: Method, dt: float, batch: int,
                  dtype: torch.dtype = torch.float64, device: str | torch.device = "cpu") -> Compiled | None:
    """Compiled ``step(x (batch, 6), u (batch, 4)) -> x_next``, or None (use eager).

    Batches above one are compiled channels first (vectorized over the batch), batches
    above `CHUNK_ROWS` as chunks of it; the callable takes and gives (batch, ·) all the same.
    """
    rows = min(batch, CHUNK_ROWS)

    def build():
        step = Step(prepared(model, rows), method, dt, rows > 1)
        return compile_cached(step, _examples(rows, dtype, device), step_label(method),
                              step_metadata(model, method, dt, rows, dtype), options=_options_for(rows))
    return _memoized(model, ("step", method, float(dt), batch, dtype, str(device)),
                     lambda: _by_rows(build(), rows, batch))


def compiled_derivative(model: nn.Module, batch: int, dtype: torch.dtype = torch.float64,
                        device: str | torch.device = "cpu") -> Compiled | None:
    """Compiled ``f(x (batch, 6), u (batch, 4)) -> dx/dt``, or None (use eager); batches
    as in `compiled_step`."""
    rows = min(batch, CHUNK_ROWS)
    return _memoized(model, ("rhs", batch, dtype, str(device)),
                     lambda: _by_rows(compile_cached(Derivative(prepared(model, rows), rows > 1), _examples(rows, dtype, device),
                                                     "rhs", options=_options_for(rows)), rows, batch))


def _options_for(rows: int) -> dict:
    """Inductor options: one row (`INDUCTOR_OPTIONS`) or channels first (`BATCH_OPTIONS`)."""
    return INDUCTOR_OPTIONS if rows == 1 else BATCH_OPTIONS


def _examples(rows: int, dtype: torch.dtype, device) -> tuple[torch.Tensor, torch.Tensor]:
    """Example (state, inputs): (rows, 6), (rows, 4), or channels first above one row."""
    shapes = ((6, rows), (4, rows)) if rows > 1 else ((rows, 6), (rows, 4))
    return tuple(torch.zeros(*s, dtype=dtype, device=device) for s in shapes)


def _by_rows(fn: Compiled | None, rows: int, batch: int) -> Compiled | None:
    """`fn` compiled for `rows` (channels first above one) as a function of (batch, ·)
    tensors: transposed in and out, in chunks of `rows` (the last one padded)."""
    if fn is None or rows == 1:
        return fn

    def run(x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        if batch == rows:
            return fn(x.T, u.T).T
        out = []
        for lo in range(0, x.shape[0], rows):
            xs, us = x[lo:lo + rows], u[lo:lo + rows]
            n = xs.shape[0]
            if n < rows:  # pad with copies of the chunk's first row, dropped afterwards
                xs = torch.cat((xs, xs[:1].expand(rows - n, -1)))
                us = torch.cat((us, us[:1].expand(rows - n, -1)))
            out.append(fn(xs.T, us.T).T[:n])
        return torch.cat(out)
    return run


def step_label(method: Method) -> str:
    return f"step-{method.name.lower()}"


def step_metadata(model: nn.Module, method: Method, dt: float, batch: int,
                  dtype: torch.dtype) -> dict[str, str]:
    """What a user of an exported step needs to know: rule, dt, shapes, channels, units."""
    from sysid import __version__
    return {"sysid_version": __version__, "kind": getattr(model, "kind", "mmg"),
            "method": method.value, "dt_s": repr(float(dt)), "batch": str(batch),
            "dtype": str(dtype).replace("torch.", ""), "state": ",".join(STATE), "inputs": ",".join(INPUTS),
            "units": "state x[m] u[m/s] y[m] v[m/s] psi[rad] r[rad/s]; inputs n_prop[rps] "
                     "delta_rudder[rad] wind_velo_true[m/s] wind_dir_true[rad, from]",
            "frames": "x, y midship position, earth frame (x north, y east); psi heading from x to y; "
                      "u, v midship velocity, body frame (forward, starboard); r, delta_rudder positive "
                      "to starboard; true wind from, earth frame, from x to y",
            "signature": "step(state (batch, 6), inputs (batch, 4)) -> state after dt; inputs held over "
                         "the step; contiguous tensors of this batch and dtype only (AOTI_RUNTIME_CHECK_INPUTS=1 "
                         "makes a compiled package refuse others)"}


def compiled_rollout_function(model: nn.Module, method: Method, dt: float, batch: int,
                              dtype: torch.dtype = torch.float64, device: str | torch.device = "cpu"
                              ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor] | None:
    """Compiled ``f(x0 (batch, 6), inputs (T, batch, 4)) -> states (T, batch, 6)`` (row 0
    is x0), or None (use `compiled_step`, or eager). Up to `ROLLOUT_STEPS` steps run in one
    native call (a `sysid.fast.stepper.Rollout`): no Python between steps."""
    if batch > ROLLOUT_ROWS:
        return None

    def build():
        fn = compile_cached(*_rollout(model, method, dt, batch, dtype, device), options=_options_for(batch))
        return None if fn is None else _chunked_rollout(fn, batch > 1)
    return _memoized(model, ("rollout", method, float(dt), batch, dtype, str(device)), build)


def _rollout(model: nn.Module, method: Method, dt: float, batch: int, dtype: torch.dtype, device
             ) -> tuple[Rollout, tuple[torch.Tensor, torch.Tensor, torch.Tensor], str]:
    """The `Rollout` compiled for `batch` ships, its example inputs and its cache label."""
    roll = Rollout(Step(prepared(model, batch), method, dt, batch > 1), ROLLOUT_STEPS)
    x0, u = _examples(batch, dtype, device)
    inputs = u.expand(ROLLOUT_STEPS, *u.shape).contiguous()
    steps = torch.tensor(ROLLOUT_STEPS, dtype=torch.int64, device=device)
    return roll, (x0, inputs, steps), f"rollout-{method.name.lower()}"


def rollout_package(model: nn.Module, method: Method, dt: float, batch: int = 1,
                    dtype: torch.dtype = torch.float64, device: str | torch.device = "cpu") -> Path:
    """Path of the AOTInductor package behind `compiled_rollout_function` (from the disk
    cache, or compiled now; raises where compilation fails): for inspection."""
    return cached_package(*_rollout(model, method, dt, batch, dtype, device),
                          options=_options_for(batch))


def _chunked_rollout(fn: Compiled, channels_first: bool) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """`fn`, a compiled `Rollout` of `ROLLOUT_STEPS` steps, as ``(x0 (B, 6), inputs (T, B, 4))
    -> states (T, B, 6)``: calls of up to `ROLLOUT_STEPS` steps, each from the last state
    (`sysid.dynamics.integrators.run_in_chunks`)."""

    def run(x0: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor:
        x = x0.T.contiguous() if channels_first else x0
        u = inputs.transpose(1, 2) if channels_first else inputs

        def call(x: torch.Tensor, done: int, n: int) -> tuple[torch.Tensor, torch.Tensor]:
            chunk = u[done:done + n]
            if n < ROLLOUT_STEPS:  # rows the loop does not reach: any numbers
                chunk = torch.cat((chunk, chunk[-1:].expand(ROLLOUT_STEPS - n, *chunk.shape[1:])))
            states = fn(x, chunk, torch.tensor(n))[:n]
            return states, states[-1]
        states = run_in_chunks(call, x, inputs.shape[0] - 1, ROLLOUT_STEPS, head=x[None])
        return states.transpose(1, 2) if channels_first else states
    return run


def compiled_rollout(model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
                     method: Method = Method.EULER) -> torch.Tensor:
    """States (T, ..., 6) from x0 (..., 6) and inputs (T, ..., 4), no gradient.

    Up to `ROLLOUT_ROWS` ships: compiled rollouts of up to `ROLLOUT_STEPS` steps per call
    (`compiled_rollout_function`); more ships: one compiled step per time step
    (`compiled_step`); the eager `Step` where compilation is unavailable. Row 0 is x0;
    step k holds inputs[k].
    """
    batch_shape = x0.shape[:-1]
    x = x0.detach().reshape(-1, 6).contiguous()
    u = inputs.detach().reshape(inputs.shape[0], -1, 4).contiguous()
    with torch.no_grad():
        roll = compiled_rollout_function(model, method, dt, x.shape[0], x.dtype, x.device)
        if roll is not None:
            states = roll(x, u)
        else:
            step = compiled_step(model, method, dt, x.shape[0], x.dtype, x.device)
            states = run_steps(step if step is not None else Step(model, method, dt), x, u)
    return states.reshape(inputs.shape[0], *batch_shape, 6)


def prediction_package(model: nn.Module, method: Method, dt: float, batch: int,
                       dtype: torch.dtype = torch.float64, device: str | torch.device = "cpu") -> tuple[str, Path]:
    """(cache label, path) of the package `compiled_rollout` runs for `batch` ships (a
    `Rollout` up to `ROLLOUT_ROWS`, else a `Step` of up to `CHUNK_ROWS` rows): the file
    exists when the prediction starts warm. Nothing is compiled."""
    if batch <= ROLLOUT_ROWS:
        roll, examples, label = _rollout(model, method, dt, batch, dtype, device)
        return label, package_path(roll, examples, label, _options_for(batch))
    rows = min(batch, CHUNK_ROWS)
    step = Step(prepared(model, rows), method, dt, rows > 1)
    label = step_label(method)
    return label, package_path(step, _examples(rows, dtype, device), label, _options_for(rows))


def predict(model: nn.Module, x0: torch.Tensor, inputs: torch.Tensor, dt: float,
            method: IntegratorLike = Method.EULER) -> torch.Tensor:
    """States (T, ..., 6) predicted from x0 (..., 6) with inputs (T, ..., 4), no gradient.

    `method` as for `sysid.dynamics.equations.integrate`; ``Integrator(rule, compiled=True)`` runs
    the compiled step (`compiled_rollout`), anything else the eager
    `sysid.dynamics.equations.eager_predict`.
    """
    integrator = Integrator.of(method)
    if not integrator.compiled:
        return eager_predict(model, x0, inputs, dt, integrator)
    check_shapes(x0, inputs)
    return compiled_rollout(model, x0, inputs, dt, integrator.method)
