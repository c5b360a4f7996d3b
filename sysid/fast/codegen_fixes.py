"""Two fixes to AOTInductor's C++ wrapper code for subgraphs, applied while sysid compiles.

A compiled rollout runs its steps as a `while_loop` whose body holds the kNN gate's `cond`s.
AOTInductor's C++ wrapper (torch 2.13) inlines each of these subgraphs where it runs, and
on every pass of the loop it:

1. allocates every buffer of the subgraph, even those the subgraph's fused kernels keep
   in registers and never touch in memory. The memory planner decides which allocations to
   drop against the *main* graph's list of removed buffers, not the subgraph's. In the
   MMG's RK4 step this left 51 of 59 one-element tensors allocated and never used;
2. makes a new tensor handle for every input of the subgraph, whether it uses it or not.
   The loop's condition (k < steps) took all 25 inputs of the hybrid's loop.

Each allocation is a few calls to malloc and free. Together they took about half the time
of a compiled 100 s MMG prediction (measured with perf). `subgraph_fixes()` patches the
two wrapper methods for the duration of a compilation: the memory planner also drops the
subgraphs' removed buffers, and a subgraph gets handles only for the inputs it uses. The
kernels are untouched, so the numbers are bit-identical (tests/test_compiled.py). Only
torch versions where this was checked (`TESTED_TORCH`) are patched; elsewhere compilation
runs as torch ships it, slower but the same.
"""
from __future__ import annotations

import contextlib
from typing import Iterator

import torch

TESTED_TORCH = ("2.13",)  # major.minor versions whose wrapper code these fixes were checked on
VERSION = "1"  # part of the compile cache key: packages built with and without differ


def available() -> bool:
    """True where the fixes apply: a tested torch with the two wrapper methods they replace."""
    if ".".join(torch.__version__.split(".")[:2]) not in TESTED_TORCH:
        return False
    try:
        from torch._inductor.codegen import cpp_wrapper_cpu, wrapper
    except ImportError:
        return False
    return (hasattr(wrapper, "EnterSubgraphLine") and hasattr(wrapper.PythonWrapperCodegen, "memory_plan_reuse")
            and hasattr(cpp_wrapper_cpu.CppWrapperCpu, "codegen_subgraph_prefix"))


def cache_tag() -> str:
    """What the compile cache key records of these fixes: their version, or "none"."""
    return f"codegen-fixes-{VERSION}" if available() else "codegen-fixes-none"


@contextlib.contextmanager
def subgraph_fixes() -> Iterator[None]:
    """Within the block, AOTInductor's C++ wrapper drops the subgraphs' unused allocations
    and input handles (module docstring); a no-op where `available()` is False."""
    if not available():
        yield
        return
    from torch._inductor import ir
    from torch._inductor.codegen import cpp_wrapper_cpu, wrapper
    from torch._inductor.virtualized import V

    plan_reuse = wrapper.PythonWrapperCodegen.memory_plan_reuse
    subgraph_prefix = cpp_wrapper_cpu.CppWrapperCpu.codegen_subgraph_prefix

    def memory_plan_reuse(self):
        # plan with the subgraphs' removed buffers too (their names carry the subgraph's
        # prefix, so they cannot clash with the main graph's)
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
        # as torch's, for the inputs the subgraph reads only
        graph = subgraph.graph
        used = {graph.qualify_name(node.target) for node in graph.module.graph.nodes
                if node.op == "placeholder" and node.users}
        assert len(graph.graph_inputs) == len(outer_inputs)
        for (inner, value), outer in zip(graph.graph_inputs.items(), outer_inputs):
            if not isinstance(value, ir.TensorBox) or inner not in used:
                continue
            self.writeline(f"AtenTensorHandle {inner}_handle;")
            self.writeline(f"AOTI_TORCH_ERROR_CODE_CHECK(aoti_torch_assign_tensors_out({outer}, &{inner}_handle));")
            self.writeline(f"RAIIAtenTensorHandle {inner}({inner}_handle);")

    wrapper.PythonWrapperCodegen.memory_plan_reuse = memory_plan_reuse
    cpp_wrapper_cpu.CppWrapperCpu.codegen_subgraph_prefix = codegen_subgraph_prefix
    try:
        yield
    finally:
        wrapper.PythonWrapperCodegen.memory_plan_reuse = plan_reuse
        cpp_wrapper_cpu.CppWrapperCpu.codegen_subgraph_prefix = subgraph_prefix
