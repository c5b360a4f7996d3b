"""The native MMG kernel (`sysid.mmg.native`) against the torch path it replaces
(`sysid.mmg.tangents` through `sysid.mmg.vjp`) and against autograd through the MMG: values
and Jacobians in float64 on every branch, at the switches and on the D2 training windows,
with and without wind; a float32 training rollout's loss and gradients; the compiled
library's cache (reused, never a corrupt file) and the fallbacks to torch."""
from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from sysid.dynamics.equations import integrate_training
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember
from sysid.mmg import native
from sysid.mmg.model import MMG
from sysid.mmg.ship import load_ship
from sysid.mmg.vjp import rate_with_jacobian
from mmg_rows import ESSO, branch_rows, reference, switch_rows

ROOT = Path(__file__).resolve().parents[2]
C = ESSO.coefficients.values_view(torch.float64)


@pytest.fixture(scope="module")
def kernel():
    """The library of this process (built on first use); a failure to build is a failure here."""
    if native.library() is None:
        pytest.fail("the native kernel did not build or load (see the sysid.mmg.native log line)")
    return native.library()


@pytest.fixture(scope="module")
def d2_rows(dataset_dir):
    """(state, inputs) (N, 6), (N, 4) float64: every row of every third of the D2 experiment's
    training windows (11 rows each)."""
    from sysid.config.experiment import load_experiment
    from sysid.identify.trainer import split_windows
    from sysid.runs.lifecycle import training_runs
    exp = load_experiment(ROOT / "configs" / "experiments" / "hybrid_D2.toml")
    t = exp.training
    train = split_windows(training_runs(exp, None), t.steps, t.stride_s, t.val_fraction, True, torch.float64,
                          t.block_s, exp.experiment.seed)[0]
    return train.states[:, ::3].reshape(-1, 6), train.inputs[:, ::3].reshape(-1, 4)


def _torch_path(state, inputs, c=C, wind=True):
    with native.torch_path(), torch.no_grad():
        return rate_with_jacobian(state, inputs, c, wind)


def _relative(new: torch.Tensor, old: torch.Tensor, dims) -> float:
    """The largest difference relative to each output's largest magnitude over the rows."""
    scale = old.abs().amax(dims, keepdim=True) + 1e-300
    return float(((new - old).abs() / scale).max())


@pytest.mark.parametrize("wind", [True, False])
@pytest.mark.parametrize("rows", [branch_rows, switch_rows])
def test_values_and_jacobian_equal_the_torch_path_on_every_branch_and_switch(kernel, rows, wind):
    state, inputs = rows()
    out, jacobian = native.rate_with_jacobian(state, inputs, C, wind)
    ref_out, ref_jacobian = _torch_path(state, inputs, wind=wind)
    assert out.dtype == jacobian.dtype == torch.float64
    assert _relative(out, ref_out, 0) < 1e-12
    assert _relative(jacobian, ref_jacobian, (0, 1)) < 1e-12
    assert torch.equal(jacobian[:, [0, 2]], torch.zeros_like(jacobian[:, [0, 2]]))  # nothing depends on x, y
    torch.testing.assert_close(native.rate(state, inputs, C, wind), out, rtol=0, atol=0)
    if not wind:  # the wind force is left out (the relative wind, an FNN input, is not)
        with_wind = native.rate(state, inputs, C, True)
        assert not torch.equal(with_wind[:, 6:9], out[:, 6:9]) and torch.equal(with_wind[:, 9:], out[:, 9:])


@pytest.mark.parametrize("wind", [True, False])
def test_values_and_jacobian_equal_the_torch_path_on_the_d2_windows(kernel, d2_rows, wind):
    state, inputs = d2_rows
    out, jacobian = native.rate_with_jacobian(state, inputs, C, wind)
    ref_out, ref_jacobian = _torch_path(state, inputs, wind=wind)
    assert len(state) > 15000
    assert _relative(out, ref_out, 0) < 1e-12
    assert _relative(jacobian, ref_jacobian, (0, 1)) < 1e-12


def test_the_jacobian_equals_autograds_of_the_mmg_away_from_switches(kernel):
    """d out / d state against `torch.autograd.functional.jacobian` of the MMG's own forward,
    the FNN inputs and the equations of motion (no hand-written derivative on either side)."""
    state, inputs = branch_rows()
    _, jacobian = native.rate_with_jacobian(state, inputs, C)
    # rows are independent: the Jacobian of the sum over rows holds each row's block
    truth = torch.autograd.functional.jacobian(lambda x: reference(x, inputs).sum(0), state)  # (18, N, 6)
    truth = truth.permute(1, 2, 0)
    assert _relative(jacobian, truth, (0, 1)) < 1e-10


def test_the_no_grad_forward_of_an_mmg_equals_its_own_forces_and_rate(kernel):
    """`forward(mmg, ...)`: F_MMG as the MMG computes it, dx/dt as the equations of motion
    do, the FNN inputs as `correction_inputs` (autograd's reference path); None where it does
    not apply."""
    for mmg in (ESSO, MMG(load_ship("esso_osaka"), dtype=torch.float32)):
        dtype = mmg.coefficients.X_vr.dtype
        for rows in (branch_rows, switch_rows):
            state, inputs = (t.to(dtype) for t in rows())
            with torch.no_grad():
                out, ref = native.forward(mmg, state, inputs), reference(state, inputs, mmg)
            assert out.dtype == dtype
            assert _relative(out, ref, 0) < (1e-12 if dtype == torch.float64 else 2e-6)
    state, inputs = branch_rows()
    assert native.forward(MMG(load_ship("kvlcc2_l7")), state, inputs) is None
    with native.torch_path():
        assert native.forward(ESSO, state, inputs) is None


def test_identified_coefficients_are_the_views_values(kernel):
    """A frozen identified MMG's values reach the kernel (its coefficient vector is made per
    values view), not the ship file's."""
    mmg = MMG(load_ship("esso_osaka"), trainable=["X_vr", "C_D"], bounds={"C_D": (0.0, 5.0)})
    mmg.coefficients.assign({"X_vr": 0.45, "C_D": 1.3})
    mmg.requires_grad_(False)
    c = mmg.coefficients.values_view(torch.float64)
    state, inputs = branch_rows()
    out, jacobian = native.rate_with_jacobian(state, inputs, c)
    ref_out, ref_jacobian = _torch_path(state, inputs, c)
    assert _relative(out, ref_out, 0) < 1e-12 and _relative(jacobian, ref_jacobian, (0, 1)) < 1e-12
    assert not torch.allclose(out, native.rate(state, inputs, C))


def _rollout(model, states, inputs):
    pred, f_nn, f_mmg = integrate_training(model, states[0], inputs, 0.1)
    loss = pred.square().mean() + f_nn.square().mean() + f_mmg.square().mean()
    net = model.model.correction_net
    net.zero_grad()
    loss.backward()
    return [loss.detach(), pred.detach()] + [p.grad.clone() for p in net.parameters()]


def test_a_float32_training_rollout_equals_the_torch_path(kernel, d2_rows):
    """Loss, states and every network gradient of a T = 10 Euler rollout (two FNN members) in
    float32, through the kernel and through the torch VJP: equal to float32 round-off."""
    state, inputs = d2_rows
    states = state.reshape(11, -1, 6)[:, :256].float().unsqueeze(1).expand(-1, 2, -1, -1)
    u = inputs.reshape(11, -1, 4)[:, :256].float().unsqueeze(1).expand(-1, 2, -1, -1)
    torch.manual_seed(0)
    net = ForceCorrection((16, 16), torch.float32, members=2)
    flat = states.reshape(-1, 6)
    net.set_standardization(flat.mean(0).repeat(2)[:9], flat.std(0).repeat(2)[:9] + 0.1,
                            torch.zeros(3), torch.tensor([2.0, 3.0, 1.5]))
    model = PerMember(CorrectedModel(MMG(load_ship("esso_osaka"), dtype=torch.float32), net))
    calls = []
    original = native.training_rate

    def counted(*args):
        calls.append(args[0].dtype)
        return original(*args)
    native.training_rate = counted
    try:
        new = _rollout(model, states, u)
    finally:
        native.training_rate = original
    with native.torch_path():
        old = _rollout(model, states, u)
    assert calls == [torch.float32] * 10  # the rollout went through the kernel
    for a, b in zip(new, old):
        assert a.dtype == torch.float32
        torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * float(b.abs().max()))


def test_a_second_build_reuses_the_library_and_a_corrupt_one_is_not_loaded(tmp_path):
    first = native.build(tmp_path)
    assert first.compiled and first.path.parent == tmp_path
    before = first.path.stat()
    second = native.build(tmp_path)
    after = second.path.stat()
    assert not second.compiled and second.path == first.path
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    assert sorted(p.name for p in tmp_path.iterdir()) == [first.path.name]  # no temporary left
    # a partial file under the library's name (a crash mid-copy, a full disk) is rebuilt
    data = first.path.read_bytes()
    first.path.write_bytes(data[: len(data) // 2])
    third = native.build(tmp_path)
    assert third.compiled and third.path == first.path and third.path.read_bytes() == data
    assert third.path.stat().st_ino != before.st_ino
    library = native.load(third.path)
    assert library.sysid_mmg_width() == native.N_COEFFICIENTS


def test_the_cache_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("SYSID_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert native.cache_dir() == tmp_path / "xdg" / "sysid" / "native"
    monkeypatch.setenv("SYSID_CACHE_DIR", str(tmp_path / "own"))
    assert native.cache_dir() == tmp_path / "own"


def _fresh_process_state(monkeypatch):
    monkeypatch.setattr(native, "_STATE", {})


def test_sysid_native_0_gives_the_torch_path_with_one_log_line(monkeypatch, caplog):
    _fresh_process_state(monkeypatch)
    monkeypatch.setenv("SYSID_NATIVE", "0")
    state, inputs = branch_rows()
    with caplog.at_level(logging.INFO, logger="sysid.mmg.native"):
        assert not native.applies(state, inputs, C)
        with torch.no_grad():
            out, jacobian = rate_with_jacobian(state, inputs, C)
            rate_with_jacobian(state, inputs, C)
    lines = [r for r in caplog.records if r.name == "sysid.mmg.native"]
    assert len(lines) == 1 and "SYSID_NATIVE=0" in lines[0].getMessage()
    ref_out, ref_jacobian = _torch_path(state, inputs)
    assert torch.equal(out, ref_out) and torch.equal(jacobian, ref_jacobian)  # the torch path's own bits


def test_a_failed_compile_gives_the_torch_path_with_one_warning(monkeypatch, caplog, tmp_path):
    _fresh_process_state(monkeypatch)
    monkeypatch.setenv("SYSID_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CXX", "false")  # a compiler that fails
    state, inputs = switch_rows()
    with caplog.at_level(logging.INFO, logger="sysid.mmg.native"):
        assert native.library() is None and not native.applies(state, inputs, C)
        assert native.library() is None
    lines = [r for r in caplog.records if r.name == "sysid.mmg.native"]
    assert len(lines) == 1 and lines[0].levelno == logging.WARNING and "failed" in lines[0].getMessage()
    assert list(tmp_path.glob("*.so")) == []  # nothing half-written


def test_where_the_kernel_does_not_apply(kernel):
    state, inputs = branch_rows()
    assert native.applies(state, inputs, C)
    assert not native.applies(state.float(), inputs, C)                      # two dtypes
    assert not native.applies(state.to(torch.float16), inputs.to(torch.float16), C)
    assert not native.applies(state.requires_grad_(True), inputs, C)         # autograd would be skipped
    with torch.no_grad():
        assert native.applies(state, inputs, C)
    identified = MMG(load_ship("esso_osaka"), trainable=["X_vr"])
    assert not native.applies(state.detach(), inputs, identified.coefficients.values_view(torch.float64))
    assert native.covers(ESSO) and not native.covers(MMG(load_ship("kvlcc2_l7")))
    assert not native.covers(MMG(load_ship("esso_osaka"), quadrature="simpson"))


def test_a_new_process_loads_the_cached_library_without_compiling(kernel, tmp_path):
    """A library built by one process is found by the next on the same cache (same file)."""
    built = native.build(tmp_path)
    before = built.path.stat()
    code = ("import logging, sys; logging.basicConfig(level=logging.DEBUG, stream=sys.stdout);"
            "from sysid.mmg import native; print(native.library() is not None)")
    env = dict(os.environ, SYSID_CACHE_DIR=str(tmp_path))
    env.pop("SYSID_NATIVE", None)
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and "True" in run.stdout, run.stderr
    assert f"{built.path} (from the cache" in run.stdout
    after = built.path.stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    assert len(list(tmp_path.glob("mmg-*.so"))) == 1
