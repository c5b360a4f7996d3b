"""The MMG right-hand side of the Esso Osaka's and the standard families as one native call per batch.

`native_kernel.cpp` (shipped beside this module) computes, row by row in double, what
`sysid.mmg.vjp.rate_with_jacobian` computes with some 400 torch operations: the MMG of
Yoshimura's hull (exact cross-flow integrals), the four-quadrant propeller and rudder and
Fujiwara's wind (or none), or the standard MMG families of Yasukawa & Yoshimura
(`sysid.mmg.hull_standard`, `propeller_standard` with either wake, `rudder_standard`) in any mix
`families_of` allows, the equations-of-motion rate, the FNN's inputs s and, by forward-mode
dual numbers over the same code, their Jacobian with respect to the state. The branches and
their derivatives are `sysid.mmg.tangents`' and the standard modules' (the branch the forward
takes, as autograd).

The public face, for states (..., 6) = (x, u, y, v, psi, r) and inputs (..., 4) = (n [rps],
delta [rad], U_T [m/s], zeta [rad]) on the CPU, float32 or float64 (both the same dtype),
``c`` a values view of the coefficients (`sysid.mmg.coefficients.Coefficients.values_view`)
and ``families`` the MMG's `Families` (`families_of`; ``True``/``False``: the Esso Osaka's
with/without Fujiwara's wind), parsed once from the ship's families:

* ``rate(state, inputs, c, families) -> out (..., 18)``: dx/dt of F_MMG (6), F_MMG (3) [N, N,
  N m], s (9) in `sysid.hybrid.correction.INPUT_NAMES` order; no gradient (a no-grad
  right-hand side: maneuvers, predictions). dx/dt of the total force is ``out[..., :6] +
  F_NN @ sysid.mmg.vjp.force_rate(c, state)``.
* ``rate_with_jacobian(state, inputs, c, families) -> (out (..., 18), jacobian (..., 6, 18))``,
  jacobian[..., i, j] = d out_j / d state_i; ``training_rate`` the same with s standardised
  for the FNN and the outputs apart, ``state_gradient`` its vector-Jacobian product (the
  training path, `sysid.mmg.vjp.training_rate`); `TrainingKernel` both with their lookups
  done once per rollout, and the values without the Jacobian for a state without gradient
  (`sysid.hybrid.fused_rate`).
* ``covers(mmg)``: the MMG's families are ones the kernel computes (`families_of` is not
  None; exact quadrature);
  ``applies(state, inputs, c)``: the library is loaded and these tensors can be passed to it
  (CPU, float32/float64, no autograd or torch.func transform through them, no capture for
  compiled code, constant coefficients; not inside ``torch_path()``). Call `rate` or
  `rate_with_jacobian` only where both hold; elsewhere compute through torch
  (`sysid.mmg.vjp`, `MMG`).
* ``forward(mmg, state, inputs) -> out (..., 18) or None``: `rate` for an `MMG` where both
  hold (its values view, its families), None where the caller computes through torch.

The library is compiled on first use with the system's C++ compiler (``$CXX``, else ``c++``
or ``g++``; flags `FLAGS`: no fast-math, no host-specific code, so every machine computes the
kernel's own arithmetic alike; its sin, cos, atan2, hypot and exp are the C library's: glibc's
FMA variants, picked on CPUs with FMA, differ from its SSE2 ones in the last bit for up to
0.07 % of arguments) into a per-user cache (``$SYSID_CACHE_DIR``, else ``$XDG_CACHE_HOME/sysid/native``,
else ``~/.cache/sysid/native``), named by a hash of the source, the compiler's version and the flags
and by the SHA-256 of its bytes (written to a temporary file, then renamed: concurrent
processes and Ray workers never load a partial file; one whose bytes do not match its name is
not loaded). ``SYSID_NATIVE=0``, no compiler or a failed compile: the torch path, said once
per process on the ``sysid.mmg.native`` logger.
"""
from __future__ import annotations

import contextlib
import enum
import ctypes
import hashlib
import itertools
import logging
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Iterator

import torch

from sysid.mmg.capture import captured, transformed
from sysid.mmg.coefficient_lookup import Rows, coefficient_vector
from sysid.mmg.guards import SPEED_GUARD, TINY
from sysid.mmg.hull import _CROSSFLOW, _HULL
from sysid.mmg.hull_standard import _ROWS as _STANDARD_HULL
from sysid.mmg.motion import _VALUES, LOW_SPEED
from sysid.mmg.propeller import _LATERAL
from sysid.mmg.rudder import _RUDDER
from sysid.mmg.tangents import FAMILIES  # the Esso Osaka's families (its wind is the one here)
from sysid.mmg.wind import _HALF_PI, _WIND

_log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("native_kernel.cpp")
# IEEE arithmetic as written: no fast-math, no contraction into FMA, no host-specific code (the
# kernel's own arithmetic is the same on every x86-64 machine: the tangents' pairs are SSE2, x86-64's
# baseline; the C library's functions it calls are glibc's variant for the CPU: on the D2 step's
# calls its FMA and SSE2 variants change 26 of 322 560 float32 outputs, all in two Jacobian entries
# of round-off size (|value| < 1e-15), and no weight of a 15-epoch D2 training; benchmarks/
# speed_results.md, session 19, kernelmath); -O3 gives the same bits as -O2 (checked on the D2 windows), 1.3x faster
FLAGS = ("-O3", "-fPIC", "-shared", "-std=c++17", "-ffp-contract=off")
WIDTH = 18  # dx/dt (6), F_MMG (3), s (9)


class Families(enum.IntFlag):
    """The force families of one call, as the kernel reads them (its ``families`` argument):
    no flag is the Esso Osaka's (Yoshimura hull, four-quadrant propeller and rudder) without
    wind; ``True``/``False`` passed for it mean that with/without Fujiwara's wind."""

    WIND = 1                 # Fujiwara's wind
    HULL_STANDARD = 2        # `sysid.mmg.hull_standard`
    PROPELLER_STANDARD = 4   # `sysid.mmg.propeller_standard` with `sysid.mmg.rudder_standard`
    WAKE_GAUSSIAN = 8        # with PROPELLER_STANDARD: shipmmg's wake (else Yasukawa's C_1, C_2)


# the ship-file families the kernel computes, by component: name -> its flags (wind: or none);
# the standard propellers only with the standard rudder, the four-quadrant ones together
HULLS = {"yoshimura_low_speed": Families(0), "standard": Families.HULL_STANDARD}
PROPELLERS = {"four_quadrant": Families(0), "standard": Families.PROPELLER_STANDARD,
              "standard_gaussian_wake": Families.PROPELLER_STANDARD | Families.WAKE_GAUSSIAN}
RUDDER_OF = {"four_quadrant": "four_quadrant", "standard": "standard", "standard_gaussian_wake": "standard"}


def _flat(block: tuple) -> tuple:
    """A family's groups of entries (a `Rows` group: rows of entries) as one tuple of entries."""
    return tuple(itertools.chain.from_iterable(
        itertools.chain.from_iterable(g) if isinstance(g, Rows) else g for g in block))


@dataclass(frozen=True)
class Segment:
    """Coefficients the kernel reads for some families: scalars (kernel name, entry), then
    blocks (kernel name, entries), each entry as `coefficient_vector` reads it (a tuple: a
    product, None: 0). Read where ``families & mask == value``, zeros elsewhere."""

    mask: Families
    value: Families
    scalars: tuple = ()
    blocks: tuple = ()

    def used(self, families: int) -> bool:
        return (families & self.mask) == self.value

    def entries(self) -> tuple:
        return tuple(e for _, e in self.scalars) + tuple(itertools.chain.from_iterable(e for _, e in self.blocks))


def _same(*names: str) -> tuple:
    return tuple((name, name) for name in names)


def _standard(*names: str) -> tuple:
    return tuple((f"S_{name}", name) for name in names)


_NONE, _HS, _PS, _WG = Families(0), Families.HULL_STANDARD, Families.PROPELLER_STANDARD, Families.WAKE_GAUSSIAN
SEGMENTS = (
    Segment(_NONE, _NONE, _same("eom_X_u", "eom_vr_u", "eom_rr_u", "eom_Y_v", "eom_N_v", "eom_ur_v", "eom_N_r",
                                "eom_ur_r") + _standard("L_pp"), (("RUDDER", _flat(_RUDDER)),)),
    Segment(_HS, _NONE, _same("X_0F", "dX_0_pi", "half_L"), (("CROSSFLOW", _flat(_CROSSFLOW)), ("HULL", _flat(_HULL)))),
    Segment(_HS, _HS, (), (("S_HULL", tuple(itertools.chain.from_iterable(_STANDARD_HULL))),)),
    Segment(_PS, _NONE, _same("x_P_L", "slow_lateral_inflow", "one_minus_wP0", "tau", "C_P", "D", "k0", "k1", "k2",
                              "C10", "C6", "C7", "C3", "one_minus_tP_rho_D4", "rho_D4", "eps2_one_minus_eta",
                              "jet_D2", "kappa", "eps2_eta", "kitagawa_jet_eps2", "C_PR", "x_R", "minus_gamma_P",
                              "minus_gamma_N", "l_R"), (("LATERAL", _flat(_LATERAL)),)),
    Segment(_PS, _PS, _standard("minus_x_P", "D", "k0", "k1", "k2", "one_minus_tP_rho_D4", "jet_D2", "kappa",
                                "eps2_eta", "eps2_one_minus_eta", "minus_l_R_nd", "gamma_R_minus", "gamma_R_plus")),
    Segment(_PS | _WG, _PS, _standard("one_minus_wP0", "minus_C_1", "wake_plus", "wake_minus")),
    Segment(_PS | _WG, _PS | _WG, _standard("minus_w_P0")),
    Segment(Families.WIND, Families.WIND, (), (("WIND", _flat(_WIND)),)),
)
N_COEFFICIENTS = sum(len(segment.entries()) for segment in SEGMENTS)
# the forward's constants (`sysid.mmg.motion.constants`)
CONSTANTS = {"SPEED_GUARD": SPEED_GUARD, "LOW_SPEED": LOW_SPEED, "TINY": TINY,
             "STOPPED_RATIO": _VALUES.stopped_ratio, "TWO_PI": _VALUES.two_pi,
             "HALF_PI": _HALF_PI}


def _header() -> str:
    """The `constexpr` lines the kernel reads: constants, the family flags, then the offsets
    into the coefficient vector."""
    lines = [f"constexpr double {name} = {float(value)!r};" for name, value in CONSTANTS.items()]
    lines += [f"constexpr int {flag.name} = {int(flag)};" for flag in Families]
    lines.append("namespace K {")
    offset = 0
    for segment in SEGMENTS:
        for name, _ in segment.scalars:
            lines.append(f"constexpr int {name} = {offset};")
            offset += 1
        for name, entries in segment.blocks:
            lines.append(f"constexpr int {name} = {offset};")
            offset += len(entries)
    lines += [f"constexpr int N_COEFFICIENTS = {offset};", "}  // namespace K", ""]
    return "\n".join(lines)


def library_source() -> str:
    """The C++ source compiled: `_header` and ``native_kernel.cpp``."""
    return "// generated by sysid.mmg.native\n" + _header() + SOURCE.read_text()


def cache_dir() -> Path:
    """Where compiled libraries are kept: ``$SYSID_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/sysid/native``, else ``~/.cache/sysid/native`` (beside the compiled
    predictions' ``~/.cache/sysid/compiled``)."""
    if os.environ.get("SYSID_CACHE_DIR"):
        return Path(os.environ["SYSID_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "sysid" / "native"


class NativeUnavailable(RuntimeError):
    """The library cannot be built or loaded here (the reason in the message)."""


def compiler() -> str:
    """The C++ compiler: ``$CXX``, else ``c++`` or ``g++`` on the PATH."""
    found = os.environ.get("CXX") or shutil.which("c++") or shutil.which("g++")
    if not found:
        raise NativeUnavailable("no C++ compiler ($CXX, c++ or g++)")
    return found


def build_key(cxx: str) -> str:
    """The hash naming a library: the source, the compiler's version and the flags."""
    try:
        version = subprocess.run([cxx, "--version"], capture_output=True, text=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError) as error:
        raise NativeUnavailable(f"{cxx} --version failed: {error}") from error
    text = "\0".join([library_source(), version, " ".join(FLAGS)])
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def _intact(directory: Path, key: str) -> Path | None:
    """A library of `key` in `directory` whose bytes match the digest in its name."""
    for path in sorted(directory.glob(f"mmg-{key}-*.so")):
        if path.name == f"mmg-{key}-{_digest(path)}.so":
            return path
    return None


@dataclass(frozen=True)
class Build:
    """A library ready to load: its path, and whether this call compiled it (and how long)."""

    path: Path
    compiled: bool
    seconds: float


def build(directory: Path | None = None) -> Build:
    """The library in `directory` (default `cache_dir`), compiled there if no intact one of
    this source, compiler and flags exists. Raises `NativeUnavailable`."""
    start = time.perf_counter()
    directory = cache_dir() if directory is None else Path(directory)
    cxx = compiler()
    key = build_key(cxx)
    try:
        found = _intact(directory, key) if directory.is_dir() else None
        if found is not None:
            return Build(found, False, time.perf_counter() - start)
        return _compile(directory, cxx, key, start)
    except OSError as error:  # the cache cannot be read or written (not a directory, full, read-only)
        raise NativeUnavailable(f"cannot build into the cache {directory}: {error}") from error


def _compile(directory: Path, cxx: str, key: str, start: float) -> Build:
    """Compile the library of `key` in a scratch directory inside `directory` and rename it
    into place."""
    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=directory, prefix=".mmg-build-") as scratch:
        # a fixed source name (it is recorded in the library): the same bytes from every build
        source = Path(scratch) / f"mmg-{key}.cpp"
        source.write_text(library_source())
        target = Path(scratch) / "mmg.so"
        try:
            done = subprocess.run([cxx, *FLAGS, "-o", str(target), source.name], cwd=scratch,
                                  capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.SubprocessError) as error:
            raise NativeUnavailable(f"{cxx} failed: {error}") from error
        if done.returncode != 0 or not target.is_file():
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            raise NativeUnavailable(f"{cxx} failed ({done.returncode}): {' | '.join(tail)}")
        final = directory / f"mmg-{key}-{_digest(target)}.so"
        os.replace(target, final)  # atomic: another process sees all of it or nothing
    return Build(final, True, time.perf_counter() - start)


_P = ctypes.c_void_p
_ENTRIES = {"rate": (ctypes.c_int64, _P, _P, _P, ctypes.c_int, _P),
            "rate_jacobian": (ctypes.c_int64, _P, _P, _P, ctypes.c_int, _P, _P),
            "training": (ctypes.c_int64, _P, _P, _P, ctypes.c_int, _P, _P, _P, _P, _P, _P),
            "state_gradient": (ctypes.c_int64, _P, _P, _P, _P, _P)}


def load(path: Path) -> ctypes.CDLL:
    """The library at `path` with its entries typed; raises `NativeUnavailable` where it
    is not this module's (its coefficient count differs)."""
    try:
        library = ctypes.CDLL(str(path))
    except OSError as error:
        raise NativeUnavailable(f"cannot load {path}: {error}") from error
    library.sysid_mmg_width.restype = ctypes.c_int
    if library.sysid_mmg_width() != N_COEFFICIENTS:
        raise NativeUnavailable(f"{path} reads {library.sysid_mmg_width()} coefficients, not {N_COEFFICIENTS}")
    for entry, argtypes in _ENTRIES.items():
        for suffix in ("f32", "f64"):
            function = getattr(library, f"sysid_mmg_{entry}_{suffix}")
            function.argtypes, function.restype = argtypes, None
    return library


_STATE: dict[str, object] = {}  # "library": the loaded CDLL, or None once it failed; "off": torch_path


def library() -> ctypes.CDLL | None:
    """The process's library (built and loaded on first call), or None where the torch path
    is used (``SYSID_NATIVE=0``, no compiler, a failed compile): said once, on the log."""
    if "library" in _STATE:
        return _STATE["library"]  # type: ignore[return-value]
    loaded = None
    if os.environ.get("SYSID_NATIVE", "1").strip() == "0":
        _log.info("native MMG kernel off (SYSID_NATIVE=0): the MMG runs through torch")
    else:
        try:
            made = build()
            loaded = load(made.path)
            _log.debug("native MMG kernel %s (%s in %.1f s)", made.path,
                       "compiled" if made.compiled else "from the cache", made.seconds)
        except NativeUnavailable as error:
            _log.warning("native MMG kernel unavailable, the MMG runs through torch: %s", error)
    _STATE["library"] = loaded
    return loaded


@contextlib.contextmanager
def torch_path() -> Iterator[None]:
    """Inside, `applies` is False: every caller computes through torch (to compare the two)."""
    before = _STATE.get("off", False)
    _STATE["off"] = True
    try:
        yield
    finally:
        _STATE["off"] = before


def available() -> bool:
    """True where the library is loaded (built on first call)."""
    return library() is not None


def families_of(mmg) -> Families | None:
    """The kernel's `Families` for `mmg`, or None where it does not compute its F_MMG: a hull
    of `HULLS`, a propeller of `PROPELLERS` with its rudder (`RUDDER_OF`), Fujiwara's wind
    or none, exact cross-flow integrals."""
    models = mmg.ship.models
    hull, propeller, wind = models.get("hull"), models.get("propeller"), models.get("wind")
    if hull not in HULLS or propeller not in PROPELLERS or models.get("rudder") != RUDDER_OF[propeller]:
        return None
    if wind not in (None, FAMILIES["wind"]) or mmg.quadrature != "exact":
        return None
    return HULLS[hull] | PROPELLERS[propeller] | (Families.WIND if wind is not None else Families(0))


def covers(mmg) -> bool:
    """True where the kernel computes `mmg`'s F_MMG (`families_of`)."""
    return families_of(mmg) is not None


_DTYPES = (torch.float32, torch.float64)


def applies(state: torch.Tensor, inputs: torch.Tensor, c, differentiated: bool = False) -> bool:
    """True where `rate`/`rate_with_jacobian` can take these tensors: the library is loaded,
    both are CPU tensors of one dtype (float32 or float64) with no gradient to record (unless
    `differentiated`: the caller's autograd Function records it) and no torch.func transform
    or compiled-code capture around them, and the coefficients in the values view `c` are
    constants."""
    if _STATE.get("off"):
        return False
    if state.device.type != "cpu" or state.dtype not in _DTYPES or inputs.dtype != state.dtype:
        return False
    if inputs.device.type != "cpu" or captured() or transformed(state) or transformed(inputs):
        return False
    if not differentiated and torch.is_grad_enabled() and (state.requires_grad or inputs.requires_grad):
        return False
    if getattr(c, "requires_grad", False) or getattr(c, "wrapped", False):
        return False
    return available()


def coefficient_values(c, families: int) -> torch.Tensor:
    """(N_COEFFICIENTS,) float64: the kernel's coefficient vector from the values view `c`
    for `families` (`Families`; the segments of other families are zeros), kept in the view:
    once per coefficient state."""
    families = int(families)
    cache = c.__dict__.setdefault("_native", {}) if type(c) is SimpleNamespace else {}
    found = cache.get(families)
    if found is not None:
        return found
    like = torch.empty((), dtype=torch.float64)
    parts = []
    with torch.no_grad():
        for segment in SEGMENTS:
            entries = segment.entries()
            parts.append(coefficient_vector(c, entries, like).detach().to("cpu", torch.float64)
                         if segment.used(families) else torch.zeros(len(entries), dtype=torch.float64))
    found = cache[families] = torch.cat(parts).contiguous()
    return found


def _call(entry: str, state: torch.Tensor, inputs: torch.Tensor, c, families: int, outputs: list,
          extra: tuple = ()):
    lib = library()
    if lib is None:
        raise NativeUnavailable("the native MMG kernel is not loaded (see `applies`)")
    if state.shape[:-1] != inputs.shape[:-1] or state.shape[-1] != 6 or inputs.shape[-1] != 4:
        raise ValueError(f"state (..., 6) and inputs (..., 4) of one batch, got {tuple(state.shape)}, "
                         f"{tuple(inputs.shape)}")
    state, inputs = state.contiguous(), inputs.contiguous()
    rows = state.numel() // 6
    families = int(families)
    coefficients = coefficient_values(c, families)
    suffix = "f32" if state.dtype == torch.float32 else "f64"
    getattr(lib, f"sysid_mmg_{entry}_{suffix}")(rows, state.data_ptr(), inputs.data_ptr(), coefficients.data_ptr(),
                                                families, *extra, *[o.data_ptr() for o in outputs])


def rate(state: torch.Tensor, inputs: torch.Tensor, c, families: int = Families.WIND) -> torch.Tensor:
    """out (..., 18) (see the module docstring), no gradient; where `applies` holds."""
    out = torch.empty(*state.shape[:-1], WIDTH, dtype=state.dtype)  # integer sizes: parsed quicker
    _call("rate", state, inputs, c, families, [out])
    return out


def rate_with_jacobian(state: torch.Tensor, inputs: torch.Tensor, c,
                       families: int = Families.WIND) -> tuple[torch.Tensor, torch.Tensor]:
    """(out (..., 18), its Jacobian (..., 6, 18), [i, j] = d out_j / d state_i); where
    `applies` holds."""
    out = torch.empty(state.shape[:-1] + (WIDTH,), dtype=state.dtype)
    jacobian = torch.empty(state.shape[:-1] + (6, WIDTH), dtype=state.dtype)
    _call("rate_jacobian", state, inputs, c, families, [out, jacobian])
    return out, jacobian


def forward(mmg, state: torch.Tensor, inputs: torch.Tensor) -> torch.Tensor | None:
    """`rate` (..., 18) of the `MMG` `mmg` at state (..., 6) with inputs (..., 4) where the
    kernel covers its families and applies to these tensors (`covers`, `applies`), else None
    (compute through torch then)."""
    families = families_of(mmg)
    if families is None:
        return None
    c = mmg.coefficients.values_view(state.dtype)
    if not applies(state, inputs, c):
        return None
    return rate(state, inputs, c, families)


def training_rate(state: torch.Tensor, inputs: torch.Tensor, c, families: int, mean: torch.Tensor,
                  std: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """What a training step reads: dx/dt of F_MMG (..., 6), F_MMG (..., 3), the FNN's inputs
    standardised, z = (s - mean) / std (..., 9) (`mean`, `std` (9,) in the state's dtype, Eq. 8),
    and the Jacobian (..., 6, 18) of (dx/dt, F_MMG, z) with respect to the state; where
    `applies` holds."""
    if state.shape[:-1] != inputs.shape[:-1] or state.shape[-1] != 6 or inputs.shape[-1] != 4:
        raise ValueError(f"state (..., 6) and inputs (..., 4) of one batch, got {tuple(state.shape)}, "
                         f"{tuple(inputs.shape)}")
    rate_out, force, z, jacobian = TrainingKernel(c, families, mean, std, state.dtype)(state, inputs, True)
    assert jacobian is not None
    return rate_out, force, z, jacobian


class TrainingKernel:
    """`training_rate` with its lookups done once (the library's entries, the coefficient
    vector, the standardisation), for the calls of one rollout: ``kernel(state (..., 6), inputs
    (..., 4), jacobian)`` gives (dx/dt of F_MMG (..., 6), F_MMG (..., 3), z (..., 9), the
    Jacobian (..., 6, 18) or, without `jacobian`, None: the values alone, the same numbers);
    ``kernel.state_gradient(jacobian, g_rate, g_force, g_z)`` is `state_gradient`. Tensors of
    `dtype` on the CPU, where `applies` holds; `mean`, `std` (9,) of that dtype (constants
    while the kernel is used)."""

    def __init__(self, c, families: int, mean: torch.Tensor, std: torch.Tensor, dtype: torch.dtype):
        lib = library()
        if lib is None:
            raise NativeUnavailable("the native MMG kernel is not loaded (see `applies`)")
        if dtype not in _DTYPES or mean.dtype != dtype or std.dtype != dtype or mean.shape != (9,) \
                or std.shape != (9,):
            raise ValueError(f"mean and std (9,) in the state's dtype {dtype}, got {mean.dtype} "
                             f"{tuple(mean.shape)}, {std.dtype} {tuple(std.shape)}")
        suffix = "f32" if dtype == torch.float32 else "f64"
        self._training = getattr(lib, f"sysid_mmg_training_{suffix}")
        self._gradient = getattr(lib, f"sysid_mmg_state_gradient_{suffix}")
        self.families = int(families)
        self.dtype = dtype
        self._keep = (coefficient_values(c, self.families), mean.contiguous(), std.contiguous())
        self._pointers = tuple(t.data_ptr() for t in self._keep)

    def __call__(self, state: torch.Tensor, inputs: torch.Tensor,
                 jacobian: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        state, inputs = state.contiguous(), inputs.contiguous()
        *batch, _ = state.shape
        # the sizes as integers: torch.empty parses them quicker than a torch.Size (once per call)
        empty, dtype, device = torch.empty, self.dtype, state.device
        rate_out, force = empty(*batch, 6, dtype=dtype, device=device), empty(*batch, 3, dtype=dtype, device=device)
        z = empty(*batch, 9, dtype=dtype, device=device)
        jac = empty(*batch, 6, WIDTH, dtype=dtype, device=device) if jacobian else None
        coefficients, mean, std = self._pointers
        self._training(state.numel() // 6, state.data_ptr(), inputs.data_ptr(), coefficients, self.families, mean,
                       std, rate_out.data_ptr(), force.data_ptr(), z.data_ptr(),
                       None if jac is None else jac.data_ptr())
        return rate_out, force, z, jac

    def _gradient_of(self, grad: torch.Tensor | None) -> torch.Tensor | None:
        """`grad` in this kernel's dtype, rows contiguous (None stays None)."""
        if grad is None:
            return None
        if grad.dtype != self.dtype:
            grad = grad.to(self.dtype)
        return grad if grad.is_contiguous() else grad.contiguous()

    def state_gradient(self, jacobian: torch.Tensor, grad_rate: torch.Tensor | None,
                       grad_force: torch.Tensor | None, grad_z: torch.Tensor | None) -> torch.Tensor:
        """`state_gradient` of this kernel's dtype."""
        g_rate, g_force, g_z = self._gradient_of(grad_rate), self._gradient_of(grad_force), self._gradient_of(grad_z)
        *batch, _, _ = jacobian.shape
        out = torch.empty(*batch, 6, dtype=jacobian.dtype, device=jacobian.device)
        self._gradient(jacobian.numel() // 108, jacobian.data_ptr(), None if g_rate is None else g_rate.data_ptr(),
                       None if g_force is None else g_force.data_ptr(), None if g_z is None else g_z.data_ptr(),
                       out.data_ptr())
        return out


def state_gradient(jacobian: torch.Tensor, grad_rate: torch.Tensor | None, grad_force: torch.Tensor | None,
                   grad_z: torch.Tensor | None) -> torch.Tensor:
    """(..., 6): the gradients of `training_rate`'s three outputs (None: zero) times its
    Jacobian (..., 6, 18), the vector-Jacobian product, in one call."""
    lib = library()
    if lib is None:
        raise NativeUnavailable("the native MMG kernel is not loaded (see `applies`)")
    grads = [None if g is None else g.to(jacobian.dtype).contiguous() for g in (grad_rate, grad_force, grad_z)]
    out = torch.empty(jacobian.shape[:-2] + (6,), dtype=jacobian.dtype)
    suffix = "f32" if jacobian.dtype == torch.float32 else "f64"
    getattr(lib, f"sysid_mmg_state_gradient_{suffix}")(out.shape.numel() // 6, jacobian.data_ptr(),
                                                       *[None if g is None else g.data_ptr() for g in grads],
                                                       out.data_ptr())
    return out
