"""MMG coefficients as tensors, so a subset can be identified by gradient.

`Coefficients` holds every scalar of a `Ship` (the keys of its force-model families) as a
0-d tensor attribute (``c.X_vr``), as a buffer by default, or as a bounded trainable
parameter. A trainable coefficient is
stored as an unconstrained raw value; its value is ``low + (high-low)*sigmoid(raw)``
when bounds are given.
"""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Iterable, Mapping

import torch
from torch import nn

from sysid.mmg.capture import captured, transformed
from sysid.mmg.ship import Ship, parameter_name
from sysid.errors import ShipDefinitionError


def _number_like(x: torch.Tensor, number: float) -> torch.Tensor:
    """`number` as a 0-d tensor of x's dtype and device. Under `torch.func.jvp` a Python
    number combined with a 0-d float32 tensor gives the result a float64 tangent (PyTorch
    2.13), which a later product with float32 operands refuses; a tensor of x's dtype does not."""
    return torch.full((), number, dtype=x.dtype, device=x.device)


def bounded_value(raw: torch.Tensor, low: float, high: float) -> torch.Tensor:
    """``low + (high-low)*sigmoid(raw)``: the value of a bounded trainable coefficient."""
    return _number_like(raw, low) + _number_like(raw, high - low) * torch.sigmoid(raw)


def raw_value(value: torch.Tensor, low: float, high: float) -> torch.Tensor:
    """The unconstrained raw value whose ``low + (high-low)*sigmoid(raw)`` is `value`."""
    frac = (value - _number_like(value, low)) / _number_like(value, high - low)
    return torch.log(frac / (_number_like(value, 1.0) - frac))


def derived_constants(c, names) -> dict:
    """Constants every forward would otherwise recompute from the coefficients, by the same
    expressions as the force functions wrote them (so the numbers are the same to the bit):
    q = 1/2 rho L_pp d [kg/m], q L_pp [kg], D^2, D^4 [m^2, m^4], P^2 [m^2], the rudder's
    H_R, eta, kappa, f_alpha and the mass terms of the equations of motion. `c` holds the
    coefficients (`names`) as 0-d tensors; only the names the ship has are derived."""
    have = {name: None for name in names}
    out: dict = {}
    _scale_constants(c, have, out)
    _rudder_constants(c, have, out)
    _interaction_constants(c, have, out)
    if "m" in have:
        _mass_constants(c, out)
    return out


def _scale_constants(c, have: dict, out: dict) -> None:
    """Into `out`: the scales of the hull and the propeller (q, q L_pp, powers of L_pp, D, P)
    and the hull's resistance terms."""
    if "rho" in have and "L_pp" in have and "d" in have:
        out["q"] = 0.5 * c.rho * c.L_pp * c.d
        out["qL"] = out["q"] * c.L_pp
        out["L_pp2"] = c.L_pp * c.L_pp
        out["L_pp3"] = c.L_pp ** 3
        out["half_L"] = 0.5 * c.L_pp
    if "D" in have:
        out["D2"], out["D4"] = c.D ** 2, c.D ** 4
    if "P" in have:
        out["P2"] = c.P ** 2
    if "X_0F" in have and "X_0A" in have:
        out["dX_0"] = c.X_0A - c.X_0F
        out["dX_0_pi"] = out["dX_0"] / math.pi
    if "C_D" in have:
        out["C_D_L"] = c.C_D / c.L_pp
        out["C_D_L2"] = c.C_D / (c.L_pp * c.L_pp)


def _rudder_constants(c, have: dict, out: dict) -> None:
    """Into `out`: the rudder's span, Fujii's gradient and the four-quadrant jet (when the
    ship has lambda_R), and eta, kappa and the inflow terms of the rudder."""
    if "lambda_R" in have:  # four-quadrant rudder: span, Fujii's normal-force gradient
        out["H_R"] = torch.sqrt(c.A_R * c.lambda_R)
        out["kappa"] = c.k_x / c.epsilon
        out["f_alpha"] = 6.13 * c.lambda_R / (2.25 + c.lambda_R)
        # Kitagawa's propeller term: (n D k_xPR)^2 8 |K_T| / pi = n^2 |K_T| kitagawa_jet [m^2]
        out["kitagawa_jet"] = 8.0 * (c.D * c.k_xPR) ** 2 / math.pi
        out["kitagawa_jet_eps2"] = out["kitagawa_jet"] / (c.epsilon * c.epsilon)
        out["minus_gamma_P"], out["minus_gamma_N"] = -c.gamma_P, -c.gamma_N
    if "H_R" in have or "H_R" in out:
        out["eta"] = c.D / out["H_R"] if "H_R" in out else c.D / c.H_R
        out["one_minus_eta"] = 1.0 - out["eta"]
        out["half_rho_A_R"] = 0.5 * c.rho * c.A_R
        out["l_R_nd"] = c.l_R / c.L_pp
        out["minus_l_R_nd"] = -out["l_R_nd"]
        # u_R^2 = epsilon^2 (eta core^2 + (1 - eta) u_P^2); the propeller race 8 K_T (n D)^2 / pi
        out["eps2_eta"] = c.epsilon * c.epsilon * out["eta"]
        out["eps2_one_minus_eta"] = c.epsilon * c.epsilon * out["one_minus_eta"]
        out["jet_D2"] = 8.0 * out["D2"] / math.pi


def _interaction_constants(c, have: dict, out: dict) -> None:
    """Into `out`: the hull-rudder and hull-propeller interaction terms (a_H, t_R, t_P, w_P0,
    x_P, the four-quadrant wake) and the air's half density."""
    if "a_H" in have:
        out["one_plus_aH"] = 1.0 + c.a_H
        out["one_minus_tR"] = 1.0 - c.t_R
        out["N_R_lever"] = c.x_R + c.a_H * c.x_H
        out["minus_one_plus_aH"] = -out["one_plus_aH"]
        out["minus_one_minus_tR"] = -out["one_minus_tR"]
        out["minus_N_R_lever"] = -out["N_R_lever"]
    if "t_P" in have:
        out["one_minus_tP"] = 1.0 - c.t_P
        out["one_minus_tP_rho"] = out["one_minus_tP"] * c.rho
        out["rho_D4"] = c.rho * out["D4"]
        out["one_minus_tP_rho_D4"] = out["one_minus_tP_rho"] * out["D4"]
    if "w_P0" in have:
        out["one_minus_wP0"] = 1.0 - c.w_P0
        out["minus_w_P0"] = -c.w_P0
    if "x_P" in have:
        out["minus_x_P"] = -c.x_P
        out["x_P_L"] = c.x_P * c.L_pp  # m
        # the four-quadrant wake's lateral inflow below the speed guard (v' = r' = 1e-7)
        out["slow_lateral_inflow"] = 1e-7 + c.x_P * 1e-7
    if "C_2_plus" in have:
        out["wake_plus"] = out["one_minus_wP0"] * (c.C_2_plus - 1.0)
        out["wake_minus"] = out["one_minus_wP0"] * (c.C_2_minus - 1.0)
        out["minus_C_1"] = -c.C_1
    if "rho_air" in have:
        out["half_rho_air"] = 0.5 * c.rho_air


def _mass_constants(c, out: dict) -> None:
    """Into `out`: the mass terms of the equations of motion, Eq. (4) solved for the accelerations."""
    m, xG = c.m, c.x_G
    out["m_plus_mx"] = m + c.m_x
    out["m_plus_my"] = m + c.m_y
    out["mxG"] = m * xG
    out["a22"] = c.I_zz_J_zz + xG * xG * m
    out["det"] = out["m_plus_my"] * out["a22"] - out["mxG"] * out["mxG"]
    # Eq. (4) solved: u_dot = X/(m+m_x) + (m+m_y)/(m+m_x) v r + m x_G/(m+m_x) r^2,
    # (v_dot, r_dot) = [[a22, -mxG], [-mxG, m+m_y]] (Y - (m+m_x) u r, N - mxG u r) / det
    det, mx, my, mxG = out["det"], out["m_plus_mx"], out["m_plus_my"], out["mxG"]
    out["eom_X_u"] = 1.0 / mx
    out["eom_vr_u"] = my / mx
    out["eom_rr_u"] = mxG / mx
    out["eom_Y_v"] = out["a22"] / det
    out["eom_N_v"] = -mxG / det
    out["eom_ur_v"] = (mxG * mxG - out["a22"] * mx) / det
    out["eom_N_r"] = my / det
    out["eom_ur_r"] = mxG * (mx - my) / det


# every name `derived_constants` may give
DERIVED_NAMES = frozenset((
    "q", "qL", "L_pp2", "L_pp3", "half_L", "D2", "D4", "P2", "dX_0", "dX_0_pi", "C_D_L", "C_D_L2", "H_R",
    "kappa", "f_alpha", "kitagawa_jet", "kitagawa_jet_eps2", "minus_gamma_P", "minus_gamma_N",
    "eta", "one_minus_eta", "half_rho_A_R", "l_R_nd", "minus_l_R_nd", "eps2_eta", "eps2_one_minus_eta",
    "jet_D2", "one_plus_aH", "one_minus_tR", "N_R_lever",
    "minus_one_plus_aH", "minus_one_minus_tR", "minus_N_R_lever", "one_minus_tP", "one_minus_tP_rho",
    "rho_D4", "one_minus_tP_rho_D4", "one_minus_wP0", "minus_w_P0", "minus_x_P", "x_P_L",
    "slow_lateral_inflow", "wake_plus", "wake_minus", "minus_C_1", "half_rho_air",
    "m_plus_mx", "m_plus_my", "mxG", "a22", "det", "eom_X_u", "eom_vr_u", "eom_rr_u", "eom_Y_v",
    "eom_N_v", "eom_ur_v", "eom_N_r", "eom_ur_r"))


def _constant(value: torch.Tensor, dtype: torch.dtype | None):
    """A constant 0-d tensor in `dtype` (the dtype of the states it multiplies: an operation
    on two dtypes costs a cast), or the tensor itself where autograd or a functorch
    transform must see it."""
    if value.requires_grad or transformed(value) or type(value) not in (torch.Tensor, nn.Parameter):
        return value
    value = value.detach()
    return value if dtype is None or value.dtype == dtype else value.to(dtype)


def coefficient_view(values: Mapping[str, torch.Tensor], dtype: torch.dtype | None = None,
                     plain: bool = True) -> SimpleNamespace:
    """Attribute access to `values` (0-d tensors) and their `derived_constants`; with
    `plain`, constants detached and in `dtype` (no operation between two coefficients per
    forward, no module lookup, no cast)."""
    view = SimpleNamespace(**values)
    view.__dict__.update(derived_constants(view, values))
    if plain:
        view.__dict__.update({k: _constant(v, dtype) for k, v in view.__dict__.items()})
    every = list(view.__dict__.values())
    view.requires_grad = any(v.requires_grad for v in every)        # autograd may pass
    view.wrapped = any(transformed(v) for v in every)  # a torch.func transform
    view.dtype = dtype
    return view


class _WatchedTensors(dict):
    """A module's ``_buffers``/``_parameters`` that counts replacements (`to`, `double`,
    `torch.func.functional_call` write here), so cached values know when they are stale."""

    def __init__(self, *args):
        super().__init__(*args)
        self.changes = 0

    def __setitem__(self, key, value):
        self.changes += 1
        super().__setitem__(key, value)

    def __delitem__(self, key):
        self.changes += 1
        super().__delitem__(key)


class Coefficients(nn.Module):
    """Every ship parameter as a tensor attribute.

    Parameters
    ----------
    ship : the validated ship definition.
    trainable : names of parameters to expose as `nn.Parameter` (e.g. ``["X_vr", "Y_v"]``).
    bounds : optional ``{name: (low, high)}`` box for trainable parameters.
    dtype : float64 by default (the physics is compared with the oracle in float64).
    """

    def __init__(self, ship: Ship, trainable: Iterable[str] = (),
                 bounds: Mapping[str, tuple[float, float]] | None = None,
                 dtype: torch.dtype = torch.float64):
        super().__init__()
        self.ship_name = ship.name
        names = [parameter_name(k, "trainable") for k in trainable]
        bounds = {parameter_name(k, "bounds"): v for k, v in (bounds or {}).items()}
        for name in names:
            if name not in ship.parameters:
                raise ShipDefinitionError(
                    f"trainable: {name} is not a parameter of ship {ship.name!r} ({ship.describe_models()})")
        self.trainable_names = tuple(names)
        self.names = tuple(ship.parameters)
        self._bounds: dict[str, tuple[float, float]] = {}
        for name in self.names:
            value = torch.tensor(ship.parameters[name], dtype=dtype)
            if name in names:
                if name in bounds:
                    low, high = map(float, bounds[name])
                    if not low < float(value) < high:
                        raise ShipDefinitionError(
                            f"bounds: {name} = {float(value)} is not strictly inside [{low}, {high}]")
                    self._bounds[name] = (low, high)
                    value = raw_value(value, low, high)
                setattr(self, f"raw_{name}", nn.Parameter(value))
            else:
                self.register_buffer(name, value)
        self._watch()

    def _watch(self):
        if not isinstance(self._buffers, _WatchedTensors):
            self._buffers = _WatchedTensors(self._buffers)
            self._parameters = _WatchedTensors(self._parameters)
            self._loads = 0   # bumped by assign, load_state_dict and _apply
            self._view_key, self._views = None, {}

    def values_view(self, dtype: torch.dtype | None = None) -> SimpleNamespace:
        """The coefficients (``view.X_vr``) and their derived constants (`derived_constants`)
        for states of `dtype` (default: the coefficients'): constants as detached 0-d
        tensors of that dtype, tensors with their history where autograd or a functorch
        transform must see them (trainable coefficients with gradient on, swapped-in
        values). Cached until a coefficient changes (`assign`, `load_state_dict`, an
        optimizer step on a trainable one, `to`, `functional_call`)."""
        if captured():  # traced code reads the module (derived names too)
            return self
        self._watch()
        raws = [self._parameters[f"raw_{n}"] for n in self.trainable_names]
        live = torch.is_grad_enabled() and any(p.requires_grad for p in raws)
        key = (self._buffers.changes, self._parameters.changes, self._loads,
               tuple(p._version for p in raws))
        if key != self._view_key:
            self._view_key, self._views = key, {}
        if live:
            return self._live_view(dtype)
        view = self._views.get(dtype)
        if view is None:
            view = self._views[dtype] = coefficient_view({name: getattr(self, name) for name in self.names}, dtype)
        return view

    def _live_view(self, dtype: torch.dtype | None) -> SimpleNamespace:
        """The values view while trainable coefficients carry gradient: the trainable values
        anew (``low + (high-low)*sigmoid(raw)`` through autograd, as `coefficient_view` makes
        them), every other entry (the constant coefficients, the derived constants that do
        not depend on a trainable one, and the constant vectors the force products look up)
        kept from the view of the first such call until a constant changes (`to`, `assign`,
        `load_state_dict`, a replaced tensor, a step or a gradient switched on or off of a
        trainable coefficient without gradient). The same tensors as a view made anew, so the
        forward and its gradient are the same to the bit; a derived constant that depends on
        a trainable coefficient, or a `torch.func` transform, makes every view anew."""
        raws = [self._parameters[f"raw_{n}"] for n in self.trainable_names]
        # a trainable coefficient without gradient is a constant of the kept entries too
        key = (self._buffers.changes, self._parameters.changes, self._loads,
               tuple(None if p.requires_grad else p._version for p in raws))
        if key != self.__dict__.get("_live_key"):
            self._live_key, self._live_parts = key, {}
        parts = self._live_parts.get(dtype)
        if parts is None:
            view = coefficient_view({name: getattr(self, name) for name in self.names}, dtype)
            kept = {k: v for k, v in view.__dict__.items() if k not in self.trainable_names}
            flags = ("requires_grad", "wrapped", "dtype")
            constant = not view.wrapped and not any(
                isinstance(v, torch.Tensor) and (v.requires_grad or transformed(v))
                for k, v in kept.items() if k not in flags)
            view.__dict__["_vectors"] = {}
            # the kept entries in the view's order, a trainable value's place held (None)
            self._live_parts[dtype] = {**view.__dict__, **dict.fromkeys(self.trainable_names)} if constant else False
            return view
        if parts is False:
            return coefficient_view({name: getattr(self, name) for name in self.names}, dtype)
        fresh = {name: _constant(getattr(self, name), dtype) for name in self.trainable_names}
        if any(transformed(v) for v in fresh.values()):
            return coefficient_view({name: getattr(self, name) for name in self.names}, dtype)
        view = SimpleNamespace()
        view.__dict__.update(parts)   # the constant vectors' cache (``_vectors``) shared
        view.__dict__.update(fresh)
        view.requires_grad = any(v.requires_grad for v in fresh.values())
        return view

    def _load_from_state_dict(self, *args, **kwargs):
        self._watch()
        self._loads += 1
        super()._load_from_state_dict(*args, **kwargs)

    def _apply(self, fn, recurse=True):
        self._watch()
        self._loads += 1
        return super()._apply(fn, recurse)

    def __getattr__(self, name: str):
        if name in self.__dict__.get("trainable_names", ()):
            raw = super().__getattr__(f"raw_{name}")
            if name in self._bounds:
                return bounded_value(raw, *self._bounds[name])
            return raw
        try:
            return super().__getattr__(name)
        except AttributeError:
            if (name.startswith("_") or name not in DERIVED_NAMES or "names" not in self.__dict__
                    or self.__dict__.get("_deriving")):
                raise
            self.__dict__["_deriving"] = True
            try:
                derived = derived_constants(self, self.names)
            finally:
                self.__dict__["_deriving"] = False
            if name not in derived:
                raise
            return derived[name]

    def assign(self, values: Mapping[str, float]) -> None:
        """Set coefficients to these values (physical units, e.g. identified ones): a
        trainable one through its raw value (bounded: the inverse of the sigmoid, so the
        value must lie strictly inside its bounds), any other in place. No range check
        against the ship file: an estimate may leave it where the data say little."""
        with torch.no_grad():
            for name, value in values.items():
                if name in self.trainable_names:
                    raw = super().__getattr__(f"raw_{name}")
                    target = torch.tensor(float(value), dtype=raw.dtype)
                    if name in self._bounds:
                        target = raw_value(target, *self._bounds[name])
                    raw.copy_(target)
                else:
                    super().__getattr__(name).fill_(float(value))
        self._watch()
        self._loads += 1

    def values(self) -> dict[str, float]:
        """Current value of every parameter, as plain floats."""
        return {name: float(getattr(self, name).detach()) for name in self.names}


class PackedCoefficients(nn.Module):
    """The values of a `Coefficients` as one buffer (``values`` (n,)), read by the same
    names (``c.X_vr`` is ``values[i]``, a 0-d tensor equal to the original's value).

    What compiled code uses: one constant instead of one per coefficient, so a compiled
    loop passes one tensor per step, not a hundred. Inference only (values detached).
    """

    def __init__(self, coefficients: Coefficients):
        super().__init__()
        self.ship_name = coefficients.ship_name
        self.names = coefficients.names
        with torch.no_grad():
            derived = derived_constants(coefficients, coefficients.names)
        every = {**{n: getattr(coefficients, n).detach() for n in self.names}, **derived}
        self.index = {name: i for i, name in enumerate(every)}  # coefficients, then derived constants
        self.register_buffer("values", torch.stack([v.to(coefficients_dtype(coefficients)) for v in every.values()]))

    def __getattr__(self, name: str):
        index = self.__dict__.get("index", {})
        if name in index:
            return super().__getattr__("values")[index[name]]
        return super().__getattr__(name)

    def values_view(self, dtype: torch.dtype | None = None) -> "PackedCoefficients":
        """Itself: coefficients and derived constants are entries of ``values``."""
        return self


def coefficients_dtype(coefficients) -> torch.dtype:
    """The dtype of a `Coefficients`' values."""
    return next(iter(coefficients.state_dict().values())).dtype
