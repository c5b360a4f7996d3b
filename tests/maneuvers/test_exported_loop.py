"""The maneuver loop as compiled code sees it: `torch.export` of the MMG's closed-loop
rollout (the program AOTInductor compiles) holds no lifted tensor constant (a tensor made
from Python numbers inside the traced forward becomes one, and the compiled loop then
fails), and the exported program, run for a short turning circle, gives the eager loop's
record. Export only, no C++ compile: the full compile is the slow test of
test_simulation.py."""
import pytest
import torch

from sysid import MMG, load_ship
from sysid.config.choices import Method
from sysid.fast.compiled import enabled, export_program
from sysid.fast.prepared import prepared
from sysid.maneuvers import Conditions, TurningCircle
from sysid.maneuvers.closed_loop import COLUMNS, ClosedLoopRollout, ClosedLoopStep, run_eager, source_digest
from sysid.maneuvers.controllers import initial_orders, order_parameters

STEPS = 40  # steps of the exported loop, dt 0.5 s: 20 s of a 35 deg turn


def test_exported_maneuver_loop_has_no_tensor_constants_and_equals_eager():
    if not enabled():
        pytest.skip("SYSID_COMPILE=0: no compiled loop")
    model = MMG(load_ship("esso_osaka"))
    dtype, dt = torch.float64, 0.5
    module = ClosedLoopRollout(ClosedLoopStep(prepared(model, 1), Method.RK4), STEPS, source_digest())
    examples = (torch.zeros(1, 6, dtype=dtype), torch.zeros(1, 2, dtype=dtype),
                torch.zeros(1, len(COLUMNS), dtype=dtype), torch.zeros((), dtype=dtype),
                torch.full((), dt, dtype=dtype), torch.tensor(STEPS, dtype=torch.int64))
    program = export_program(module, examples)
    # tensor constants, lifted or inside the loop body's subgraph (torch.tensor of numbers)
    assert not program.constants, f"lifted tensor constants: {sorted(program.constants)}"
    constant_nodes = [node.target for graph_module in program.graph_module.modules() if hasattr(graph_module, "graph")
                      for node in graph_module.graph.nodes
                      if (node.op == "get_attr" and "_tensor_constant" in str(node.target))
                      or "lift_fresh" in str(node.target)]
    assert not constant_nodes, f"{len(constant_nodes)} tensor constants in the traced loop: {constant_nodes[:4]}"

    maneuvers = [TurningCircle(35.0)]
    conditions = Conditions(0.35, 8.85, 24.1, dt, STEPS * dt)  # U0 [m/s], n [rps], rudder rate [deg/s]
    x0 = torch.zeros(1, 6, dtype=dtype)
    x0[:, 1] = conditions.speed
    orders, parameters = initial_orders(maneuvers, dtype), order_parameters(maneuvers, conditions, dtype)
    eager = run_eager(model, x0, orders, parameters, STEPS, dt, Method.RK4)
    with torch.no_grad():
        record, last = program.module()(x0, orders, parameters, torch.zeros((), dtype=dtype),
                                        torch.tensor(dt, dtype=dtype), torch.tensor(STEPS))
    assert float(eager[-1, 0, 5]) > 0.01  # turning: r [rad/s]
    torch.testing.assert_close(record, eager, rtol=0, atol=1e-10, equal_nan=True)  # gate column: NaN without a gate
    torch.testing.assert_close(last, eager[-1, :, :6], rtol=0, atol=1e-10)
