"""Typed integrator, the fused step loop, the compiled prediction and the export.

Truth: torchdiffeq's Euler `odeint` and the eager model (the compiled code must give the
same states), the lab's RK4 trajectories (test_mmg_oracle.py), and a fresh Python
process that has only torch (the exported file must predict the same without sysid).
"""
import json
import os
import re
import subprocess
import zipfile
import sys
from pathlib import Path

import pandas as pd
import pytest
import torch

from sysid import MMG, integrate, load_ship
from sysid.fast import codegen_fixes
from sysid.fast.compiled import compiled_rollout_function, compiled_step, predict, rollout_package
from sysid.hybrid.correction import correction_inputs
from sysid.config.experiment import parse_experiment
from sysid.store.files import write_text
from sysid.dynamics.integrators import Integrator, Method
from sysid.hybrid.knn_gate import KNNGate
from sysid.hybrid.force_models import build_model
from sysid.store.manifest import write_manifest
from sysid.runs.layout import load_model, save_model
from sysid.dynamics.integrators import run_steps
from sysid.fast.stepper import Step

pytestmark = pytest.mark.slow  # every test here compiles (minutes on a cold cache)

STATE = ["x", "u", "y", "v", "psi", "r"]
INPUTS = ["n_prop", "delta_rad", "wind_velo_true", "wind_dir_true"]


@pytest.fixture(scope="module")
def zigzag(oracle_dir):
    """Recorded start state (6,) and 101 s of recorded inputs (101, 4) of the zigzag oracle."""
    traj = pd.read_csv(oracle_dir / "traj_zigzag_dt1p0.csv")
    return torch.tensor(traj[STATE].to_numpy()), torch.tensor(traj[INPUTS].to_numpy())


@pytest.fixture(scope="module")
def hybrid_run(zigzag, tmp_path_factory):
    """A run directory of a hybrid model (seeded network, kNN gate in input space) whose
    gate switches the network off on part of the zigzag, and the model loaded from it."""
    states, inputs = zigzag
    exp = parse_experiment({"experiment": {"model": "hybrid", "dataset": "D2", "name": "export_test"},
                            "gate": {"k": 5, "space": "inputs"}})
    torch.manual_seed(0)
    model = build_model(exp)
    s = correction_inputs(states, inputs, model.mmg(states, inputs).relative_wind)
    model.correction_net.set_standardization(s.mean(0), s.std(0), torch.zeros(3), torch.tensor([2.0, 2.0, 1.0]))
    with torch.no_grad():  # the bank: the first half of the manoeuvre, so the second is partly out
        z = model.gate_coordinates(s[:50])
    model.gate = KNNGate(5, 0.9, z.shape[-1], torch.float64).fit(z)
    model.gate_enabled = True
    run_dir = tmp_path_factory.mktemp("run")
    write_text(exp.to_toml(), run_dir / "config.toml")
    save_model(model, run_dir)
    write_text('{"name": "export_test", "model": "hybrid"}', run_dir / "summary.json")
    write_text("scenario,file,horizon_s,n_windows,rmse_u,rmse_v,rmse_r\n", run_dir / "metrics.csv")
    write_manifest(run_dir, "run")  # sealed, as a run written by sysid is
    return run_dir, load_model(run_dir)[1]


def test_integrator_names_are_typed():
    assert Method.parse("rk4") is Method.RK4 and Method.parse(Method.EULER) is Method.EULER
    assert Integrator.of("rk4_3/8") == Integrator(Method.RK4_38, compiled=False)
    assert Integrator("euler").method is Method.EULER
    with pytest.raises(ValueError, match="euler, rk4, rk4_3/8"):
        Method.parse("dopri5")
    x0, inputs = torch.zeros(6, dtype=torch.float64), torch.zeros(3, 4, dtype=torch.float64)
    with pytest.raises(ValueError, match="differentiable"):  # integrate keeps its gradient
        integrate(MMG(load_ship("esso_osaka")), x0, inputs, 1.0, Integrator("euler", compiled=True))


def test_no_torchdiffeq_internals_in_the_package():
    import sysid
    root = Path(sysid.__file__).parent
    offenders = [p.name for p in root.rglob("*.py") if "torchdiffeq._impl" in p.read_text()]
    assert offenders == []


def test_classical_and_3_8_rules_are_fourth_order_on_an_analytic_case():
    """dx/dt = -x: one step of h gives exp(-h) to O(h^5) for both fourth-order rules."""
    from sysid.dynamics.integrators import STEP_RULES
    x = torch.ones(1, dtype=torch.float64)
    for method in (Method.RK4, Method.RK4_38):
        errors = [abs(float(STEP_RULES[method](lambda s: -s, x, h)) - torch.exp(torch.tensor(-h)).item())
                  for h in (0.2, 0.1)]
        assert 24 < errors[0] / errors[1] < 40, (method, errors)  # ratio 2^5 = 32
    # Euler: exactly 1 - h
    assert float(STEP_RULES[Method.EULER](lambda s: -s, x, 0.25)) == 0.75


def test_step_loop_is_torchdiffeq_euler_bit_for_bit(hybrid_run, zigzag):
    states, inputs = zigzag
    model = hybrid_run[1]
    with torch.no_grad():
        reference = integrate(model, states[0], inputs, 1.0, "euler")  # torchdiffeq odeint
        ours = run_steps(Step(model, Method.EULER, 1.0), states[:1], inputs[:, None])[:, 0]
        on = model(reference, inputs).gate_on
    assert on.any() and not on.all()  # both branches of the gate are exercised
    assert torch.equal(ours, reference)


def test_record_gives_one_force_breakdown_per_euler_step(zigzag):
    states, inputs = zigzag
    model = MMG(load_ship("esso_osaka"))
    record = []
    pred = integrate(model, states[0], inputs[:6], 1.0, "euler", record=record)
    assert len(record) == 5
    torch.testing.assert_close(record[3].total, model(pred[3], inputs[3]).total, rtol=0, atol=0)


@pytest.mark.parametrize("method", [Method.EULER, Method.RK4])
def test_compiled_prediction_equals_eager(hybrid_run, zigzag, method):
    states, inputs = zigzag
    model = hybrid_run[1]
    if compiled_rollout_function(model, method, 1.0, 1) is None:
        pytest.skip("compilation unavailable here (the eager fallback was used)")
    with torch.no_grad():
        eager = integrate(model, states[0], inputs, 1.0, method)
        on = model(eager, inputs).gate_on
    assert on.any() and not on.all()  # the gate's tiers decide both ways
    compiled = predict(model, states[0], inputs, 1.0, Integrator(method, compiled=True))
    assert compiled.shape == (101, 6)
    torch.testing.assert_close(compiled, eager, rtol=1e-12, atol=1e-12)
    # longer than one compiled call (ROLLOUT_STEPS): chained calls, the same states
    long_inputs = torch.cat((inputs, inputs[1:], inputs[1:]))
    with torch.no_grad():
        eager = integrate(model, states[0], long_inputs, 1.0, method)
    compiled = predict(model, states[0], long_inputs, 1.0, Integrator(method, compiled=True))
    torch.testing.assert_close(compiled, eager, rtol=1e-12, atol=1e-12)


def _loop_source(package: Path) -> str:
    """The C++ of a compiled rollout's while loop (from its wrapper source in the package)."""
    with zipfile.ZipFile(package) as archive:
        names = [n for n in archive.namelist() if n.endswith(".wrapper.cpp")]
        if not names:
            pytest.skip("this torch does not keep the wrapper source in its packages")
        source = archive.read(names[0]).decode()
    return source[source.index("while (1) {"):]


def test_compiled_loop_allocates_only_what_its_kernels_use(hybrid_run, zigzag):
    """The two wrapper fixes of `sysid.fast.codegen_fixes`, read off the generated C++ of the
    hybrid's RK4 loop (gate with its conds): every tensor the loop allocates is used by a
    kernel or handed on, and the loop's condition takes handles of only k and steps. The
    numbers are those of eager (test_compiled_prediction_equals_eager compiles this loop)."""
    if not codegen_fixes.available():
        pytest.skip(f"the wrapper fixes are not applied to torch {torch.__version__}")
    model = hybrid_run[1]
    if compiled_rollout_function(model, Method.RK4, 1.0, 1) is None:
        pytest.skip("compilation unavailable here (the eager fallback was used)")
    loop = _loop_source(rollout_package(model, Method.RK4, 1.0))
    condition = loop[loop.index("// subgraph: while_loop_cond_graph"):loop.index("// subgraph: while_loop_body_graph")]
    assert condition.count("aoti_torch_assign_tensors_out(") == 2
    allocated = re.findall(r"aoti_torch_empty_strided\([^;]*&(\w+)_handle\)\);", loop)
    assert len(allocated) > 10
    moves = dict(re.findall(r"auto (\w+) = std::move\((\w+)\);  // reuse", loop))
    renamed = {old: new for new, old in moves.items()}
    bookkeeping = re.compile(r"^\s*(AtenTensorHandle \w+;|RAIIAtenTensorHandle \w+\(\w+\);|\w+\.reset\(\);"
                             r"|auto \w+ = std::move\(\w+\);  // reuse|AOTI_TORCH_ERROR_CODE_CHECK\(aoti_torch_empty_strided.*)$")
    work = "\n".join(line for line in loop.splitlines() if not bookkeeping.match(line))
    unused = []
    for name in allocated:
        names = [name]
        while names[-1] in renamed:  # a buffer reused under another name
            names.append(renamed[names[-1]])
        if not any(re.search(rf"\b{n}\b", work) for n in names):
            unused.append(name)
    assert not unused, f"{len(unused)} of {len(allocated)} tensors allocated per pass and never used: {unused[:5]}"


def _predict_in_fresh_python(path: Path, loader: str, x0: torch.Tensor, inputs: torch.Tensor, tmp: Path):
    """Load an exported step in a new interpreter with torch only; (states, sysid imported?)."""
    torch.save({"x0": x0.contiguous(), "inputs": inputs.contiguous()}, tmp / "case.pt")
    script = f"""
import sys, torch
case = torch.load({str(tmp / 'case.pt')!r})
step = {loader}
x, out = case["x0"], [case["x0"]]
with torch.no_grad():
    for u in case["inputs"][:-1]:
        x = step(x, u)
        out.append(x)
torch.save(torch.stack(out), {str(tmp / 'out.pt')!r})
print(any(m == "sysid" or m.startswith("sysid.") for m in sys.modules))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return torch.load(tmp / "out.pt"), done.stdout.strip().splitlines()[-1] == "True"


@pytest.mark.parametrize("portable", [False, True])
def test_export_predicts_the_same_without_sysid(hybrid_run, zigzag, tmp_path, portable):
    from sysid.cli import run
    from sysid.fast.export import load_step
    run_dir, model = hybrid_run
    states, inputs = zigzag
    if not portable and compiled_step(model, Method.EULER, 1.0, 1) is None:
        pytest.skip("compilation unavailable here")
    out = tmp_path / "model.pt2"
    run(["export", str(run_dir), "-o", str(out)] + (["--portable"] if portable else []))
    exported = load_step(out)
    assert exported.metadata["method"] == "euler" and exported.dt == 1.0
    assert exported.metadata["kind"] == "hybrid"
    with torch.no_grad():
        eager = integrate(model, states[0], inputs, 1.0, "euler")
    torch.testing.assert_close(exported.predict(states[:1], inputs[:, None])[:, 0], eager, rtol=1e-12, atol=1e-12)
    loader = (f"torch.export.load({str(out)!r}).module()" if portable
              else f"torch._inductor.aoti_load_package({str(out)!r})")
    fresh, imported_sysid = _predict_in_fresh_python(out, loader, states[:1], inputs[:, None], tmp_path)
    assert not imported_sysid
    torch.testing.assert_close(fresh[:, 0], eager, rtol=1e-12, atol=1e-12)
    if portable:
        extra = {"sysid.json": ""}
        torch.export.load(str(out), extra_files=extra)
        assert json.loads(extra["sysid.json"])["format"] == "torch.export"
    assert not exported.gated
    with pytest.raises(ValueError, match="--with-gate"):
        exported.outputs(states[:1].contiguous(), inputs[:1].contiguous())
    x, u = states[:1].contiguous(), inputs[:1].contiguous()
    for wrong in ((x.float(), u), (x.expand(2, 6).contiguous(), u.expand(2, 4).contiguous())):
        with pytest.raises(ValueError, match=r"exported step: .* the file takes \(1, [46]\) float64"):
            exported(*wrong)
    column_major = inputs[:2].T.contiguous().T[:1]   # a row of a column-major array: read as its values
    torch.testing.assert_close(exported(x, column_major), exported(x, u.clone()), rtol=0, atol=0)
    if not portable:   # the package itself refuses them with its own checks on
        for name, wrong in {"dtype": "x.float(), u.float()", "rows": "x.expand(2, 6).contiguous(), u.expand(2, 4).contiguous()",
                            "stride": "x, torch.zeros(4, 2, dtype=torch.float64).T[:1]"}.items():   # a row of a column-major array
            script = (f"import torch; step = {loader}; x = torch.zeros(1, 6, dtype=torch.float64); "
                      f"u = torch.zeros(1, 4, dtype=torch.float64); x[0, 1] = 1.0\n"
                      f"try:\n    step({wrong}); print('accepted')\nexcept RuntimeError as e:\n    print('refused', e)")
            done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path,
                                  timeout=300, env={**os.environ, "AOTI_RUNTIME_CHECK_INPUTS": "1"})
            assert done.stdout.startswith("refused") and f"unmatched {'dim' if name == 'rows' else name}" in done.stdout, (
                name, done.stdout[-500:], done.stderr[-500:])


@pytest.mark.parametrize("portable", [False, True])
def test_an_export_with_the_gate_returns_its_decision_without_sysid(hybrid_run, zigzag, tmp_path, portable):
    """``--with-gate``: step(x, u) -> (x_next, gate_on) in a python with torch alone; the
    states are the eager Euler rollout's, the decisions the model's own gate's at each
    step's start (on part of the zigzag, off on the rest)."""
    from sysid.cli import run
    from sysid.fast.export import load_step
    run_dir, model = hybrid_run
    states, inputs = zigzag
    if not portable and compiled_step(model, Method.EULER, 1.0, 1) is None:
        pytest.skip("compilation unavailable here")
    out = tmp_path / "gated.pt2"
    run(["export", str(run_dir), "-o", str(out), "--with-gate"] + (["--portable"] if portable else []))
    with torch.no_grad():
        eager = integrate(model, states[0], inputs, 1.0, "euler")
        decided = model.gate_decision(eager[:-1], inputs[:-1]).to(torch.float64)
    assert 0 < int(decided.sum()) < len(decided)   # the gate decides both ways along the zigzag
    torch.save({"x0": states[:1].contiguous(), "inputs": inputs[:, None].contiguous()}, tmp_path / "case.pt")
    loader = (f"torch.export.load({str(out)!r}).module()" if portable
              else f"torch._inductor.aoti_load_package({str(out)!r})")
    script = f"""
import sys, torch
case = torch.load({str(tmp_path / 'case.pt')!r})
step = {loader}
x, out, gates = case["x0"], [case["x0"]], []
with torch.no_grad():
    for u in case["inputs"][:-1]:
        x, gate = step(x, u)
        out.append(x)
        gates.append(gate)
torch.save({{"states": torch.stack(out), "gates": torch.stack(gates)}}, {str(tmp_path / 'out.pt')!r})
print(any(m == "sysid" or m.startswith("sysid.") for m in sys.modules))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "False"   # sysid not imported
    fresh = torch.load(tmp_path / "out.pt")
    torch.testing.assert_close(fresh["states"][:, 0], eager, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(fresh["gates"][:, 0], decided, rtol=0, atol=0)
    exported = load_step(out)
    assert exported.gated and "gate_on" in exported.metadata["outputs"]
    x, gate = exported.outputs(states[:1].contiguous(), inputs[:1].contiguous())
    assert float(gate[0]) == float(decided[0]) and torch.equal(x, exported(states[:1].contiguous(), inputs[:1].contiguous()))
    torch.testing.assert_close(exported.predict(states[:1], inputs[:, None])[:, 0], eager, rtol=1e-12, atol=1e-12)


def test_trajectory_stacks_the_forces_of_every_euler_step(hybrid_run, zigzag):
    from sysid.dynamics.equations import integrate_with_forces
    states, inputs = zigzag
    model = hybrid_run[1]
    traj = integrate_with_forces(model, states[0], inputs[:8], 1.0)
    assert traj.forces.correction.shape == (7, 3) and traj.forces.gate_on.shape == (7,)
    with torch.no_grad():  # step by step: the same shapes, so the same rounding
        again = torch.stack([model(traj.states[k], inputs[k]).total for k in range(7)])
    torch.testing.assert_close(traj.forces.total.detach(), again, rtol=0, atol=0)
    torch.testing.assert_close(traj.states, integrate(model, states[0], inputs[:8], 1.0), rtol=0, atol=0)


def test_compiled_batch_equals_eager(zigzag):
    """Batches are compiled channels first (vectorized): the same states as eager."""
    states, inputs = zigzag
    model = MMG(load_ship("esso_osaka"))
    if compiled_step(model, Method.EULER, 1.0, 4) is None:
        pytest.skip("compilation unavailable here")
    x0 = states[:4] * torch.tensor([1.0, 1.1, 1.0, 0.9, 1.0, 1.2], dtype=torch.float64)  # four ships
    u = inputs[:31, None].expand(31, 4, 4).contiguous()
    with torch.no_grad():
        eager = integrate(model, x0, u, 1.0, "euler")
    compiled = predict(model, x0, u, 1.0, Integrator("euler", compiled=True))
    torch.testing.assert_close(compiled, eager, rtol=1e-12, atol=1e-12)


def test_large_batches_run_in_padded_channels_first_chunks():
    """`_by_rows` feeds a function compiled for `rows` channels-first rows with any batch."""
    from sysid.fast.compiled import _by_rows
    calls = []

    def fn(xT, uT):  # stands for a compiled (6, rows), (4, rows) -> (6, rows) function
        assert xT.shape == (6, 4) and uT.shape == (4, 4)
        calls.append(1)
        return xT * 2.0 + uT[:1]
    x = torch.arange(60, dtype=torch.float64).reshape(10, 6)
    u = torch.arange(40, dtype=torch.float64).reshape(10, 4)
    out = _by_rows(fn, rows=4, batch=10)(x, u)
    torch.testing.assert_close(out, x * 2.0 + u[:, :1], rtol=0, atol=0)
    assert len(calls) == 3  # 4 + 4 + 2 (padded to 4)


def test_lean_right_hand_side_is_the_breakdown_total_bit_for_bit(hybrid_run, zigzag):
    """Compiled steps sum X, Y, N as separate channels (no force breakdown): the same
    numbers as the breakdown's total, for MMG, hybrid and NN-only; channels first they come
    from the channel-wise equations of motion rather than the eager one-product form, equal
    to round-off."""
    from sysid.dynamics.equations import derivative, lean_derivative
    from sysid.hybrid.force_models import CorrectedModel
    states, inputs = zigzag
    hybrid = hybrid_run[1]
    nn_only = CorrectedModel(hybrid.mmg, hybrid.correction_net, hybrid.gate, physics=False, gate_space="inputs")
    with torch.no_grad():
        for model in (MMG(load_ship("esso_osaka")), hybrid, nn_only):
            assert torch.equal(lean_derivative(model, states, inputs), derivative(model, states, inputs))
            channels_first = lean_derivative(model, states.T.contiguous().T, inputs, 0)
            torch.testing.assert_close(channels_first, derivative(model, states, inputs).T, rtol=1e-13, atol=1e-16)


def test_packed_coefficients_give_the_same_forces(hybrid_run, zigzag):
    from sysid.mmg.coefficients import PackedCoefficients
    from sysid.fast.prepared import packed
    states, inputs = zigzag
    hybrid = hybrid_run[1]
    fast = packed(hybrid)
    assert isinstance(fast.mmg.coefficients, PackedCoefficients)
    assert not isinstance(hybrid.mmg.coefficients, PackedCoefficients)  # the model is untouched
    c, p = hybrid.mmg.coefficients, fast.mmg.coefficients
    assert all(torch.equal(getattr(c, n), getattr(p, n)) for n in c.names)
    with torch.no_grad():
        torch.testing.assert_close(fast(states, inputs).total, hybrid(states, inputs).total, rtol=0, atol=0)


def test_compiled_float32_rows_equal_eager(zigzag):
    """The batched float32 right-hand side (channels first, packed coefficients) agrees
    with eager float32 to float32 round-off."""
    from sysid.fast.compiled import compiled_derivative
    from sysid.dynamics.equations import derivative
    states, inputs = zigzag
    model = MMG(load_ship("esso_osaka"), dtype=torch.float32)
    x, u = states[:8].float(), inputs[:8].float()
    rhs = compiled_derivative(model, 8, torch.float32)
    if rhs is None:
        pytest.skip("compilation unavailable here")
    with torch.no_grad():
        eager = derivative(model, x, u)
    torch.testing.assert_close(rhs(x, u), eager, rtol=1e-5, atol=1e-6)


def test_compiled_functions_are_rebuilt_when_the_model_changes(hybrid_run):
    """The in-process memo of compiled functions keys on every parameter's and buffer's
    storage, version and shape, and on the scalar settings: a change to any of them
    (training in place, a refitted gate, the gate switched off) builds anew."""
    from sysid.fast.compiled import _memoized
    model = hybrid_run[1]
    builds = []

    def build():
        builds.append(1)
        return len(builds)

    assert _memoized(model, ("test",), build) == 1
    assert _memoized(model, ("test",), build) == 1  # unchanged: the same function
    with torch.no_grad():
        model.correction_net.biases[0].add_(0.0)  # an in-place update, same numbers
    assert _memoized(model, ("test",), build) == 2
    model.gate.threshold.mul_(1.0)  # a buffer
    assert _memoized(model, ("test",), build) == 3
    model.gate_enabled = False
    try:
        assert _memoized(model, ("test",), build) == 4
    finally:
        model.gate_enabled = True
    assert _memoized(model, ("test",), build) == 3  # back to the settings of build 3


def test_the_compile_lines_are_stage_lines_of_the_commands_log(monkeypatch, tmp_path, capsys):
    """"sysid: compiling ..." and "sysid: compiled ... in N s" (a compiled step) and the
    closed loop's "compiling" line reach a command's stdout through the `sysid` log, with
    their text unchanged (time-stamped when stdout is not a terminal), none on stderr; ``-q``
    hides them like every stage line. The compiler itself is replaced: only the lines are checked."""
    from sysid import logs
    from sysid.fast import compiled
    from sysid.maneuvers import closed_loop

    path = tmp_path / "cache" / "step-0.pt2"
    path.parent.mkdir()
    monkeypatch.setattr(compiled, "package_path", lambda *args: path)
    monkeypatch.setattr(compiled, "export_program", lambda module, inputs: None)
    monkeypatch.setattr(compiled, "compile_package", lambda program, p, metadata, options: p.write_bytes(b"x"))
    monkeypatch.setattr(compiled, "record_seconds", lambda *args: None)
    logs.configure(0)                                                   # what a command sets up
    assert compiled.cached_package(torch.nn.Identity(), (torch.zeros(3, 6),), "step") == path
    closed_loop._notice("sysid: compiling closed loop ...")
    closed_loop._notice("sysid: compiled closed loop in 1 s")           # not said: the compiling line was
    out, err = capsys.readouterr()
    stamp = re.compile(r"^\d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2} ")
    assert all(stamp.match(line) for line in out.splitlines()) and err == ""
    said = [stamp.sub("", line) for line in out.splitlines()]
    assert said[0] == f"sysid: compiling step for (3, 6) torch.float32 (once; cached in {path.parent}) ..."
    assert re.fullmatch(r"sysid: compiled step in \d+ s", said[1])
    assert said[2:] == ["sysid: compiling closed loop ..."]
    logs.configure(-1)
    path.unlink()
    compiled.cached_package(torch.nn.Identity(), (torch.zeros(3, 6),), "step")
    closed_loop._notice("sysid: compiling closed loop ...")
    assert capsys.readouterr() == ("", "")
    logs.configure(0)
