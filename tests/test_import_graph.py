"""The package's import graph: no circle anywhere (module-level or inside functions), and the
data flow stays one way: preprocessing -> data -> models -> train -> evaluate -> report."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sysid", "preprocessing")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """module -> the project modules it imports (any depth in the file)."""
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = name.split(".")[: len(name.split(".")) - node.level + (1 if is_package else 0)]
                    base = ".".join(anchor + ([base] if base else []))
                # a submodule, or a name defined in `base` itself (an edge to base, parents too)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            for target in targets:
                while target and target not in files:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    edges.add(target)
        graph[name] = edges
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_graph_is_read_and_sees_known_edges():
    graph = import_graph()
    assert "sysid.identify.trainer" in graph["sysid.runs.lifecycle"]  # the checker does see imports
    assert "sysid.mmg.model" in graph["sysid.hybrid.force_models"]


def test_no_import_circle():
    cycle = _cycle(import_graph())
    assert cycle is None, " -> ".join(cycle)


def test_data_flows_one_way():
    graph = import_graph()

    def reaches(src: str, dst: str) -> bool:
        seen, todo = set(), [src]
        while todo:
            node = todo.pop()
            if node == dst or node.startswith(dst + "."):
                return True
            if node not in seen:
                seen.add(node)
                todo += graph.get(node, ())
        return False

    assert not any(reaches(m, "sysid") for m in graph if m.startswith("preprocessing"))
    order = ["sysid.data.recordings", "sysid.hybrid.force_models", "sysid.identify.trainer", "sysid.evaluation.evaluate", "sysid.report"]
    for i, upstream in enumerate(order):
        for downstream in order[i + 1:]:
            assert not reaches(upstream, downstream), f"{upstream} imports {downstream}"
    assert not any(reaches(m, "sysid.cli") for m in graph if not m.startswith("sysid.cli") and m != "sysid.__main__")


def test_no_two_modules_named_alike():
    names = sorted({Path(m.replace(".", "/")).name for m in import_graph()})
    for a in names:
        for b in names:
            assert a == b or not (a.startswith(b) and len(a) - len(b) <= 3 and len(b) >= 4), (a, b)
