"""Ship definitions: a TOML file to a frozen, validated `Ship`.

A ship TOML (``configs/ships/NAME.toml``) holds principal particulars, every MMG
coefficient (SI; dimensionless derivatives without the prime) and the ``[sensors]``
table. `load_ship` checks every key against `PARAMETERS` (section and allowed range)
and applies overrides such as ``{"Xvr": 0.4535}``; keys are matched without
underscores and primes (``X_vr``, ``Xvr`` and ``X'vr`` are the same key).
"""
from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

from preprocessing.sensors import SensorLayout
from sysid.errors import ShipDefinitionError

_BIG = 1e6

# name -> (section, low, high): the allowed closed range of each scalar.
PARAMETERS: dict[str, tuple[str, float, float]] = {
    # principal particulars
    "L_pp": ("principal", 1e-3, 1e3),
    "B": ("principal", 1e-3, 1e3),
    "d": ("principal", 1e-3, 1e2),
    "rho": ("principal", 500.0, 1100.0),
    "rho_air": ("principal", 0.5, 2.0),
    # rigid body and added masses
    "m": ("mass", 1e-6, 1e12),
    "m_x": ("mass", 0.0, 1e12),
    "m_y": ("mass", 0.0, 1e12),
    "I_zz_J_zz": ("mass", 1e-9, 1e16),
    "x_G": ("mass", -1e2, 1e2),
    # hull
    "X_0F": ("hull", -1.0, 0.0),
    "X_0A": ("hull", -1.0, 0.0),
    "X_vr": ("hull", -2.0, 2.0),
    "Y_v": ("hull", -5.0, 5.0),
    "Y_r": ("hull", -5.0, 5.0),
    "N_v": ("hull", -5.0, 5.0),
    "N_r": ("hull", -5.0, 5.0),
    "C_D": ("hull", 0.0, 5.0),
    "C_rY": ("hull", 0.0, 10.0),
    "C_rN": ("hull", 0.0, 10.0),
    # propeller
    "D": ("propeller", 1e-3, 20.0),
    "P": ("propeller", 1e-3, 40.0),
    "t_P": ("propeller", 0.0, 0.99),
    "w_P0": ("propeller", 0.0, 0.99),
    "tau": ("propeller", -10.0, 10.0),
    "C_P": ("propeller", -10.0, 10.0),
    "x_P": ("propeller", -1.0, 1.0),
    "k0": ("propeller", -5.0, 5.0),
    "k1": ("propeller", -5.0, 5.0),
    "k2": ("propeller", -5.0, 5.0),
    **{f"A{i}": ("propeller", -1.0, 1.0) for i in range(1, 9)},
    **{f"B{i}": ("propeller", -1.0, 1.0) for i in range(1, 9)},
    "C3": ("propeller", -5.0, 5.0),
    "C6": ("propeller", -5.0, 5.0),
    "C7": ("propeller", -5.0, 5.0),
    "C10": ("propeller", -10.0, 10.0),
    # rudder
    "A_R": ("rudder", 1e-6, 1e3),
    "lambda_R": ("rudder", 0.1, 10.0),
    "epsilon": ("rudder", 0.1, 5.0),
    "k_x": ("rudder", 0.0, 5.0),
    "k_xPR": ("rudder", 0.0, 5.0),
    "C_PR": ("rudder", -5.0, 5.0),
    "x_R": ("rudder", -1e3, 0.0),
    "l_R": ("rudder", -1e3, 1e3),
    "gamma_P": ("rudder", 0.0, 5.0),
    "gamma_N": ("rudder", 0.0, 5.0),
    "t_R": ("rudder", 0.0, 0.99),
    "a_H": ("rudder", -1.0, 5.0),
    "x_H": ("rudder", -1e3, 1e3),
    # wind
    "A_T": ("wind", 0.0, 1e5),
    "A_L": ("wind", 0.0, 1e6),
    "L_wind": ("wind", 1e-3, 1e3),
    **{k: ("wind", -10.0, 10.0) for k in ("X0", "X1", "X3", "X5", "Y1", "Y3", "Y5", "N1", "N2", "N3")},
}

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
    """

    name: str
    parameters: Mapping[str, float]
    sensors: SensorLayout
    source: str = ""
    description: str = ""
    overrides: Mapping[str, float] = field(default_factory=dict)

    def __getitem__(self, key: str) -> float:
        return self.parameters[parameter_name(key)]

    def with_overrides(self, overrides: Mapping[str, float], source: str = "override") -> "Ship":
        """A copy with some parameters replaced (validated like the file's values)."""
        params = dict(self.parameters)
        applied = dict(self.overrides)
        for key, value in overrides.items():
            name = parameter_name(key, source)
            params[name] = _check_value(name, value, source)
            applied[name] = params[name]
        return Ship(self.name, MappingProxyType(params), self.sensors, self.source,
                    self.description, MappingProxyType(applied))


def _check_value(name: str, value: object, source: str) -> float:
    section, low, high = PARAMETERS[name]
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
    """Directory of the bundled ship definitions (``$SYSID_CONFIGS/ships`` wins)."""
    env = os.environ.get("SYSID_CONFIGS")
    if env:
        return Path(env) / "ships"
    return Path(__file__).resolve().parents[1] / "configs" / "ships"


def resolve_ship_path(name_or_path: str | os.PathLike) -> Path:
    """A ship name (``esso_osaka``) or a path to a TOML file, to an existing path."""
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or candidate.exists():
        if not candidate.is_file():
            raise ShipDefinitionError(f"ship definition {candidate}: file not found")
        return candidate
    path = ships_dir() / f"{name_or_path}.toml"
    if not path.is_file():
        known = sorted(p.stem for p in ships_dir().glob("*.toml"))
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
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ShipDefinitionError(f"{path}: not valid TOML ({exc})") from None
    src = str(path)
    params: dict[str, float] = {}
    known_sections = {s for s, _, _ in PARAMETERS.values()} | {"ship", "sensors"}
    for section in doc:
        if section not in known_sections:
            raise ShipDefinitionError(f"{src}: unknown section [{section}]")
    for name, (section, _, _) in PARAMETERS.items():
        table = doc.get(section)
        if not isinstance(table, dict):
            raise ShipDefinitionError(f"{src}: missing section [{section}]")
        if name not in table:
            raise ShipDefinitionError(f"{src}: [{section}] {name} is missing")
        params[name] = _check_value(name, table[name], src)
    for section in known_sections - {"ship", "sensors"}:
        for key in doc.get(section, {}):
            if key not in PARAMETERS or PARAMETERS[key][0] != section:
                raise ShipDefinitionError(f"{src}: [{section}] {key} is not a known parameter")
    sensors = _load_sensors(doc.get("sensors"), src)
    meta = doc.get("ship", {})
    ship = Ship(
        name=str(meta.get("name", path.stem)),
        parameters=MappingProxyType(params),
        sensors=sensors,
        source=src,
        description=str(meta.get("description", "")),
        overrides=MappingProxyType({}),
    )
    return ship.with_overrides(overrides, "override") if overrides else ship


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
        return SensorLayout(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()})
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
