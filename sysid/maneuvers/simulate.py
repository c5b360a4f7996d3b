"""Standard maneuvers of any force model: conditions from the ship file and the model,
closed-loop simulation (eager and batched over maneuvers, or compiled), indices, the kNN
gate's decision and distance at every step and its off share, and the spread over an ensemble's members or seeds.

    from sysid.maneuvers import load_maneuver_model, default_conditions, run_maneuvers, imo_maneuvers
    subject = load_maneuver_model("runs/hybrid_D2")                 # or "configs/ships/kvlcc2_l7.toml"
    conditions, sources = default_conditions(subject.model, subject.ship)
    results = run_maneuvers(subject, imo_maneuvers(), conditions, compiled=True)
    results[0].indices.advance_m                                      # [m]
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np
import torch
from torch import nn

from sysid.dynamics.integrators import Method
from sysid.evaluation.divergence import PhysicalRange
from sysid.maneuvers.any_model import ManeuverModel, ship_of
from sysid.maneuvers.base import Conditions, Maneuver, ManeuverError, ManeuverResult, check_number
from sysid.maneuvers.closed_loop import compiled_loop, loop_is_cached, run_compiled, run_eager
from sysid.maneuvers.controllers import initial_orders, order_parameters
from sysid.maneuvers.indices import Track, maneuver_indices
from sysid.maneuvers.straight import straight_running_rps
from sysid.mmg.ship import Ship
from sysid.channel_names import VELOCITY_INDEX

if TYPE_CHECKING:
    from sysid.fast.payoff import PathChoice

FULL_SCALE_RUDDER_RATE = 2.32  # deg/s: 65 deg in 28 s (SOLAS II-1/29), at full scale
DURATION_L_OVER_U = 80.0       # default duration [s]: this many times L/U0
GATE_CHUNK = 1024              # rows per call when the kNN gate is evaluated along a maneuver
SPEED_OVER_U0 = 3.0            # without a training range: a maneuver faster than this many times U0 diverged


def first_divergence(t: np.ndarray, states: np.ndarray, speed0: float,
                     limits: PhysicalRange | None = None) -> tuple[float, str] | None:
    """(time [s], why) at which a simulated maneuver diverged, or None: the first state
    (t (T,), states (T, 6), `sysid.channel_names`) that is not finite, or whose speed sqrt(u^2 +
    v_m^2) exceeds `limits.factor` times the larger of the training logs' largest speed and
    the approach speed `speed0` [m/s], or whose |r| exceeds that factor times their largest
    |r|. Without a training range (`limits` None): non-finite, or speed beyond
    `SPEED_OVER_U0` x `speed0`."""
    states = np.asarray(states, dtype=float)
    u, v, r = (states[:, i] for i in VELOCITY_INDEX)
    factor = limits.factor if limits is not None else SPEED_OVER_U0
    top_speed = factor * (max(limits.speed, speed0) if limits is not None else speed0)
    top_r = factor * limits.yaw_rate if limits is not None else math.inf
    finite = np.all(np.isfinite(states), axis=1)
    with np.errstate(invalid="ignore"):
        fast, turning = np.hypot(u, v) > top_speed, np.abs(r) > top_r
    bad = ~finite | fast | turning
    if not bad.any():
        return None
    k = int(np.argmax(bad))
    if not finite[k]:
        why = "a non-finite state"
    elif fast[k]:
        why = f"speed {float(np.hypot(u[k], v[k])):.3g} m/s, beyond {top_speed:.3g} m/s"
    else:
        why = f"|r| {abs(float(r[k])):.3g} rad/s, beyond {top_r:.3g} rad/s"
    return float(t[k]), why


def default_rudder_rate(ship: Ship) -> tuple[float, str]:
    """(rudder rate [deg/s], where it comes from): the ship file's steering gear, else
    2.32 deg/s at full scale Froude-scaled (times sqrt(scale)) with a scale factor, else
    2.32 deg/s."""
    given = ship.maneuvering
    if "rudder_rate" in given:
        return float(given["rudder_rate"]), "ship file [maneuvering] rudder_rate"
    if "scale" in given:
        scale = float(given["scale"])
        return FULL_SCALE_RUDDER_RATE * math.sqrt(scale), f"2.32 deg/s at full scale, Froude-scaled (scale {scale:g})"
    return FULL_SCALE_RUDDER_RATE, "2.32 deg/s (ship file gives no scale: taken as full scale)"


MAX_LENGTHS_PER_STEP = 0.1   # ship lengths run per integration step, at most


def default_conditions(model: nn.Module, ship: Ship, *, speed: float | None = None, rps: float | None = None,
                       rudder_rate: float | None = None, dt: float = 0.1, duration: float | None = None,
                       wind_speed: float = 0.0, wind_direction: float = 0.0,
                       method: Method = Method.RK4) -> tuple[Conditions, dict[str, str]]:
    """`Conditions` with every value not given taken from the ship file or the model, and
    where each came from: approach speed [m/s] from ``[maneuvering] approach_speed``;
    revolutions [rps] that hold it in straight running (`straight_running_rps`); rudder
    rate [deg/s] (`default_rudder_rate`); duration [s] `DURATION_L_OVER_U` L/U0 rounded up to
    10 s; calm water."""
    sources = {}
    if speed is None:
        if "approach_speed" not in ship.maneuvering:
            raise ManeuverError(f"{ship.source or ship.name}: no approach speed: give --speed (speed= in Python), or "
                                "approach_speed [m/s] in the ship file's [maneuvering] table")
        speed, sources["speed"] = float(ship.maneuvering["approach_speed"]), "ship file [maneuvering] approach_speed"
    else:
        sources["speed"] = "given"
    check_number("approach speed", speed, "m/s", positive=True)  # before the search for revolutions
    longest = MAX_LENGTHS_PER_STEP * float(ship["L_pp"]) / speed
    if dt > longest:  # a turn of a few steps: its indices are not resolved (and may not exist)
        raise ManeuverError(f"dt {dt:g} s: the ship runs {speed * dt / float(ship['L_pp']):.2g} ship lengths per "
                            f"step at {speed:g} m/s; a maneuver is resolved with at most {MAX_LENGTHS_PER_STEP:g} "
                            f"L per step: give dt <= {longest:.3g} s")
    check_number("wind speed", wind_speed, "m/s", low=0.0)
    check_number("wind direction", wind_direction, "rad")
    if rps is None:
        rps = straight_running_rps(model, speed, wind_speed, wind_direction)
        sources["rps"] = "straight running of the model"
    else:
        sources["rps"] = "given"
    if rudder_rate is None:
        rudder_rate, sources["rudder_rate"] = default_rudder_rate(ship)
    else:
        sources["rudder_rate"] = "given"
    if duration is None:
        L = float(ship["L_pp"])
        duration = 10.0 * math.ceil(DURATION_L_OVER_U * L / speed / 10.0)
        sources["duration"] = f"{DURATION_L_OVER_U:g} L/U0"
    else:
        sources["duration"] = "given"
    sources["wind"] = "calm water" if wind_speed == 0.0 else "given"
    return Conditions(speed, rps, rudder_rate, dt, duration, wind_speed, wind_direction, method), sources


def ahead_only(model: nn.Module) -> bool:
    """True when the model's propeller force is the standard MMG family's, which holds for
    ahead motion only (no astern thrust): a crash stop needs a four-quadrant propeller (or
    a learned force, NN-only)."""
    return getattr(model, "kind", "mmg") != "nn" and ship_of(model).models.get("propeller") != "four_quadrant"


def _check_ahead(model: nn.Module, maneuvers: Sequence[Maneuver]) -> None:
    """One `ManeuverError` line when a crash stop is asked of an ahead-only propeller."""
    if any(m.kind == "crash_stop" for m in maneuvers) and ahead_only(model):
        raise ManeuverError(f"crash stop: the propeller model {ship_of(model).models.get('propeller')!r} of "
                            f"{ship_of(model).name} is for ahead motion only (no astern thrust); a crash stop needs "
                            "a four-quadrant propeller")


def gate_off_share(model: nn.Module, states: torch.Tensor, inputs: torch.Tensor) -> float | None:
    """Share of the rows (states (N, 6), inputs (N, 4)) at which the model's kNN gate
    switches its FNN off; None for a model without a gate."""
    off, total = 0, 0
    with torch.no_grad():
        for lo in range(0, states.shape[0], GATE_CHUNK):
            gate = model(states[lo:lo + GATE_CHUNK], inputs[lo:lo + GATE_CHUNK]).gate_on
            if gate is None:
                return None
            off += int((~gate).sum())
            total += gate.numel()
    return off / total if total else None


def gate_distances(model: nn.Module, states: torch.Tensor, inputs: torch.Tensor) -> np.ndarray | None:
    """d_kNN (N,) of the rows (states (N, 6), inputs (N, 4)): the kNN distance the model's
    gate compares with its threshold (an ensemble's: its members' mean); None without a gate."""
    parts = []
    with torch.no_grad():
        for lo in range(0, states.shape[0], GATE_CHUNK):
            d = model(states[lo:lo + GATE_CHUNK], inputs[lo:lo + GATE_CHUNK]).ood_distance
            if d is None:
                return None
            parts.append(d.double().numpy())
    return np.concatenate(parts) if parts else None


def gate_threshold(model: nn.Module) -> float | None:
    """The threshold delta_kNN of the model's one kNN gate; None without one (an MMG, a
    model without a gate, an ensemble: each member has its own)."""
    gate = getattr(model, "gate", None)
    return float(gate.threshold) if gate is not None and getattr(model, "gate_enabled", True) else None


def _with_distances(model: nn.Module, results: list[ManeuverResult]) -> list[ManeuverResult]:
    """`results` of a gated model with each step's d_kNN (`gate_distances` of its state and
    the inputs held from it) and the gate's threshold filled in."""
    for r in results:
        if r.gate_on is None:
            continue
        d = gate_distances(model, torch.as_tensor(r.states), torch.as_tensor(r.inputs))
        r.knn_distance, r.knn_threshold = d, gate_threshold(model)
    return results


def _results(maneuvers: Sequence[Maneuver], conditions: Conditions, x0: torch.Tensor, record: torch.Tensor,
             label: str, limits: PhysicalRange | None = None) -> list[ManeuverResult]:
    """`ManeuverResult`s from a record (steps, B, `RECORD`) of closed-loop steps from x0 (B, 6);
    the kNN gate's off share is over the steps' start states; where each diverged
    (`first_divergence` against `limits`)."""
    steps = record.shape[0]
    states = torch.cat((x0[None], record[..., :6]))
    rudder = torch.cat((torch.zeros_like(x0[None, :, 0]), record[..., 6]))
    held = torch.cat((record[..., 8:12], record[-1:, :, 8:12]))
    t = np.arange(steps + 1) * conditions.dt
    out = []
    for b, maneuver in enumerate(maneuvers):
        s, r, u = states[:, b].numpy(), rudder[:, b].numpy(), held[:, b].numpy()
        indices = maneuver_indices(maneuver, Track.of(t, s), r)
        on = record[:, b, 12]
        share = None if torch.isnan(on).any() else float((on < 0.5).double().mean())
        out.append(ManeuverResult(maneuver, t, s, r, u, indices, share, label))
        if share is not None:   # the decision at each step's start; the last row starts none
            out[-1].gate_on = np.append(on.double().numpy(), math.nan)
        if (found := first_divergence(t, s, conditions.speed, limits)) is not None:
            out[-1].diverged_at_s, out[-1].divergence = found
    return out


def choose_loop(models: Sequence[nn.Module], maneuvers: Sequence[Maneuver], conditions: Conditions,
                compiled: bool | None = None) -> PathChoice:
    """The loop for simulating `maneuvers` with each of `models`: as asked (`compiled`
    True or False); otherwise (None) by `sysid.fast.payoff.choose_path` from the step count
    and the cache alone (no clock): the compiled loop when every model's loop is in the
    cache (a warm start), or when the eager steps (`conditions.steps` per model) reach
    `MANEUVER_REPAY_STEPS` per loop still to compile; else the eager loop. Up to
    `LOOP_ROWS` maneuvers share one loop and one eager step, so their number does not count."""
    from sysid.fast.payoff import MANEUVER_REPAY_STEPS, choose_path
    from sysid.fast.compiled import enabled
    label = f"maneuver-{conditions.method.name.lower()}"
    asked = compiled is not None or not enabled()
    cold = 0 if asked else sum(not loop_is_cached(m, conditions.method) for m in models)
    return choose_path("loop", conditions.steps * len(models), cold, len(models), MANEUVER_REPAY_STEPS,
                       compiled, label)


def _start(maneuvers: Sequence[Maneuver], conditions: Conditions):
    """(x0 (B, 6), controller state (B, 2), parameters (B, P)) at the execute."""
    dtype = torch.float64
    x0 = torch.zeros(len(maneuvers), 6, dtype=dtype)
    x0[:, 1] = conditions.speed
    return x0, initial_orders(maneuvers, dtype), order_parameters(maneuvers, conditions, dtype)


def simulate_maneuvers(model: nn.Module, maneuvers: Sequence[Maneuver], conditions: Conditions, *,
                       compiled: bool | None = False, label: str = "model",
                       limits: PhysicalRange | None = None) -> list[ManeuverResult]:
    """Each maneuver from straight running at the approach speed (x = y = psi = 0, u = U0,
    v_m = r = 0, rudder amidships) for `conditions.duration`, closed loop, with its indices
    and the kNN gate's off share.

    Eager: all maneuvers at once, one batched step per time step. ``compiled=True``: up to
    `LOOP_ROWS` maneuvers side by side through the model's compiled loop
    (`sysid.maneuvers.closed_loop`; compiled once per model and rule, cached on disk, one
    notice line on stderr), or eager where compilation is off or unavailable; the numbers
    agree to round-off. ``compiled=None``: as `choose_loop` decides. A maneuver that
    diverged (`first_divergence` against the training range `limits`, None: unknown) says
    when in its ``diverged_at_s``.
    """
    if not maneuvers:
        return []
    _check_ahead(model, maneuvers)
    if compiled is None:
        compiled = choose_loop([model], maneuvers, conditions).compiled
    x0, orders, parameters = _start(maneuvers, conditions)
    loop = compiled_loop(model, conditions.method, x0.dtype) if compiled else None
    if loop is None:
        record = run_eager(model, x0, orders, parameters, conditions.steps, conditions.dt, conditions.method)
    else:
        record = run_compiled(loop, x0, orders, parameters, conditions.steps, conditions.dt)
    return _with_distances(model, _results(maneuvers, conditions, x0, record, label, limits))


def simulate_rows(model: nn.Module, maneuvers: Sequence[Maneuver], conditions: Sequence[Conditions], *,
                  label: str = "model", limits: PhysicalRange | None = None,
                  distances: bool = True) -> list[ManeuverResult]:
    """`simulate_maneuvers` (eager) of each maneuver under its own `Conditions` (approach
    speed, revolutions, rudder rate, wind and duration per row; one dt and integration rule
    for all), as one batched rollout to the longest duration: maneuver b is the first
    ``conditions[b].steps`` steps of its row. Rows do not interact, so each result equals
    the maneuver simulated alone to round-off. `distances`: each step's d_kNN filled in
    (`gate_distances`: a whole-bank scan per step), else left None (the gate's decisions
    and off share are there either way)."""
    if len(maneuvers) != len(conditions):
        raise ValueError(f"{len(maneuvers)} maneuvers with {len(conditions)} conditions")
    if not maneuvers:
        return []
    first = conditions[0]
    if any(c.dt != first.dt or c.method != first.method for c in conditions):
        raise ManeuverError("maneuvers simulated side by side share one time step and integration rule")
    _check_ahead(model, maneuvers)
    starts = [_start([m], c) for m, c in zip(maneuvers, conditions)]
    x0, orders, parameters = (torch.cat(parts) for parts in zip(*starts))
    record = run_eager(model, x0, orders, parameters, max(c.steps for c in conditions), first.dt, first.method)
    results = [_results([m], c, x0[b:b + 1], record[:c.steps, b:b + 1], label, limits)[0]
               for b, (m, c) in enumerate(zip(maneuvers, conditions))]
    return _with_distances(model, results) if distances else results


def run_maneuvers(subject: ManeuverModel, maneuvers: Sequence[Maneuver], conditions: Conditions, *,
                  compiled: bool | None = False) -> list[ManeuverResult]:
    """`simulate_maneuvers` of the subject's model, and of each member (an ensemble's
    members, a folder's seeds) into each result's ``members``: the spread of the indices.
    ``compiled=None``: one `choose_loop` for the model and its members."""
    if compiled is None:
        compiled = choose_loop([subject.model, *(m for _, m in subject.members)], maneuvers, conditions).compiled
    results = simulate_maneuvers(subject.model, maneuvers, conditions, compiled=compiled, label=subject.label,
                                 limits=subject.training_range)
    for label, member in subject.members:
        for result, own in zip(results, simulate_maneuvers(member, maneuvers, conditions, compiled=compiled,
                                                           label=label, limits=subject.training_range)):
            result.members.append(own)
    return results


def run_baseline(baseline: ManeuverModel, maneuvers: Sequence[Maneuver], conditions: Conditions, *,
                 compiled: bool | None = False) -> tuple[list[ManeuverResult], list[str]]:
    """The `maneuvers` of a learned model's physics baseline (`sysid.maneuvers.any_model.physics_baseline`)
    under the learned model's own `conditions` (its approach revolutions included): (results
    labelled with the baseline's label, names of the maneuvers it cannot run: a crash stop
    with a propeller model for ahead motion only)."""
    runnable = [m for m in maneuvers if not (m.kind == "crash_stop" and ahead_only(baseline.model))]
    left_out = [m.name for m in maneuvers if m not in runnable]
    return (simulate_maneuvers(baseline.model, runnable, conditions, compiled=compiled, label=baseline.label,
                               limits=baseline.training_range), left_out)
