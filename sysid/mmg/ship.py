"""Ship definitions: a TOML file to a frozen, validated `Ship`.

A ship TOML (a file, or a bundled ``sysid/configs/ships/NAME.toml`` by name) holds principal particulars, masses, one
section per force component and the ``[sensors]`` table. Each of [hull], [propeller],
[rudder] and the optional [wind] names its force-model family (``model = "standard"``;
see `sysid.mmg.families`, the Esso Osaka's families when absent) and holds exactly the
coefficients that family needs (SI; dimensionless derivatives without the prime). A ship
without a [wind] section feels no wind force. `load_ship` checks every key (section and
allowed range) and applies overrides such as ``{"Xvr": 0.4535}``; keys are matched without
underscores and primes (``X_vr``, ``Xvr`` and ``X'vr`` are the same key).

The optional ``[maneuvering]`` table holds what standard maneuvers (`sysid.maneuvers`) take
as defaults: ``approach_speed`` [m/s], ``scale`` (full-scale L_pp over this ship's L_pp,
for Froude scaling; absent: the ship is taken as it is, no full-scale criteria that need
L/U) and ``rudder_rate`` [deg/s] of the steering gear at this ship's scale.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

from preprocessing.sensors import SensorLayout
from sysid.package_data import bundled_dir
from sysid.errors import ShipDefinitionError
from sysid.store.toml_file import read_toml

from sysid.mmg.families import COMPONENTS, DEFAULT_MODELS, FAMILIES, OPTIONAL_COMPONENTS

# name -> (section, low, high): what every ship needs, whatever its force models
BASE_PARAMETERS: dict[str, tuple[str, float, float]] = {
    # principal particulars
    "L_pp": ("principal", 1e-3, 1e3),
    "B": ("principal", 1e-3, 1e3),
    "d": ("principal", 1e-3, 1e2),
    "rho": ("principal", 500.0, 1100.0),
    # rigid body and added masses
    "m": ("mass", 1e-6, 1e12),
    "m_x": ("mass", 0.0, 1e12),
    "m_y": ("mass", 0.0, 1e12),
    "I_zz_J_zz": ("mass", 1e-9, 1e16),
    "x_G": ("mass", -1e2, 1e2),
}
SECTIONS = ("principal", "mass") + COMPONENTS
# [maneuvering] (optional): key -> (low, high, unit); see the module docstring
MANEUVERING_KEYS: dict[str, tuple[float, float, str]] = {
    "approach_speed": (1e-3, 50.0, "m/s"),
    "scale": (1.0, 1000.0, "-"),
    "rudder_rate": (0.1, 100.0, "deg/s"),
}


def active_parameters(models: Mapping[str, str]) -> dict[str, tuple[str, float, float]]:
    """name -> (section, low, high) of every key a ship with these force models needs,
    in file order (section by section; the base keys first, then the families')."""
    tables = [BASE_PARAMETERS] + [FAMILIES[c][models[c]].parameters for c in COMPONENTS if c in models]
    out: dict[str, tuple[str, float, float]] = {}
    for section in SECTIONS:
        for table in tables:
            for name, spec in table.items():
                if spec[0] == section:
                    out.setdefault(name, spec)
    return out


# every parameter any family knows (the first family's range where names are shared)
PARAMETERS: dict[str, tuple[str, float, float]] = {}
for _component in COMPONENTS:
    for _name in FAMILIES[_component]:
        for _key, _spec in active_parameters({_component: _name}).items():
            PARAMETERS.setdefault(_key, _spec)

_SENSOR_KEYS = ("gnss_fore", "gnss_aft", "gnss_baseline", "heading_offset",
                "anemometer_1", "anemometer_2", "fog")


def canonical_key(key: str) -> str:
    """Key as matched: ``X_vr`` == ``Xvr`` == ``X'vr`` (case matters: d is not D)."""
    return key.replace("_", "").replace("'", "")


_BY_CANONICAL = {canonical_key(k): k for k in PARAMETERS}
assert len(_BY_CANONICAL) == len(PARAMETERS), "parameter names collide after canonicalisation"


def parameter_name(key: str, source: str = "override") -> str:
    """The parameter's canonical spelling, or a clear error naming the unknown key."""
    try:
        return _BY_CANONICAL[canonical_key(key)]
    except KeyError:
        raise ShipDefinitionError(f"{source}: unknown ship parameter {key!r}") from None


@dataclass(frozen=True)
class Ship:
    """A validated ship definition.

    Attributes
    ----------
    name : ship identifier (``esso_osaka``).
    parameters : read-only mapping of every scalar in `PARAMETERS` (SI units).
    sensors : sensor layout for preprocessing.
    source : file it was read from.
    overrides : the parameters changed from the file's values.
    models : force-model family per component (``{"hull": "standard", ...}``); no "wind"
        key when the ship file has no [wind] section.
    maneuvering : the ``[maneuvering]`` values the file gives (`MANEUVERING_KEYS`; absent
        keys are absent): approach_speed [m/s], scale [-], rudder_rate [deg/s].
    """

    name: str
    parameters: Mapping[str, float]
    sensors: SensorLayout
    source: str = ""
    description: str = ""
    overrides: Mapping[str, float] = field(default_factory=dict)
    models: Mapping[str, str] = field(default_factory=lambda: MappingProxyType(dict(DEFAULT_MODELS)))
    maneuvering: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def has_wind(self) -> bool:
        """True when the ship file has a [wind] section (else the wind force is zero)."""
        return "wind" in self.models

    def describe_models(self) -> str:
        """``hull 'standard', propeller 'standard', rudder 'standard'`` for messages."""
        return ", ".join(f"{c} {m!r}" for c, m in self.models.items())

    def __getitem__(self, key: str) -> float:
        return self.parameters[parameter_name(key)]

    def with_overrides(self, overrides: Mapping[str, float], source: str = "override") -> "Ship":
        """A copy with some parameters replaced (validated like the file's values)."""
        params = dict(self.parameters)
        applied = dict(self.overrides)
        spec = active_parameters(self.models)
        for key, value in overrides.items():
            name = parameter_name(key, source)
            if name not in spec:
                raise ShipDefinitionError(
                    f"{source}: {name} is not a parameter of ship {self.name!r} ({self.describe_models()})")
            params[name] = _check_value(name, value, source, spec[name])
            applied[name] = params[name]
        return Ship(self.name, MappingProxyType(params), self.sensors, self.source,
                    self.description, MappingProxyType(applied), self.models, self.maneuvering)


def _check_value(name: str, value: object, source: str,
                 spec: tuple[str, float, float] | None = None) -> float:
    section, low, high = spec or PARAMETERS[name]
    where = f"{source}: [{section}] {name}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ShipDefinitionError(f"{where}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ShipDefinitionError(f"{where}: value must be finite, got {value!r}")
    if not low <= value <= high:
        raise ShipDefinitionError(f"{where} = {value!r} is out of range [{low}, {high}]")
    return value


def ships_dir() -> Path:
    """Directory of the bundled ship definitions (package data; ``$SYSID_CONFIGS/ships`` wins)."""
    return bundled_dir("ships")


def known_ships() -> list[str]:
    """The bundled ship names (`ships_dir`'s TOML files), sorted."""
    return sorted(p.stem for p in ships_dir().glob("*.toml"))


def resolve_ship_path(name_or_path: str | os.PathLike) -> Path:
    """A ship name (``esso_osaka``) or a path to a TOML file, to an existing path."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        if not candidate.is_file():
            raise ShipDefinitionError(f"ship definition {candidate}: file not found")
        return candidate
    path = ships_dir() / f"{name_or_path}.toml"
    if not path.is_file():
        known = known_ships()
        raise ShipDefinitionError(
            f"unknown ship {str(name_or_path)!r}: no {path}; known ships: {', '.join(known) or 'none'}"
        )
    return path


def load_ship(name_or_path: str | os.PathLike = "esso_osaka",
              overrides: Mapping[str, float] | None = None) -> Ship:
    """Read, validate and (optionally) override a ship definition.

    Parameters
    ----------
    name_or_path : bundled ship name or path to a ship TOML.
    overrides : parameter values replacing the file's, e.g. ``{"Xvr": 0.4535}``.
    """
    path = resolve_ship_path(name_or_path)
    doc, _ = read_toml(path, "ship file", ShipDefinitionError)
    src = str(path)
    for section in doc:
        if section not in SECTIONS + ("ship", "sensors", "maneuvering"):
            raise ShipDefinitionError(f"{src}: unknown section [{section}]")
    models = _read_models(doc, src)
    spec = active_parameters(models)
    params: dict[str, float] = {}
    for name, (section, _low, _high) in spec.items():
        table = doc.get(section)
        if not isinstance(table, dict):
            raise ShipDefinitionError(f"{src}: missing section [{section}]")
        if name not in table:
            owner = "" if name in BASE_PARAMETERS else f" (needed by {_owner(name, models)})"
            raise ShipDefinitionError(f"{src}: [{section}] {name} is missing{owner}")
        params[name] = _check_value(name, table[name], src, spec[name])
    for section in SECTIONS:
        for key in doc.get(section, {}):
            if key == "model" and section in COMPONENTS:
                continue
            if key not in spec or spec[key][0] != section:
                where = f"{section} model {models[section]!r}" if section in models else f"[{section}]"
                raise ShipDefinitionError(f"{src}: [{section}] {key} is not a parameter of {where}")
    sensors = _load_sensors(doc.get("sensors"), src)
    meta = doc.get("ship", {})
    ship = Ship(
        name=str(meta.get("name", path.stem)),
        parameters=MappingProxyType(params),
        sensors=sensors,
        source=src,
        description=str(meta.get("description", "")),
        overrides=MappingProxyType({}),
        models=MappingProxyType(models),
        maneuvering=MappingProxyType(_read_maneuvering(doc.get("maneuvering", {}), src)),
    )
    return ship.with_overrides(overrides, "override") if overrides else ship


def _read_models(doc: dict, src: str) -> dict[str, str]:
    """The force-model family of each component present in the file (``model = ...``;
    the Esso Osaka's families when a section names none)."""
    models: dict[str, str] = {}
    for component in COMPONENTS:
        table = doc.get(component)
        if table is None and component in OPTIONAL_COMPONENTS:
            continue
        if not isinstance(table, dict):
            raise ShipDefinitionError(f"{src}: missing section [{component}]")
        name = table.get("model", DEFAULT_MODELS[component])
        if name not in FAMILIES[component]:
            known = ", ".join(repr(k) for k in sorted(FAMILIES[component]))
            raise ShipDefinitionError(f"{src}: [{component}] model = {name!r} is not known; choose one of {known}")
        models[component] = name
    return models


def _read_maneuvering(table: object, src: str) -> dict[str, float]:
    """The optional [maneuvering] values, each checked against `MANEUVERING_KEYS`."""
    if not isinstance(table, dict):
        raise ShipDefinitionError(f"{src}: [maneuvering] must be a table of keys "
                                  f"({', '.join(MANEUVERING_KEYS)})")
    out = {}
    for key, value in table.items():
        if key not in MANEUVERING_KEYS:
            raise ShipDefinitionError(f"{src}: [maneuvering] {key} is not known; "
                                      f"choose from {', '.join(MANEUVERING_KEYS)}")
        low, high, unit = MANEUVERING_KEYS[key]
        out[key] = _check_value(key, value, src, ("maneuvering", low, high))
    return out


def _owner(name: str, models: Mapping[str, str]) -> str:
    owners = [f"{c} model {m!r}" for c, m in models.items() if name in FAMILIES[c][m].parameters]
    return " and ".join(owners)


def _load_sensors(table: object, src: str) -> SensorLayout:
    if not isinstance(table, dict):
        raise ShipDefinitionError(f"{src}: missing section [sensors]")
    unknown = set(table) - set(_SENSOR_KEYS)
    if unknown:
        raise ShipDefinitionError(f"{src}: [sensors] unknown key(s) {sorted(unknown)}")
    for key in _SENSOR_KEYS:
        if key not in table:
            raise ShipDefinitionError(f"{src}: [sensors] {key} is missing")
    try:
        return SensorLayout(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()})  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise ShipDefinitionError(f"{src}: {exc}") from None


def parse_overrides(items: list[str] | None, source: str = "--set") -> dict[str, float]:
    """``["Xvr=0.4535", "Y_v=-0.37"]`` to ``{"X_vr": 0.4535, "Y_v": -0.37}``."""
    out: dict[str, float] = {}
    for item in items or []:
        if "=" not in item:
            raise ShipDefinitionError(f"{source} {item!r}: expected NAME=VALUE")
        key, _, value = item.partition("=")
        name = parameter_name(key.strip(), source)
        try:
            out[name] = float(value)
        except ValueError:
            raise ShipDefinitionError(f"{source} {item!r}: value is not a number") from None
    return out
