"""The configurations a sweep trains: grid points or seeded random samples, each with a
stable name (the name of its directory, so a resumed sweep finds what it already did).

Names hold the exact values (floats as Python's shortest repr, which reads back to the same
number), so two values never share a name; a name that would be too long for a directory,
or that only the replacement of unsafe characters made equal to another, carries a digest
of the exact values as well."""
from __future__ import annotations

import hashlib
import itertools
import math
import re
from typing import Any

import numpy as np

from sysid.config.choices import Search
from sysid.sweep.spec import Axis, SweepSpec


MAX_NAME = 120   # characters of a point's name before it is cut and given a digest


def format_value(value: Any) -> str:
    """A value as it appears in a point's name: 0.003, 0.0010001 (every digit a float needs
    to read back exactly), 128x128 (widths), X_vr+Y_v (names), none (an empty list), true."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (tuple, list)):
        if not value:
            return "none"
        joiner = "+" if all(isinstance(v, str) for v in value) else "x"
        return joiner.join(format_value(v) for v in value)
    return str(value)


def _digest(values: dict[str, Any]) -> str:
    return hashlib.sha256(repr(sorted(values.items())).encode()).hexdigest()[:10]


def point_name(values: dict[str, Any]) -> str:
    """Directory-safe, stable name of a configuration: ``learning_rate=0.003,hidden=128x128``."""
    if not values:
        return "base"
    options = [k.split(".", 1)[1] for k in values]
    labels = [k.split(".", 1)[1] if options.count(k.split(".", 1)[1]) == 1 else k for k in values]
    text = ",".join(f"{label}={format_value(v)}" for label, v in zip(labels, values.values()))
    name = re.sub(r"[^A-Za-z0-9=.,_+-]", "_", text)
    if name != text or len(name) > MAX_NAME:  # no longer the exact values: add their digest
        name = name[:MAX_NAME - 11] + "-" + _digest(values)
    return name


def unique_names(points: list[dict[str, Any]]) -> list[str]:
    """`point_name` of each point; a `ConfigError` if two different points share a name
    (a digest collision) and the same name for equal points."""
    from sysid.errors import ConfigError

    seen: dict[str, dict] = {}
    names = []
    for values in points:
        name = point_name(values)
        if name in seen and seen[name] != values:
            raise ConfigError(f"configurations {seen[name]} and {values} have the same name {name!r}")
        seen[name] = values
        names.append(name)
    return names


def _draw(axis: Axis, rng: np.random.Generator) -> Any:
    low, high = axis.bounds
    if axis.distribution == "uniform":
        return float(rng.uniform(low, high))
    if axis.distribution == "loguniform":
        return float(math.exp(rng.uniform(math.log(low), math.log(high))))
    if axis.distribution == "randint":
        return int(rng.integers(int(low), int(high)))
    return axis.values[int(rng.integers(len(axis.values)))]


def sweep_points(spec: SweepSpec) -> list[dict[str, Any]]:
    """Grid: every combination of the axes' values, in file order. Random: ``samples`` draws
    from a generator seeded with ``search_seed`` (the same points on every run). Optuna
    proposes its points while it runs: none here."""
    if spec.search is Search.GRID:
        keys = spec.keys
        return [dict(zip(keys, combo)) for combo in itertools.product(*(a.values for a in spec.axes))]
    if spec.search is Search.RANDOM:
        rng = np.random.default_rng(spec.search_seed)
        return [{a.key: _draw(a, rng) for a in spec.axes} for _ in range(spec.samples)]
    return []
