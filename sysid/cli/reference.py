"""The CLI reference, generated from the commands themselves (their usage, help texts and
options), so the docs never describe an option the command does not take."""
from __future__ import annotations

import typer.main

from sysid.cli.app import EPILOG, app


def _cell(text: str) -> str:
    return " ".join(text.replace("|", "\\|").split())


def _command_markdown(command, ctx, path: str) -> list[str]:
    lines = [f"## `{path}`", "", "```", command.get_usage(ctx), "```", ""]
    lines += [(command.help or "").strip(), ""]
    rows = [p.get_help_record(ctx) for p in command.params]
    rows = [r for r in rows if r]
    if rows:
        lines += ["| argument or option | meaning |", "|---|---|"]
        lines += [f"| `{_cell(opts)}` | {_cell(text)} |" for opts, text in rows]
        lines.append("")
    return lines


def markdown() -> str:
    """Every command of `sysid`, with its usage, help and options, as Markdown."""
    root = typer.main.get_command(app)
    # a fixed width: the page is the same whatever terminal generates it
    root_ctx = root.context_class(root, info_name="sysid", terminal_width=100, max_content_width=100)
    lines = [_cell(EPILOG), "", "## `sysid`", "", "```", root.get_usage(root_ctx), "```", "",
             "| option | meaning |", "|---|---|"]
    lines += [f"| `{_cell(o)}` | {_cell(t)} |" for o, t in filter(None, (p.get_help_record(root_ctx)
                                                                         for p in root.params))]
    lines.append("")

    def walk(group, ctx, prefix):
        for name in sorted(group.commands):
            command = group.commands[name]
            sub = command.context_class(command, info_name=name, parent=ctx)
            if getattr(command, "commands", None):
                walk(command, sub, f"{prefix} {name}")
            else:
                lines.extend(_command_markdown(command, sub, f"{prefix} {name}"))

    walk(root, root_ctx, "sysid")
    return "\n".join(lines)


MARKER = "<!-- generated: cli-reference (python -m sysid.cli.reference --write); edit above this line -->"
PAGE = "docs/reference/cli.md"   # relative to the repository's root


def main(argv=None) -> int:
    """``python -m sysid.cli.reference [--write | --check]``: print the reference, write it
    into ``docs/reference/cli.md`` below its marker, or exit 1 when that page differs."""
    from sysid.config.reference import page_command

    return page_command(argv, PAGE, MARKER, markdown)


if __name__ == "__main__":
    raise SystemExit(main())
