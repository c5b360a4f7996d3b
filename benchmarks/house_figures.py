"""The house's figures (issue 35) for one checkout of sysid, read from its source.

    python benchmarks/house_figures.py CHECKOUT [--list]

Prints:
  rooms               units of the layer table: subpackages of sysid, top-level modules of
                      sysid (``sysid/__init__.py`` counted as ``sysid``) and ``preprocessing``
  modules             .py files under sysid/
  largest module      lines of the longest file under sysid/
  largest function    lines (def to last line, decorators left out) of the longest function
                      or method under sysid/
  functions > 60      how many functions or methods under sysid/ are longer than 60 lines
  integrator parses   calls that parse an integrator's name: ``Method.parse(...)``,
                      ``Integrator.of(...)``
  choice comparisons  comparisons (==, !=, in, not in) of a value with a string literal
                      (or a tuple/list/set of them) that is the word of a closed choice
                      (a member of a `sysid.config.choices.Choice` subclass); words that
                      name no choice are not counted
  RunDir imports      what ``from sysid.runs import RunDir`` loads in a fresh process run in
                      the checkout: torch? sysid.identify?

``--list`` prints every long function, parse site and choice comparison with its place.
The checkout's own sysid is imported (PYTHONPATH set to it) for the choice words and the
RunDir check; nothing else runs.
"""
from __future__ import annotations

import argparse
import ast
import json
import subprocess
import sys
from pathlib import Path

LONG = 60


def choice_words(root: Path) -> set[str]:
    """The words of every closed choice in the checkout (`sysid.config.choices`)."""
    code = ("import enum, json, sysid.config.choices as c; "
            "print(json.dumps(sorted({m.value for k in vars(c).values() if isinstance(k, type) "
            "and issubclass(k, c.Choice) and k is not c.Choice for m in k})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root,
                          env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"}, check=True)
    return set(json.loads(done.stdout))


def run_dir_loads(root: Path) -> dict[str, bool]:
    """Whether importing `RunDir` in a fresh process loads torch and sysid.identify."""
    code = ("import sys, json; from sysid.runs import RunDir; "
            "print(json.dumps({'torch': 'torch' in sys.modules, "
            "'sysid.identify': any(m.startswith('sysid.identify') for m in sys.modules)}))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root,
                          env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"}, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _strings(node: ast.AST) -> list[str]:
    """The string literals `node` is, or holds as a tuple/list/set display."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
    return []


def figures(root: Path) -> dict:
    package = root / "sysid"
    files = sorted(package.rglob("*.py"))
    units = {"preprocessing"}
    for path in files:
        parts = path.relative_to(root).with_suffix("").parts
        if len(parts) == 2 and parts[1] == "__init__":
            units.add("sysid")
        elif len(parts) == 2:
            units.add(".".join(parts))
        else:
            units.add(".".join(parts[:2]))
    words = choice_words(root)
    sizes, functions, parses, comparisons = {}, [], [], []
    for path in files:
        text = path.read_text()
        where = str(path.relative_to(root))
        sizes[where] = len(text.splitlines())
        for node in ast.walk(ast.parse(text, where)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                functions.append((node.end_lineno - node.lineno + 1, f"{where}:{node.lineno} {node.name}"))
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and isinstance(node.func.value, ast.Name):
                if (node.func.value.id, node.func.attr) in (("Method", "parse"), ("Integrator", "of")):
                    parses.append(f"{where}:{node.lineno} {node.func.value.id}.{node.func.attr}")
            elif isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                for op, right in zip(node.ops, node.comparators):
                    if not isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn)):
                        continue
                    hit = [w for side in sides for w in _strings(side) if w in words]
                    if hit:
                        comparisons.append(f"{where}:{node.lineno} {sorted(set(hit))}")
                        break
    functions.sort(reverse=True)
    largest_module = max(sizes.items(), key=lambda kv: kv[1])
    return {
        "rooms": len(units), "modules": len(files),
        "largest module": f"{largest_module[1]} ({largest_module[0]})",
        "largest function": f"{functions[0][0]} ({functions[0][1]})",
        "functions > 60": sum(1 for n, _ in functions if n > LONG),
        "integrator parses": len(parses),
        "choice comparisons": len(comparisons),
        "RunDir imports": run_dir_loads(root),
        "_long": [f"{n:4d} {name}" for n, name in functions if n > LONG],
        "_parses": parses, "_comparisons": comparisons,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("checkout", type=Path)
    parser.add_argument("--list", action="store_true", help="list long functions, parse sites, comparisons")
    args = parser.parse_args()
    found = figures(args.checkout.resolve())
    for key, value in found.items():
        if not key.startswith("_"):
            print(f"{key:20s} {value}")
    if args.list:
        for key in ("_long", "_parses", "_comparisons"):
            print(f"\n{key[1:]}:")
            print("\n".join(f"  {line}" for line in found[key]))


if __name__ == "__main__":
    main()
