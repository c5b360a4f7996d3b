"""Two fixes to AOTInductor's C++ wrapper code for subgraphs, applied while sysid compiles.

A compiled rollout runs its steps as a `while_loop` whose body holds the kNN gate's `cond`s.
AOTInductor's C++ wrapper (torch 2.13.0) inlines each of these subgraphs where it runs, and
on every pass of the loop it:

1. allocates every buffer of the subgraph, even those the subgraph's fused kernels keep
   in registers and never touch in memory. The memory planner decides which allocations to
   drop against the *main* graph's list of removed buffers, not the subgraph's. In the
   MMG's RK4 step this left 51 of 59 one-element tensors allocated and never used;
2. makes a new tensor handle for every input of the subgraph, whether it uses it or not.
   The loop's condition (k < steps) took all 25 inputs of the hybrid's loop.

Each allocation is a few calls to malloc and free. Together they took about half the time
of a compiled 100 s MMG prediction (measured with perf). `subgraph_fixes()` wraps the two
wrapper methods for the duration of a compilation; each calls torch's own method:

1. ``PythonWrapperCodegen.memory_plan_reuse`` runs with the subgraphs' removed buffers added
   to the graph's list (their names carry the subgraph's prefix, so they cannot clash);
2. ``CppWrapperCpu.codegen_subgraph_prefix`` runs with the inputs the subgraph does not
   read hidden from it (shown as non-tensors, which it skips), so it writes handles only
   for the others.

The kernels are untouched, so the numbers are bit-identical (tests/fast/test_compiled.py).

The fixes lean on the private names and behaviour of exactly the torch they were derived
from (`TORCH_VERSION`); under any other torch `available()` is False and compilation runs
as torch ships it: slower, the same numbers.

To drop this module (once torch plans a subgraph's buffers against its own removed buffers
and gives handles only to the inputs a subgraph reads, or to move to another torch):
delete it, the ``codegen_fixes.subgraph_fixes()`` context in
`sysid.fast.compiled.compile_package` and ``codegen_fixes.cache_tag()`` in
`sysid.fast.compiled.fingerprint`; then
``tests/fast/test_compiled.py::test_compiled_loop_allocates_only_what_its_kernels_use`` (which
reads the generated loop) says whether torch alone now allocates only what its kernels use.
"""
from __future__ import annotations

import contextlib
from typing import Iterator

import torch

TORCH_VERSION = "2.13.0"  # the torch whose wrapper code these fixes were derived from and checked on
VERSION = "2"  # part of the compile cache key: packages built with and without differ


def available() -> bool:
    """True where the fixes apply: exactly `TORCH_VERSION` (any local build tag such as
    ``+cpu``) with the wrapper methods and classes they wrap."""
    if torch.__version__.split("+")[0] != TORCH_VERSION:
        return False
    try:
        from torch._inductor.codegen import cpp_wrapper_cpu, wrapper
    except ImportError:
        return False
    return (hasattr(wrapper, "EnterSubgraphLine") and hasattr(wrapper.PythonWrapperCodegen, "memory_plan_reuse")
            and hasattr(cpp_wrapper_cpu.CppWrapperCpu, "codegen_subgraph_prefix"))


def cache_tag() -> str:
    """What the compile cache key records of these fixes: their version under `TORCH_VERSION`,
    else "none". Read from the version alone (the key's torch version pins the rest), so
    that checking the cache imports no compiler (`torch._inductor`: seconds)."""
    return f"codegen-fixes-{VERSION}" if torch.__version__.split("+")[0] == TORCH_VERSION else "codegen-fixes-none"


def _read_inputs(graph) -> set[str]:
    """Names of the subgraph inputs (placeholders) that some node of `graph` reads."""
    return {graph.qualify_name(node.target) for node in graph.module.graph.nodes
            if node.op == "placeholder" and node.users}


@contextlib.contextmanager
def subgraph_fixes() -> Iterator[None]:
    """Within the block, AOTInductor's C++ wrapper drops the subgraphs' unused allocations
    and input handles (module docstring); a no-op where `available()` is False."""
    if not available():
        yield
        return
    from torch._inductor.codegen import cpp_wrapper_cpu, wrapper
    from torch._inductor.virtualized import V

    plan_reuse = wrapper.PythonWrapperCodegen.memory_plan_reuse
    subgraph_prefix = cpp_wrapper_cpu.CppWrapperCpu.codegen_subgraph_prefix

    def memory_plan_reuse(self):
        removed = V.graph.removed_buffers
        for line in self.lines:
            if isinstance(line, wrapper.EnterSubgraphLine):
                removed = removed | line.graph.removed_buffers
        kept, V.graph.removed_buffers = V.graph.removed_buffers, removed
        try:
            return plan_reuse(self)
        finally:
            V.graph.removed_buffers = kept

    def codegen_subgraph_prefix(self, subgraph, outer_inputs, outer_outputs):
        graph = subgraph.graph
        read = _read_inputs(graph)
        inputs = graph.graph_inputs
        graph.graph_inputs = {name: value if name in read else None for name, value in inputs.items()}
        try:
            return subgraph_prefix(self, subgraph, outer_inputs, outer_outputs)
        finally:
            graph.graph_inputs = inputs

    wrapper.PythonWrapperCodegen.memory_plan_reuse = memory_plan_reuse
    cpp_wrapper_cpu.CppWrapperCpu.codegen_subgraph_prefix = codegen_subgraph_prefix
    try:
        yield
    finally:
        wrapper.PythonWrapperCodegen.memory_plan_reuse = plan_reuse
        cpp_wrapper_cpu.CppWrapperCpu.codegen_subgraph_prefix = subgraph_prefix
