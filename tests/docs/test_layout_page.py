"""The package layout page (docs/layout.md) names every module of `sysid` and
`preprocessing`: by its dotted name, or by its bare name in the row of its package
(``| `sysid.report/` | ... `palette` ... |``); and it names none that does not exist."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "layout.md"


def modules() -> list[list[str]]:
    """Every module file of the two packages as its name's parts (packages' __init__ left out)."""
    found = []
    for package in ("sysid", "preprocessing"):
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] != "__init__":
                found.append(parts)
    return found


def unnamed(text: str, tree: list[list[str]]) -> list[str]:
    """The modules of `tree` that the layout page `text` does not name."""
    named = set(re.findall(r"`([\w.]+)`", text))
    in_row = {}
    for row in (line for line in text.splitlines() if line.startswith("| `")):
        first = re.fullmatch(r"`([\w.]+)/`", row.split("|")[1].strip())
        if first:
            in_row[first.group(1)] = set(re.findall(r"`(\w+)`", row))
    return [".".join(parts) for parts in tree
            if ".".join(parts) not in named and parts[-1] not in in_row.get(".".join(parts[:-1]), ())]


def test_layout_names_every_module():
    missing = unnamed(PAGE.read_text(), modules())
    assert not missing, f"docs/layout.md does not name {missing}"


def test_layout_names_only_modules_that_exist():
    """A dotted name on the page is a module, a package, or a name inside a module file."""
    files = {".".join(p) for p in modules()}
    packages = {".".join(p[:i]) for p in modules() for i in range(1, len(p))}
    stale = sorted(n for n in set(re.findall(r"`((?:sysid|preprocessing)\.[\w.]+?)/?`", PAGE.read_text()))
                   if n not in files | packages and n.rsplit(".", 1)[0] not in files)
    assert not stale, f"docs/layout.md names {stale}, which do not exist"


def test_the_check_sees_a_module_left_out():
    tree = [["sysid", "runs", "rundir"], ["sysid", "report", "palette"], ["preprocessing", "gnss"]]
    page = "| `sysid.runs.rundir` | ... |\n| `sysid.report/` | `palette` |\n| `preprocessing/` | `gnss` |\n"
    assert unnamed(page, tree) == []
    assert unnamed(page.replace("`palette`", "palette"), tree) == ["sysid.report.palette"]
    assert unnamed(page.replace("sysid.runs.rundir", "sysid.runs.layout"), tree) == ["sysid.runs.rundir"]
