"""``sysid export``: one integration step of a trained model as a ``.pt2`` file."""
from __future__ import annotations

from pathlib import Path

import typer

from sysid import logs
from sysid.cli.app import app
from sysid.cli.outputs import claim
from sysid.store.target import OutputKind
from sysid.errors import DataError


@app.command()
def export(
    run_dir: Path = typer.Argument(..., help="A run directory (sysid train)."),
    output: Path = typer.Option(..., "-o", "--output", help="File to write, ending in .pt2 (model.pt2)."),
    integrator: str = typer.Option("euler", "--integrator", help="euler (the paper's), rk4 (classical) or rk4_3/8."),
    dt: float = typer.Option(1.0, "--dt", help="Step length [s]."),
    batch: int = typer.Option(1, "--batch", help="Ships per call (fixed in the file)."),
    float32: bool = typer.Option(False, "--float32", help="float32 instead of float64."),
    portable: bool = typer.Option(False, "--portable",
                                  help="A torch.export program (any platform and later torch, tens of times slower) instead of native code."),
    with_gate: bool = typer.Option(False, "--with-gate", help="Return the kNN gate's decision too: step(x, u) -> "
                                                              "(x_next, gate_on), gate_on 1 where the FNN acted, 0 "
                                                              "outside the training data."),
) -> None:
    """Export step(state, inputs) -> next state of a trained model (MMG, NN-only, hybrid with its
    kNN gate), loadable with torch alone; prints its latency."""
    import torch

    from sysid.config.choices import Method
    from sysid.fast.export import export_model, load_step, step_latency
    from sysid.runs.layout import load_model
    from sysid.config import checks

    try:
        method = Method.parse(integrator, "--integrator")  # every rule, the 3/8 one too
    except ValueError as exc:
        raise DataError(str(exc)) from None
    checks.STEP.check("--dt", dt)
    checks.BATCH.check("--batch", batch)
    dtype = torch.float32 if float32 else torch.float64
    claim(output, OutputKind.FILE, [run_dir])
    if output.suffix != ".pt2":   # torch loads a package or program by this suffix (else warns, later refuses)
        raise DataError(f"-o {output}: an exported step is a .pt2 file; name it e.g. -o {output.with_suffix('.pt2')}")
    exp, model = load_model(run_dir, dtype)
    export_model(model, output, method, dt, batch, dtype, compiled=not portable,
                 log=logs.indented(), gate=with_gate)
    per_step, prediction = step_latency(load_step(output), 200 if portable else 2000)
    kind = "torch.export program" if portable else "AOTInductor package"
    outputs = "the state and the kNN gate's decision" if with_gate else "the state alone"
    typer.echo(f"export: {exp.experiment.model} model of {run_dir}, {method.value} dt {dt:g} s, batch {batch}, "
               f"{str(dtype)[6:]} -> {output} ({kind}; returns {outputs})\n"
               f"  latency: {per_step * 1e6:.0f} us per step, {prediction * 1e3:.1f} ms per 100-step prediction")
