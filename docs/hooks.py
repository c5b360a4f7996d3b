"""MkDocs hook: pages that hold a marker get text generated from the code at build time.

``<!-- generated: config-reference -->``: every key of the experiment config
(`sysid.config.reference`); ``<!-- generated: cli-reference -->``: every command and option
(`sysid.cli.reference`). Generated, so the docs cannot drift from what the parser and the
commands accept."""
from __future__ import annotations

GENERATORS = {
    "<!-- generated: config-reference -->": "sysid.config.reference",
    "<!-- generated: cli-reference -->": "sysid.cli.reference",
}


def on_page_markdown(markdown, page, config, files):
    import importlib

    for marker, module in GENERATORS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, importlib.import_module(module).markdown())
    return markdown
