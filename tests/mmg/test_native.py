"""The native MMG kernel (`sysid.mmg.native`) against the torch path it replaces
(`sysid.mmg.tangents` through `sysid.mmg.vjp`) and against autograd through the MMG: values
and Jacobians in float64 on every branch, at the switches and on the D2 training windows,
with and without wind; a float32 training rollout's loss and gradients; the compiled
library's cache (reused, never a corrupt file) and the fallbacks to torch."""
from __future__ import annotations

import dataclasses
import logging
import os
import subprocess
import sys
from pathlib import Path
from types import MappingProxyType

import pytest
import torch

from sysid.dynamics.equations import integrate_training
from sysid.mmg.native import Families
from sysid.hybrid.correction import ForceCorrection
from sysid.hybrid.force_models import CorrectedModel, PerMember
from sysid.mmg import native
from sysid.mmg.families import FAMILIES
from sysid.mmg.model import MMG
from sysid.mmg.ship import active_parameters, load_ship
from sysid.mmg.vjp import rate_with_jacobian
from mmg_rows import ESSO, branch_rows, reference, rows_of, switch_rows

ROOT = Path(__file__).resolve().parents[2]
C = ESSO.coefficients.values_view(torch.float64)
KVLCC2 = load_ship("kvlcc2_l7")


def _with_families(ship, donor, components, models=None):
    """`ship` with `donor`'s families of `components` (and their parameters from `donor`),
    then the families in `models` ({component: name}, parameters from `donor`)."""
    chosen = dict(ship.models)
    chosen.update({k: donor.models[k] for k in components})
    chosen.update(models or {})
    parameters = dict(ship.parameters)
    for component in set(components) | set(models or {}):
        parameters.update({k: donor.parameters[k] for k in FAMILIES[component][chosen[component]].parameters})
    parameters = {k: parameters[k] for k in active_parameters(chosen)}  # the mix's parameters only
    return dataclasses.replace(ship, name=f"{ship.name}+{donor.name}", models=MappingProxyType(chosen),
                               parameters=MappingProxyType(parameters))


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
    assert native.forward(MMG(load_ship("esso_osaka"), quadrature="simpson"), state, inputs) is None
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


def _rollout(model, states, inputs, fast=True):
    pred, f_nn, f_mmg = integrate_training(model, states[0], inputs, 0.1, fast)
    loss = pred.square().mean() + f_nn.square().mean() + f_mmg.square().mean()
    net = model.model.correction_net
    net.zero_grad()
    loss.backward()
    return [loss.detach(), pred.detach()] + [p.grad.clone() for p in net.parameters()]


def _hybrid(ship, states, dtype, force_scale):
    """A two-member hybrid of `ship` whose FNN is standardised on `states` (seeded)."""
    torch.manual_seed(0)
    net = ForceCorrection((16, 16), dtype, members=2)
    flat = states.reshape(-1, 6)
    net.set_standardization(flat.mean(0).repeat(2)[:9], flat.std(0).repeat(2)[:9] + 0.1,
                            torch.zeros(3), torch.tensor(force_scale))
    return PerMember(CorrectedModel(MMG(ship, dtype=dtype), net))


def _rollout_through_the_kernel(model, states, inputs):
    """`_rollout` and the dtype of every kernel call it made (`native.training_rate`, or a
    `native.TrainingKernel`'s: the fused right-hand side, `sysid.hybrid.fused_rate`)."""
    calls = []
    original, original_call = native.training_rate, native.TrainingKernel.__call__

    def counted(*args):
        calls.append(args[0].dtype)
        return original(*args)

    def counted_call(self, *args):
        calls.append(args[0].dtype)
        return original_call(self, *args)
    native.training_rate, native.TrainingKernel.__call__ = counted, counted_call
    try:
        return _rollout(model, states, inputs), calls
    finally:
        native.training_rate, native.TrainingKernel.__call__ = original, original_call


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_training_rollout_equals_the_torch_path(kernel, d2_rows, dtype):
    """Loss, states and every network gradient of a T = 10 Euler rollout (two FNN members),
    through the kernel and through the torch VJP: equal to round-off."""
    state, inputs = d2_rows
    states = state.reshape(11, -1, 6)[:, :256].to(dtype).unsqueeze(1).expand(-1, 2, -1, -1)
    u = inputs.reshape(11, -1, 4)[:, :256].to(dtype).unsqueeze(1).expand(-1, 2, -1, -1)
    model = _hybrid(load_ship("esso_osaka"), states, dtype, [2.0, 3.0, 1.5])
    new, calls = _rollout_through_the_kernel(model, states, u)
    with native.torch_path():
        old = _rollout(model, states, u)
    assert calls == [dtype] * 10  # the rollout went through the kernel
    rtol = 2e-5 if dtype == torch.float32 else 1e-11
    for a, b in zip(new, old):
        assert a.dtype == dtype
        torch.testing.assert_close(a, b, rtol=rtol, atol=rtol * float(b.abs().max()))



@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_the_state_gradient_is_the_jacobian_times_the_gradients(kernel, dtype):
    """`state_gradient` of any Jacobian (its x and y rows too) equals torch's product of the
    Jacobian with (g_rate, g_force, g_z) in float64, a None gradient as zero; a non-finite
    gradient gives NaN (or the infinity) where the product does, in the x and y rows too."""
    torch.manual_seed(3)
    rows = 300
    jacobian = torch.randn(2, rows // 2, 6, 18, dtype=torch.float64)
    jacobian[0, :5, [0, 2]] = 0.0  # rows x, y zero, as the kernel's
    g = [torch.randn(rows, n, dtype=torch.float64) * 10 for n in (6, 3, 9)]
    g[0][7, 2] = float("inf")
    g[2][11, 4] = float("nan")
    for grads in (g, [None, g[1], g[2]], [g[0], None, None]):
        full = torch.cat([torch.zeros(rows, n, dtype=torch.float64) if x is None else x
                          for x, n in zip(grads, (6, 3, 9))], -1)
        expected = (jacobian.reshape(rows, 6, 18) * full.unsqueeze(1)).sum(-1).reshape(2, rows // 2, 6)
        got = native.state_gradient(jacobian.to(dtype), *[None if x is None else x.to(dtype) for x in grads])
        assert got.shape == (2, rows // 2, 6) and got.dtype == dtype
        if dtype == torch.float32:  # the product of the float32 entries, summed in double
            expected = (jacobian.to(dtype).double().reshape(rows, 6, 18)
                        * torch.cat([torch.zeros(rows, n, dtype=torch.float64) if x is None else x.to(dtype).double()
                                     for x, n in zip(grads, (6, 3, 9))], -1).unsqueeze(1)).sum(-1)
            expected = expected.reshape(2, rows // 2, 6).to(dtype)
        torch.testing.assert_close(got, expected, rtol=1e-6 if dtype == torch.float32 else 1e-13, atol=1e-12,
                                   equal_nan=True)
        assert torch.equal(got.isnan(), expected.isnan())
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


def test_a_cache_that_cannot_be_written_gives_the_torch_path(monkeypatch, caplog, tmp_path):
    _fresh_process_state(monkeypatch)
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("SYSID_CACHE_DIR", str(blocker / "cache"))
    with caplog.at_level(logging.INFO, logger="sysid.mmg.native"):
        assert native.library() is None
    lines = [r for r in caplog.records if r.name == "sysid.mmg.native"]
    assert len(lines) == 1 and "cannot build into the cache" in lines[0].getMessage()


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
    assert native.covers(ESSO) and native.covers(MMG(load_ship("kvlcc2_l7")))
    # a standard propeller drives only the standard rudder in the kernel
    assert not native.covers(MMG(_with_families(KVLCC2, ESSO.ship, ("rudder",))))
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


# the standard families (Yasukawa & Yoshimura 2015) and mixes with the Esso Osaka's
STANDARD_SHIPS = {
    "kvlcc2": (KVLCC2, Families.HULL_STANDARD | Families.PROPELLER_STANDARD),
    "kvlcc2 gaussian wake": (_with_families(KVLCC2, KVLCC2, (), {"propeller": "standard_gaussian_wake"}),
                             Families.HULL_STANDARD | Families.PROPELLER_STANDARD | Families.WAKE_GAUSSIAN),
    "esso hull and wind, standard propeller and rudder": (
        _with_families(ESSO.ship, KVLCC2, ("propeller", "rudder")), Families.PROPELLER_STANDARD | Families.WIND),
    "standard hull, esso propeller, rudder and wind": (
        _with_families(ESSO.ship, KVLCC2, ("hull",)), Families.HULL_STANDARD | Families.WIND),
}


def standard_rows() -> tuple[torch.Tensor, torch.Tensor]:
    """Random rows (seeded) over the operating range, ahead and astern, ahead and reverse
    revolutions, then rows on switches: beta_P = beta_R = 0 (v = r = 0), n = 0, u = 0, inside
    the speed guard, calm."""
    g = torch.Generator().manual_seed(7)

    def uniform(low, high, size=300):
        return low + (high - low) * torch.rand(size, generator=g, dtype=torch.float64)
    random = torch.stack([uniform(-0.8, 2.0), uniform(-0.5, 0.5), uniform(-3.0, 3.0), uniform(-0.3, 0.3),
                          uniform(-10.0, 25.0), uniform(-0.6, 0.6), uniform(0.0, 5.0), uniform(0.0, 6.2)], -1)
    state, inputs = rows_of(random.tolist())
    switch_state, switch_inputs = rows_of([
        (1.0, 0.0, 0.3, 0.0, 15.0, 0.2, 3.0, 1.0),
        (-0.5, 0.0, 0.3, 0.0, -8.0, -0.2, 3.0, 1.0),
        (0.8, 0.05, 0.2, 0.01, 0.0, 0.2, 4.0, 0.5),
        (0.0, 0.3, 0.2, 0.01, 5.0, 0.1, 3.0, 1.0),
        (4e-6, 3e-6, 0.4, 0.01, 3.0, 0.2, 3.0, 2.0),
        (0.6, 0.02, 0.4, 0.01, 12.0, 0.2, 0.0, 2.0),
    ])
    return torch.cat([state, switch_state]), torch.cat([inputs, switch_inputs])


@pytest.mark.parametrize("name", list(STANDARD_SHIPS))
def test_standard_families_equal_the_mmgs_torch_forward_and_autograds_jacobian(kernel, name):
    """The standard hull, both standard propellers (wake by Yasukawa's C_1, C_2 and shipmmg's
    Gaussian) with the standard rudder, alone and mixed with the Esso Osaka's families: out as
    the MMG's own forward (no grad) to 1e-12, the Jacobian as autograd's through it to 1e-10."""
    ship, families = STANDARD_SHIPS[name]
    mmg = MMG(ship)
    assert native.families_of(mmg) == families
    state, inputs = standard_rows()
    u, n = state[:, 1], inputs[:, 0]
    assert ((u < 0) & (n < 0)).any() and ((u < 0) & (n > 0)).any() and ((u > 0) & (n < 0)).any()
    with torch.no_grad():
        out, ref = native.forward(mmg, state, inputs), reference(state, inputs, mmg)
    assert _relative(out, ref, 0) < 1e-12
    c = mmg.coefficients.values_view(torch.float64)
    values, jacobian = native.rate_with_jacobian(state, inputs, c, families)
    assert torch.equal(values, out)
    truth = torch.autograd.functional.jacobian(lambda x: reference(x, inputs, mmg).sum(0), state).permute(1, 2, 0)
    assert _relative(jacobian, truth, (0, 1)) < 1e-10


def test_a_kvlcc2_training_rollout_through_the_kernel_equals_autograd(kernel):
    """Loss, states and every network gradient of a T = 10 float32 Euler rollout of a KVLCC2
    hybrid (two FNN members) through the kernel and through autograd over the forward."""
    dtype = torch.float32
    state, inputs = standard_rows()
    keep = state[:, 1] > 0.2  # ahead motion, as in training logs
    states = state[keep][:128].to(dtype).expand(11, 2, -1, -1)
    u = inputs[keep][:128].to(dtype).expand(11, 2, -1, -1)
    model = _hybrid(KVLCC2, states, dtype, [20.0, 30.0, 15.0])
    new, calls = _rollout_through_the_kernel(model, states, u)
    assert calls == [dtype] * 10  # the rollout went through the kernel
    old = _rollout(model, states, u, fast=False)  # autograd over every operation
    with native.torch_path():  # a step the kernel does not take: autograd over the forward
        fallback = _rollout(model, states, u)
    for a, b, f in zip(new, old, fallback):
        assert a.dtype == dtype
        torch.testing.assert_close(a, b, rtol=2e-5, atol=2e-5 * float(b.abs().max()))
        torch.testing.assert_close(f, b, rtol=2e-5, atol=2e-5 * float(b.abs().max()))


def test_the_torch_vjp_computes_only_the_esso_osakas_families(kernel):
    """Where the kernel does not apply, the hand-derived torch VJP refuses the standard
    families in one line (it has the Esso Osaka's derivatives only)."""
    from sysid.mmg.vjp import training_rate
    state, inputs = standard_rows()
    c = MMG(KVLCC2).coefficients.values_view(torch.float64)
    mean, std = torch.zeros(9, dtype=torch.float64), torch.ones(9, dtype=torch.float64)
    with native.torch_path(), pytest.raises(ValueError, match="computes the Esso Osaka's only"):
        training_rate(state, inputs, c, Families.HULL_STANDARD | Families.PROPELLER_STANDARD, mean, std)
