"""MMG coefficients as tensors, so a subset can be identified by gradient.

`Coefficients` holds every scalar of a `Ship` (the keys of its force-model families) as a
0-d tensor attribute (``c.X_vr``), as a buffer by default, or as a bounded trainable
parameter. A trainable coefficient is
stored as an unconstrained raw value; its value is ``low + (high-low)*sigmoid(raw)``
when bounds are given.
"""
from __future__ import annotations

from typing import Iterable, Mapping

import torch
from torch import nn

from sysid.mmg.ship import Ship, parameter_name
from sysid.errors import ShipDefinitionError


def raw_value(value: torch.Tensor, low: float, high: float) -> torch.Tensor:
    """The unconstrained raw value whose ``low + (high-low)*sigmoid(raw)`` is `value`."""
    frac = (value - low) / (high - low)
    return torch.log(frac / (1 - frac))


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

    def __getattr__(self, name: str):
        if name in self.__dict__.get("trainable_names", ()):
            raw = super().__getattr__(f"raw_{name}")
            if name in self._bounds:
                low, high = self._bounds[name]
                return low + (high - low) * torch.sigmoid(raw)
            return raw
        return super().__getattr__(name)

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
        self.index = {name: i for i, name in enumerate(self.names)}
        self.register_buffer("values", torch.stack([getattr(coefficients, n).detach() for n in self.names]))

    def __getattr__(self, name: str):
        index = self.__dict__.get("index", {})
        if name in index:
            return super().__getattr__("values")[index[name]]
        return super().__getattr__(name)
