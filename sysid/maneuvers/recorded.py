"""The indices of recorded turning and zig-zag runs beside each model's indices of the same
maneuver, computed the same way.

A recorded run's order is its largest rudder angle (95th percentile of |delta|, rounded to
a whole degree); the turn is the longest stretch of samples within 10 % of it, a zig-zag's
first order the first such stretch of `HOLD_S` (the approach's course keeping never holds
that long); the execute is the last sample before it with the rudder below half of the
order on that side. The maneuver is a turning circle of that angle, or a zig-zag A/A (the
dataset's zig-zags check at the rudder angle; a scenario name such as "Zigzag 20/20" gives
both).

Like for like: a model predicts the run from the recorded state at the execute with the
recorded inputs (zero-order hold, the protocol's rate and integrator), which for a turning
circle is the maneuver itself. A zig-zag's IMO overshoots are those of the model run
closed loop from the record's approach (`approach_conditions`: surge speed and
revolutions at the execute, the record's rudder angle, check angle and rudder rate, its
mean true wind relative to the approach heading) with the heading-triggered reversals
(`sysid.maneuvers.simulate`); the record's own overshoots are taken between the same
heading-triggered reversals. The open-loop prediction's peak heading deviation beyond the
check angle between the recorded rudder's reversals stays, under its own name
(``open_loop_first_peak_deg``, ``open_loop_second_peak_deg``; the record's: the same peak
of the record): under the same rudder it shows how far the model lags or leads the ship.
"""
from __future__ import annotations

import functools
import math
import multiprocessing
import os
import re
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
import pandas as pd
import torch
from torch import nn

from sysid.data.datasets import TEST_FILES, data_dir
from sysid.data.recordings import Run, read_runs
from sysid.data.scenario import FOLDERS, Maneuver as Kind, recognise
from sysid.dynamics.equations import eager_predict
from sysid.dynamics.integrators import Integrator, Method
from sysid.errors import DataError
from sysid.hybrid.ensemble import MembersSideBySide, SeedEnsemble
from sysid.hybrid.rollout_gate import with_rollout_gate
from sysid.maneuvers.any_model import load_maneuver_model
from sysid.maneuvers.base import Conditions, Maneuver, Side, TurningCircle, ZigZag
from sysid.maneuvers.indices import INDEX_COLUMNS, KIND_INDICES, Track, maneuver_indices, zigzag_overshoots
from sysid.maneuvers.simulate import gate_off_share, simulate_rows
from sysid.device import compute_threads
from sysid.store.manifest import has_manifest, seed_run_dirs
from sysid.store.files import write_csv
from sysid.workers import in_workers

OPEN_LOOP_COLUMNS = ("open_loop_first_peak_deg", "open_loop_second_peak_deg")
RECORD_INDEX_COLUMNS = (*INDEX_COLUMNS, *OPEN_LOOP_COLUMNS)
# the indices of the record table per kind: a zig-zag's IMO overshoots, then the open-loop peaks
RECORD_INDICES = {"turning": KIND_INDICES["turning"], "zigzag": (*KIND_INDICES["zigzag"], *OPEN_LOOP_COLUMNS)}
RECORD_COLUMNS = ["scenario", "file", "maneuver", "model", "n_members", *RECORD_INDEX_COLUMNS,
                  *(f"{c}_std" for c in RECORD_INDEX_COLUMNS), "gate_off_share"]
CLOSED_LOOP_DT = 0.1  # [s] step of the closed-loop zig-zags (classical RK4)
RECORDED = "recorded"  # the `model` of the record's own row
HOLD_S = 5.0  # [s] a zig-zag's first order is the first stretch this long near the run's largest angle


def recorded_test_runs(data: str | os.PathLike | None = None, rate: float = 1.0) -> dict[str, Run]:
    """The protocol's turning and zig-zag test runs (scenario -> `Run` at `rate` [Hz])."""
    root = data_dir(data)
    names = [name for name in TEST_FILES if name.startswith(("Turning", "Zigzag"))]
    return dict(zip(names, read_runs([root / TEST_FILES[n] for n in names], rate)))


def recorded_maneuver(run: Run, scenario: str = "") -> tuple[Maneuver, int]:
    """(the maneuver of a recorded run, the sample index of its execute). The kind comes
    from the scenario name (else the file's name: ``turn...``, ``zigzag...``), the file's
    folder (``turning/``, ``zigzag/``), else the signals (`sysid.data.scenario.recognise`)."""
    label = scenario.lower() if scenario else run.name.lower()[:6]  # "Zigzag 20/20"; "turn_14-Sep-..."
    folder = FOLDERS.get(run.path.parent.name.lower())
    kind = ("zigzag" if "zigzag" in label else "turning" if "turn" in label[:4] or " turn" in label
            else folder.value if folder in (Kind.TURNING, Kind.ZIGZAG) else None)
    found = None
    if kind is None:
        found = recognise(run)
        kind = found.kind.value if found.kind in (Kind.TURNING, Kind.ZIGZAG) else None
    if kind is None:
        raise DataError(f"{run.path}: not a turning or zig-zag run (its rudder and heading record "
                        f"{found.name if found else 'neither'}; name it in the scenario or keep it in a turning/ "
                        "or zigzag/ folder)")
    rudder = run.inputs[:, 1]
    order = float(np.percentile(np.abs(rudder), 95))
    if order < math.radians(1.0):
        raise DataError(f"{run.path}: no rudder order found (95th percentile of |delta_rudder| below 1 deg)")
    full = np.concatenate(([0], (np.abs(rudder) >= 0.9 * order).astype(int), [0]))
    edges = np.diff(full)
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]  # stretches at the order
    lengths = (ends - starts) * run.dt
    if kind == "turning":  # the turn: the longest stretch at the order
        first = int(starts[np.argmax(lengths)])
    else:  # the first order of the zig-zag: the first stretch held HOLD_S
        held = np.nonzero(lengths >= HOLD_S)[0]
        if not len(held):
            raise DataError(f"{run.path}: the rudder never holds its order ({math.degrees(order):.0f} deg) "
                            f"for {HOLD_S:g} s")
        first = int(starts[held[0]])
    sign = 1.0 if rudder[first] > 0 else -1.0
    side = Side.STARBOARD if sign > 0 else Side.PORT
    execute = first
    while execute > 0 and sign * rudder[execute] >= 0.5 * order:  # back to the sample before the order
        execute -= 1
    angle = float(round(math.degrees(order)))
    if kind == "turning":
        return TurningCircle(angle, side), execute
    pair = re.search(r"(\d+(?:\.\d+)?)\s*/\s*(\d+(?:\.\d+)?)", scenario)
    if pair:
        rudder_deg, check_deg = float(pair[1]), float(pair[2])
    elif found is not None and found.heading_deg is not None:   # the check angle the record shows
        rudder_deg, check_deg = angle, found.heading_deg
    else:
        rudder_deg, check_deg = angle, angle
    if not 0.0 < check_deg <= 180.0:
        raise DataError(f"{run.path}: a zig-zag's heading deviation of {check_deg:g} deg at its rudder reversals "
                        "is no check angle in (0, 180] deg: not a zig-zag run (name its scenario, e.g. "
                        "\"Zigzag 20/20\", or keep it out of the recorded runs)")
    return ZigZag(rudder_deg, check_deg, side), execute


def approach_conditions(run: Run, execute: int, dt: float = CLOSED_LOOP_DT) -> Conditions:
    """The record's approach as `Conditions` of a closed-loop maneuver: surge speed u [m/s]
    and revolutions [rps] at the execute; rudder rate [deg/s]: the record's fastest rudder
    move, max |d delta/dt| at the log's rate (a lower bound when the gear moves within one
    sample); true wind: its mean speed [m/s] and circular-mean direction over the maneuver,
    turned into the frame of the approach heading (the simulation starts at psi = 0); the
    duration of the record after the execute [s]; RK4 at `dt` [s]."""
    delta = np.degrees(run.inputs[:, 1])
    rate = float(np.max(np.abs(np.diff(delta)) / np.diff(run.t)))
    wind = run.inputs[execute:, 2:4]
    direction = math.atan2(np.mean(np.sin(wind[:, 1])), np.mean(np.cos(wind[:, 1]))) - run.states[execute, 4]
    return Conditions(speed=float(run.states[execute, 1]), rps=float(run.inputs[execute, 0]), rudder_rate=rate,
                      dt=dt, duration=float(run.t[-1] - run.t[execute]), wind_speed=float(np.mean(wind[:, 0])),
                      wind_direction=direction % (2.0 * math.pi))


def closed_loop_indices(model: nn.Module, runs: Sequence[Run], maneuvers: Sequence[Maneuver | None],
                        executes: Sequence[int], dt: float = CLOSED_LOOP_DT) -> list[dict[str, float] | None]:
    """Each zig-zag's indices of `model` run closed loop from its record's approach
    (`approach_conditions`, step `dt` [s]), all zig-zags as rows of one batched rollout
    (`simulate_rows`: each as if run alone, to round-off); None for another maneuver (its
    prediction is the recorded run's) or a run without one."""
    rows = [i for i, m in enumerate(maneuvers) if m is not None and m.kind == "zigzag"]
    results = simulate_rows(model, [maneuvers[i] for i in rows],
                            [approach_conditions(runs[i], executes[i], dt) for i in rows], distances=False)
    found: list[dict[str, float] | None] = [None] * len(maneuvers)
    for i, result in zip(rows, results):
        found[i] = result.indices.as_dict()
    return found


def _predictions(model: nn.Module, runs: Sequence[Run], starts: Sequence[int], method: Method,
                 maneuvers: Sequence[Maneuver] | None = None, dt: float = CLOSED_LOOP_DT,
                 gates: Sequence[nn.Module] | None = None) -> list[tuple[np.ndarray, float | None, dict | None]]:
    """Each run predicted from its recorded state at `starts` with its recorded inputs, all
    runs in one batched integration (shorter ones padded with their last inputs), and each
    zig-zag of `maneuvers` run closed loop (`closed_loop_indices`): (states (T_i, 6), kNN
    gate off share or None, closed-loop indices or None) per run; the gate's share of run i
    from `gates[i]` (default: `model`)."""
    lengths = [len(r) - s for r, s in zip(runs, starts)]
    longest = max(lengths)
    x0 = torch.tensor(np.stack([r.states[s] for r, s in zip(runs, starts)]), dtype=torch.float64)
    inputs = []
    for r, s in zip(runs, starts):
        u = r.inputs[s:]
        inputs.append(np.concatenate([u, np.repeat(u[-1:], longest - len(u), 0)]))
    u = torch.tensor(np.stack(inputs, 1), dtype=torch.float64)
    # the kNN gate's decisions along the rollout from earlier steps' scans (`RolloutGate`: the gate's own)
    states = eager_predict(with_rollout_gate(model), x0, u, runs[0].dt, Integrator(method))
    closed = closed_loop_indices(model, runs, maneuvers if maneuvers is not None else [None] * len(runs), starts, dt)
    return [(states[:n, i].numpy(), gate_off_share(gates[i] if gates is not None else model, states[:n - 1, i],
                                                   u[:n - 1, i]), closed[i])
            for i, n in enumerate(lengths)]


def group_predictions(members: Sequence[nn.Module], runs: Sequence[Run], starts: Sequence[int], method: Method,
                      maneuvers: Sequence[Maneuver] | None = None, dt: float = CLOSED_LOOP_DT
                      ) -> tuple[list[Predictions], Predictions]:
    """(`_predictions` of each of the K `members`, of their mean-of-seeds ensemble
    `SeedEnsemble`): all K + 1 models' predictions as one batched rollout (each model on its
    own block of rows, `MembersSideBySide`: the same numbers as each model's own rollout, to
    round-off) where the ensemble's batched rate applies, else one model after another."""
    ensemble = SeedEnsemble(list(members))
    side = MembersSideBySide(ensemble)
    x0 = torch.zeros(len(runs) * (len(members) + 1), 6, dtype=torch.float64)
    if side.no_grad_rate(x0) is None:
        return ([_predictions(m, runs, starts, method, maneuvers, dt) for m in members],
                _predictions(ensemble, runs, starts, method, maneuvers, dt))
    blocks = len(members) + 1
    found = _predictions(side, list(runs) * blocks, list(starts) * blocks, method,
                         None if maneuvers is None else list(maneuvers) * blocks, dt,
                         gates=[m for m in (*members, ensemble) for _ in runs])
    n = len(runs)
    return [found[j * n:(j + 1) * n] for j in range(len(members))], found[len(members) * n:]


def _row(scenario: str, run: Run, maneuver: Maneuver, model: str, values: list[dict], shares: list) -> dict:
    row = {"scenario": scenario, "file": run.name, "maneuver": maneuver.name, "model": model, "n_members": len(values)}
    for c in RECORD_INDEX_COLUMNS:
        column = np.array([v[c] for v in values], dtype=float)
        finite = column[np.isfinite(column)]
        row[c] = float(finite.mean()) if len(finite) == len(column) else math.nan
        row[f"{c}_std"] = float(np.std(finite, ddof=1)) if len(finite) >= 2 else math.nan
    known = [s for s in shares if s is not None]
    row["gate_off_share"] = float(np.mean(known)) if known else math.nan
    return row


# per run: (states (T_i, 6), gate off share, a zig-zag's closed-loop indices)
Predictions = list[tuple[np.ndarray, "float | None", "dict | None"]]


def _execute_starts(runs: Mapping[str, Run]) -> list[int]:
    """Sample index of each run's execute (scenario -> `Run`, in order), where predictions start."""
    return [start for _, start in (recorded_maneuver(run, scenario) for scenario, run in runs.items())]


def _maneuvers(runs: Mapping[str, Run]) -> list[Maneuver]:
    """Each run's maneuver (scenario -> `Run`, in order)."""
    return [maneuver for maneuver, _ in (recorded_maneuver(run, scenario) for scenario, run in runs.items())]


def like_for_like(maneuver: Maneuver, track: Track, rudder: np.ndarray, closed: dict | None) -> dict[str, float]:
    """The record-table indices of one run (`RECORD_INDEX_COLUMNS`): for a zig-zag, the IMO
    overshoots of `closed` (a model's closed-loop indices) or, for the record (None), of
    `track` between its heading-triggered reversals; and the peaks beyond the check angle
    of `track` between the reversals of the recorded `rudder` (the open-loop peaks)."""
    values = maneuver_indices(maneuver, track, rudder).as_dict()
    if not isinstance(maneuver, ZigZag):
        return {**values, **dict.fromkeys(OPEN_LOOP_COLUMNS, math.nan)}
    peaks = dict(zip(OPEN_LOOP_COLUMNS, zigzag_overshoots(track, maneuver.check_deg, rudder)))
    imo = closed if closed is not None else maneuver_indices(maneuver, track).as_dict()
    return {**values, **{k: imo[k] for k in KIND_INDICES["zigzag"]}, **peaks}


def record_comparison(models: Mapping[str, Sequence[nn.Module]], runs: Mapping[str, Run],
                      method: Method = Method.EULER, closed_loop_dt: float = CLOSED_LOOP_DT) -> pd.DataFrame:
    """`RECORD_COLUMNS` rows: for each run (scenario -> `Run`) the record's indices, then
    each model's (label -> its models: one, or several seeds whose indices are averaged,
    with their standard deviation in ``<index>_std``) indices of it, like for like (the
    module's docstring; zig-zags closed loop at step `closed_loop_dt` [s])."""
    starts, maneuvers = _execute_starts(runs), _maneuvers(runs)
    predicted = {label: [_predictions(m, list(runs.values()), starts, method, maneuvers, closed_loop_dt)
                         for m in members]
                 for label, members in models.items()}
    return compared(predicted, runs)


def compared(predicted: Mapping[str, Sequence[Predictions]], runs: Mapping[str, Run]) -> pd.DataFrame:
    """`record_comparison`'s rows from its models' predictions (label -> per member: the
    predictions of `runs` in their order, from each run's execute)."""
    scenarios = list(runs)
    found = [recorded_maneuver(runs[s], s) for s in scenarios]
    rows = []
    for i, scenario in enumerate(scenarios):
        run, (maneuver, start) = runs[scenario], found[i]
        t = run.t[start:] - run.t[start]
        rudder = run.inputs[start:, 1]
        record = like_for_like(maneuver, Track.of(t, run.states[start:]), rudder, None)
        rows.append(_row(scenario, run, maneuver, RECORDED, [record], [None]))
        for label, per_member in predicted.items():
            values = [like_for_like(maneuver, Track.of(t, p[i][0]), rudder, p[i][2]) for p in per_member]
            rows.append(_row(scenario, run, maneuver, label, values, [p[i][1] for p in per_member]))
    frame = pd.DataFrame(rows, columns=RECORD_COLUMNS)
    frame.loc[frame.model == RECORDED, "n_members"] = 0
    return frame


def recorded_maneuver_runs(runs: Sequence[Run]) -> tuple[dict[str, Run], list[Run]]:
    """(label -> run for the runs recognised as turning circles or zig-zags, by
    `recorded_maneuver`: "zigzag 20/20 NAME", "turning 35 NAME"; the other runs)."""
    found, other = {}, []
    for run in runs:
        try:
            maneuver, _ = recorded_maneuver(run)
        except DataError:
            other.append(run)
            continue
        angle = f"{maneuver.rudder_deg:g}/{maneuver.check_deg:g}" if isinstance(maneuver, ZigZag) else \
            f"{getattr(maneuver, 'rudder_deg', 0.0):g}"
        found[f"{maneuver.kind} {angle} {run.name}"] = run
    return found, other


def differences(frame: pd.DataFrame) -> pd.DataFrame:
    """`side_by_side` of a `record_comparison` frame with, per model, its difference from
    the record (``<model> - recorded``) in the index's unit."""
    wide = side_by_side(frame)
    models = [m for m in dict.fromkeys(frame.model) if m != RECORDED]
    for m in models:
        wide[f"{m} - {RECORDED}"] = wide[m] - wide[RECORDED]
    return wide


def side_by_side(frame: pd.DataFrame) -> pd.DataFrame:
    """A `record_comparison` frame as one row per (scenario, index that applies) and one
    column per model, the record first: what the report shows."""
    rows = []
    for (scenario, maneuver), group in frame.groupby(["scenario", "maneuver"], sort=False):
        kind = "zigzag" if maneuver.startswith("zigzag") else "turning"
        for index in RECORD_INDICES[kind]:
            values = dict(zip(group.model, group[index]))
            if all(isinstance(v, float) and math.isnan(v) for v in values.values()):
                continue
            rows.append({"scenario": scenario, "maneuver": maneuver, "index": index, **values})
    return pd.DataFrame(rows)


def run_models(run_dirs: Mapping[str, str | os.PathLike]) -> dict[str, list[nn.Module]]:
    """label -> models of run directories (a folder of seed run directories gives each
    seed's model)."""
    out = {}
    for label, path in run_dirs.items():
        subject = load_maneuver_model(Path(path))
        out[label] = [m for _, m in subject.members] if subject.spread == "seeds" else [subject.model]
    return out


RECORD_FILE = "maneuver_indices.csv"


def model_paths(path: str | os.PathLike) -> list[Path]:
    """The paths whose models `run_models` takes from `path`, in its order: a folder's seed
    run directories, else `path` itself (a run directory or ship)."""
    path = Path(path)
    if not path.is_dir() or has_manifest(path):
        return [path]
    seeds = seed_run_dirs(path)
    return seeds or [path]  # none: loading `path` gives the clear error


def _predicted_run(path: Path, runs: Sequence[Run], starts: Sequence[int], method: Method,
                   threads: int, maneuvers: Sequence[Maneuver] | None = None,
                   dt: float = CLOSED_LOOP_DT) -> tuple[Path, Predictions]:
    """(path, `_predictions` of the model of one run directory): one worker's item."""
    with compute_threads(threads):
        return path, _predictions(load_maneuver_model(path).model, runs, starts, method, maneuvers, dt)


def _predicted_group(paths: Sequence[Path], ensemble: Path, runs: Sequence[Run], starts: Sequence[int],
                     method: Method, threads: int, maneuvers: Sequence[Maneuver] | None = None,
                     dt: float = CLOSED_LOOP_DT) -> dict[Path, Predictions]:
    """{path: `_predictions`} of the models of the seed run directories `paths` and of their
    mean-of-seeds ensemble under the path `ensemble` (`group_predictions`): one worker's item."""
    with compute_threads(threads):
        members = [load_maneuver_model(p).model for p in paths]
        seeds, mean = group_predictions(members, runs, starts, method, maneuvers, dt)
    return {**dict(zip(paths, seeds)), ensemble: mean}


def group_predictor(runs: Mapping[str, Run], method: Method = Method.EULER, threads: int = 1,
                    closed_loop_dt: float = CLOSED_LOOP_DT) -> Callable[[Sequence[Path], Path], dict[Path, Predictions]]:
    """As `record_predictor`, for a protocol run's seeds and their mean-of-seeds ensemble
    together: (the seeds' run directories, the ensemble's path) -> {path: predictions}, the
    same predictions as `record_predictor` gives each path (to round-off: one batched
    rollout, `group_predictions`); picklable."""
    return functools.partial(_predicted_group, runs=list(runs.values()), starts=_execute_starts(runs),
                             method=method, threads=threads, maneuvers=_maneuvers(runs), dt=closed_loop_dt)


def record_predictor(runs: Mapping[str, Run], method: Method = Method.EULER, threads: int = 1,
                     closed_loop_dt: float = CLOSED_LOOP_DT) -> Callable[[Path], tuple[Path, Predictions]]:
    """The work of one worker item of `write_record_comparison` for the recorded runs
    `runs` (`recorded_test_runs`): a model's path (`model_paths`) -> (path, its predictions),
    with `threads` torch threads; picklable, for worker processes."""
    return functools.partial(_predicted_run, runs=list(runs.values()), starts=_execute_starts(runs), method=method,
                             threads=threads, maneuvers=_maneuvers(runs), dt=closed_loop_dt)


def write_record_comparison(out_dir: str | os.PathLike, run_dirs: Mapping[str, str | os.PathLike],
                            data: str | os.PathLike | None = None, method: Method = Method.EULER,
                            workers: int = 1, threads: int = 1, closed_loop_dt: float = CLOSED_LOOP_DT,
                            predicted: Mapping[Path, Predictions] | None = None) -> Path:
    """``out_dir/maneuver_indices.csv``: `record_comparison` of the protocol's turning and
    zig-zag test runs (1 Hz) and the models of `run_dirs` (label -> run directory or folder
    of seed run directories). `workers` > 1 predicts the models side by side in that many
    worker processes (`sysid.workers`, `threads` torch threads each); `predicted` (a model's
    path -> its predictions by `record_predictor` with the same settings, made earlier)
    are not predicted again. The numbers depend on neither."""
    runs = recorded_test_runs(data)
    if workers <= 1 and not predicted:
        frame = record_comparison(run_models(run_dirs), runs, method, closed_loop_dt)
        return write_csv(frame, Path(out_dir) / RECORD_FILE, float_format="%.6g")
    done = dict(predicted or {})
    paths = {label: model_paths(path) for label, path in run_dirs.items()}
    items = [p for found in paths.values() for p in found if p not in done]
    if items:
        work = record_predictor(runs, method, threads, closed_loop_dt)
        done.update(in_workers(work, items, workers, multiprocessing.get_context("spawn")))
    frame = compared({label: [done[p] for p in found] for label, found in paths.items()}, runs)
    return write_csv(frame, Path(out_dir) / RECORD_FILE, float_format="%.6g")
