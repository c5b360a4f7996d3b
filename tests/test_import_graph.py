"""The package's import graph: no circle anywhere (module-level or inside functions), none
between subpackages, every subpackage in its layer (`LAYERS`: each imports only those below
it), and the data flow stays one way: preprocessing -> data -> models -> train -> evaluate ->
report. Training, evaluation, run directories and the protocol do not load the compiled path
(`sysid.fast`) when imported; the config is read without torch or pandas; `RunDir` without
torch or training code."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sysid", "preprocessing")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(tree: ast.AST):
    """(import node, executed when the module is imported) for every import in the file:
    those inside a function body run only when it is called."""
    todo = [(tree, False)]
    while todo:
        node, deferred = todo.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node, not deferred
        inner = deferred or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        todo += [(child, inner) for child in ast.iter_child_nodes(node)]


def import_edges() -> tuple[dict[str, dict[str, bool]], dict[str, dict[str, bool]]]:
    """module -> {project module it imports: at import time?} and module -> {outside
    top-level package it imports (torch, numpy, ...): at import time?}."""
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, dict[str, bool]] = {}
    outside: dict[str, dict[str, bool]] = {}
    for name, path in files.items():
        is_package = path.name == "__init__.py"
        edges, external = {}, {}
        for node, at_import in _imports(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = name.split(".")[: len(name.split(".")) - node.level + (1 if is_package else 0)]
                    base = ".".join(anchor + ([base] if base else []))
                # a submodule, or a name defined in `base` itself (an edge to base, parents too)
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            for target in targets:
                if target.split(".")[0] not in PACKAGES:
                    top = target.split(".")[0]
                    external[top] = external.get(top, False) or at_import
                    continue
                while target and target not in files:
                    target = target.rpartition(".")[0]
                if target and target != name:
                    edges[target] = edges.get(target, False) or at_import
        graph[name], outside[name] = edges, external
    return graph, outside


def import_graph() -> dict[str, set[str]]:
    """module -> the project modules it imports (any depth in the file)."""
    return {name: set(edges) for name, edges in import_edges()[0].items()}


def import_time_graph() -> dict[str, set[str]]:
    """module -> the project modules importing it imports (function bodies left out)."""
    return {name: {t for t, now in edges.items() if now} for name, edges in import_edges()[0].items()}


def package_of(module: str) -> str:
    """The unit a module belongs to: its subpackage of sysid (``sysid.mmg``), a top-level
    module of sysid as itself (``sysid.errors``), or its top-level package."""
    parts = module.split(".")
    if parts[0] == "sysid" and len(parts) > 1 and (ROOT / "sysid" / parts[1]).is_dir():
        return ".".join(parts[:2])
    return module if parts[0] == "sysid" else parts[0]


def package_graph() -> dict[str, set[str]]:
    """subpackage -> the subpackages its modules import (any depth in the file)."""
    out: dict[str, set[str]] = {}
    for module, targets in import_graph().items():
        here = package_of(module)
        out.setdefault(here, set()).update(package_of(t) for t in targets if package_of(t) != here)
    return out


def reached(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module `start` imports, directly or through others."""
    seen, todo = set(), [start]
    while todo:
        node = todo.pop()
        if node not in seen:
            seen.add(node)
            todo += graph.get(node, ())
    return seen - {start}


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


# The layers, lowest first: a unit (a subpackage of sysid, a top-level module of sysid, or
# `preprocessing`) imports only units of lower layers, anywhere in its files (function bodies
# included), never one of its own layer or above. `sysid.fast` is imported when a module is
# imported only by the CLI (`test_training_evaluation_and_runs_do_not_load_the_compiled_path`,
# `test_the_protocol_loads_the_compiled_path_only_where_it_is_chosen`).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("preprocessing", "sysid", "sysid.errors", "sysid.channel_names", "sysid.logs", "sysid.workers", "sysid.package_data"),
    ("sysid.progress", "sysid.store"),        # progress lines; files, manifests, staging
    ("sysid.mmg",),                           # ship files, force families, the force model
    ("sysid.config",),                        # the closed choices and experiment configs (no torch, no pandas)
    ("sysid.records", "sysid.device"),        # what a run directory holds (no torch); the torch device
    ("sysid.dynamics", "sysid.hybrid", "sysid.data"),
    ("sysid.fast",),                          # the compiled path and export
    ("sysid.identify", "sysid.evaluation"),   # training; evaluation and the verdict (evaluation reads no trainer)
    ("sysid.runs",),                          # run directories: written by the lifecycle, read by `RunDir`
    ("sysid.experiment_tracking",),                      # MLflow
    ("sysid.sweep",),
    ("sysid.maneuvers",),
    ("sysid.protocol",),
    ("sysid.report",),
    ("sysid.cli",),
    ("sysid.__main__",),
)
# (module, module it imports) against the layers, each waiting for its fix: none left (the
# verdict's losses live in `sysid.dynamics.rollouts`, below training and evaluation).
KNOWN_BREAKS: frozenset[tuple[str, str]] = frozenset()


def layer_breaks(graph: dict[str, set[str]], layers=LAYERS, known=KNOWN_BREAKS) -> list[str]:
    """Every import in `graph` (module -> modules) of a unit of the same or a higher layer
    (not in `known`), as "module -> target (unit layer i -> unit layer j)"; a unit without a
    layer is a break too."""
    layer_of = {unit: i for i, units in enumerate(layers) for unit in units}
    breaks = []
    for module in sorted(graph):
        here = package_of(module)
        if here not in layer_of:
            breaks.append(f"{module}: {here} has no layer")
            continue
        for target in sorted(graph[module]):
            there = package_of(target)
            if there == here or (module, target) in known:
                continue
            if layer_of.get(there, len(layers)) >= layer_of[here]:
                breaks.append(f"{module} -> {target} ({here} layer {layer_of[here]} -> {there} "
                              f"layer {layer_of.get(there, 'none')})")
    return breaks


def test_every_unit_imports_only_lower_layers():
    breaks = layer_breaks(import_graph())
    assert not breaks, "\n".join(breaks)
    units = {package_of(m) for m in import_graph()}
    placed = {u for layer in LAYERS for u in layer}
    assert units <= placed and len(placed) == sum(map(len, LAYERS)), sorted(units - placed)


def test_the_layer_check_fails_on_an_upward_import():
    """The checker itself: a planted import of a higher layer is a break, in a synthetic
    graph and in the real one; an import downwards is not."""
    assert layer_breaks({"sysid.store.files": {"sysid.report.build"}, "sysid.report.build": {"sysid.store.files"}}) == [
        "sysid.store.files -> sysid.report.build (sysid.store layer 1 -> sysid.report layer 13)"]
    assert layer_breaks({"sysid.config.experiment": {"sysid.data.columns"}}) == [
        "sysid.config.experiment -> sysid.data.columns (sysid.config layer 3 -> sysid.data layer 5)"]
    assert layer_breaks({"sysid.dynamics.equations": {"sysid.hybrid.correction"}})  # the same layer
    assert layer_breaks({"sysid.tools": set()}) == ["sysid.tools: sysid.tools has no layer"]
    planted = import_graph()
    planted["sysid.records.columns"] = planted["sysid.records.columns"] | {"sysid.identify.trainer"}
    assert layer_breaks(planted) == ["sysid.records.columns -> sysid.identify.trainer "
                                     "(sysid.records layer 4 -> sysid.identify layer 7)"]


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


def test_no_circle_between_subpackages():
    cycle = _cycle(package_graph())
    assert cycle is None, " -> ".join(cycle)


def test_package_graph_sees_known_edges():
    packages = package_graph()
    assert "sysid.mmg" in packages["sysid.dynamics"] and "sysid.config" in packages["sysid.hybrid"]
    assert "sysid.dynamics" not in packages["sysid.mmg"]


FAST_FREE = ("sysid.identify", "sysid.evaluation", "sysid.runs", "sysid.records")


def test_training_evaluation_and_runs_do_not_load_the_compiled_path():
    graph, now = import_graph(), import_time_graph()
    for module in graph:
        if not module.startswith(FAST_FREE):
            continue
        loaded = {m for m in reached(now, module) if m.startswith("sysid.fast")}
        assert not loaded, f"importing {module} imports {sorted(loaded)}"
        direct = {m for m in graph[module] if m.startswith("sysid.fast")}
        # evaluation imports it inside the function that predicts, when compiled is asked for
        allowed = {"sysid.fast.compiled"} if module == "sysid.evaluation.evaluate" else set()
        assert direct <= allowed, f"{module} imports {sorted(direct - allowed)}"


def test_training_evaluation_and_runs_import_without_the_compiled_path():
    modules = ["sysid.identify.trainer", "sysid.evaluation.evaluate", "sysid.runs.lifecycle", "sysid.runs.rundir"]
    code = (f"import sys; import {', '.join(modules)}; "
            "print(sorted(m for m in sys.modules if m.startswith('sysid.fast')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    assert done.stdout.strip() == "[]"
    assert "sysid.identify.trainer" in import_graph()  # the names above exist


def test_config_imports_no_torch():
    """Through the graph: no module `import sysid.config.*` runs imports torch or pandas; and
    a fresh process that imports the config module (and reads a config) has loaded neither."""
    graph, outside = import_edges()
    now = import_time_graph()
    for module in (m for m in graph if m.startswith("sysid.config")):
        heavy = {m for m in reached(now, module) | {module}
                 if any(outside[m].get(pkg) for pkg in ("torch", "torchdiffeq", "pandas", "numpy"))}
        assert not heavy, f"importing {module} imports torch through {sorted(heavy)}"
    config = ROOT / "configs" / "experiments" / "hybrid_D2.toml"
    code = ("import sys; from sysid.config.experiment import load_experiment; "
            f"load_experiment({str(config)!r}); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'pandas', 'numpy')))")
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    assert done.stdout.strip() == "[]"
    timed = [line.rsplit("|", 1)[-1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")]
    assert "sysid.config.experiment" in timed and "torch" not in timed


def test_the_protocol_loads_the_compiled_path_only_where_it_is_chosen():
    """Importing the protocol or the maneuvers loads no compiled path: the closed loop's
    right-hand side (`sysid.fast.stepper`) and the rule that picks the path (`sysid.fast.payoff`,
    plain Python) at most, the compiler inside the functions that compile."""
    now = import_time_graph()
    for start in ("sysid.protocol.reproduce", "sysid.maneuvers.recorded", "sysid.maneuvers.closed_loop"):
        loaded = {m for m in reached(now, start) if m.startswith("sysid.fast")}
        assert loaded <= {"sysid.fast", "sysid.fast.stepper", "sysid.fast.payoff"}, \
            f"importing {start} imports {sorted(loaded)}"
    assert "sysid.fast.compiled" in import_graph()["sysid.maneuvers.closed_loop"]  # inside compiled_loop


def test_run_directories_are_read_without_torch_or_training_code():
    """A fresh process that imports `RunDir` (as the report, sweeps and tracking do) has
    loaded neither torch nor any of identify, evaluation or hybrid."""
    code = ("import sys; from sysid.runs import RunDir; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'torchdiffeq') "
            "or m.startswith(('sysid.identify', 'sysid.evaluation', 'sysid.hybrid', 'sysid.fast'))))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    assert done.stdout.strip() == "[]"
