"""The CLI and config reference pages are committed files, readable in the repository: the
part below each page's marker is what the code generates now (a new option, command or
config key without regenerating the page fails here)."""
from __future__ import annotations

from pathlib import Path

import pytest

from sysid.cli import reference as cli_reference
from sysid.config import reference as config_reference

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("module", [cli_reference, config_reference], ids=["cli", "config"])
def test_reference_page_is_what_the_code_generates(module):
    page = (ROOT / module.PAGE).read_text()
    assert page.count(module.MARKER) == 1
    generated = module.markdown()
    assert page.split(module.MARKER, 1)[1].strip("\n") == generated.strip("\n"), (
        f"{module.PAGE} is out of date: run python -m {module.__name__} --write")
    assert config_reference.generated_page(page, module.MARKER, generated) == page


def test_pages_name_every_command_and_every_config_key():
    cli = (ROOT / cli_reference.PAGE).read_text()
    for command in ("compare", "evaluate", "train", "report", "maneuver", "sweep", "ship check"):
        assert f"## `sysid {command}`" in cli
    config = (ROOT / config_reference.PAGE).read_text()
    for ref in config_reference.config_keys():
        assert f"| `{ref.key}` | {ref.type} |" in config


def test_check_flag_tells_a_drifted_page(tmp_path):
    page = tmp_path / "cli.md"
    page.write_text("# CLI reference\n\n" + cli_reference.MARKER + "\n\nold text\n")
    assert not config_reference.regenerate(page, cli_reference.MARKER, cli_reference.markdown(), write=False)
    assert config_reference.regenerate(page, cli_reference.MARKER, cli_reference.markdown(), write=True) is False
    assert config_reference.regenerate(page, cli_reference.MARKER, cli_reference.markdown(), write=False)
    assert page.read_text().startswith("# CLI reference\n\n" + cli_reference.MARKER + "\n\n")
