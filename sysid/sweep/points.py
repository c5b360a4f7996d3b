"""The configurations a sweep trains: grid points or seeded random samples, each with a
stable name (the name of its directory, so a resumed sweep finds what it already did)."""
from __future__ import annotations

import hashlib
import itertools
import math
import re
from typing import Any

import numpy as np

from sysid.config.choices import Search
from sysid.sweep.spec import Axis, SweepSpec


def format_value(value: Any) -> str:
    """A value as it appears in a point's name: 0.003, 128x128 (widths), X_vr+Y_v (names),
    none (an empty list), true."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (tuple, list)):
        if not value:
            return "none"
        joiner = "+" if all(isinstance(v, str) for v in value) else "x"
        return joiner.join(format_value(v) for v in value)
    return str(value)


def point_name(values: dict[str, Any]) -> str:
    """Directory-safe, stable name of a configuration: ``learning_rate=0.003,hidden=128x128``."""
    if not values:
        return "base"
    options = [k.split(".", 1)[1] for k in values]
    labels = [k.split(".", 1)[1] if options.count(k.split(".", 1)[1]) == 1 else k for k in values]
    name = ",".join(f"{label}={format_value(v)}" for label, v in zip(labels, values.values()))
    name = re.sub(r"[^A-Za-z0-9=.,_+-]", "_", name)
    if len(name) > 96:
        digest = hashlib.sha256(repr(sorted(values.items())).encode()).hexdigest()[:10]
        name = name[:80] + "-" + digest
    return name


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
