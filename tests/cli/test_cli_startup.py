"""`sysid --help` answers at once: the CLI imports no heavy module before a command needs it."""
from __future__ import annotations

import subprocess
import sys

HEAVY = ("torch", "torchdiffeq", "pandas", "scipy", "matplotlib", "filterpy")


def test_the_cli_imports_no_heavy_module_until_a_command_runs():
    code = ("import sys, sysid.cli\n"
            "from sysid.cli import app\n"
            f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""


def test_help_texts_keep_their_bracketed_units():
    done = subprocess.run([sys.executable, "-m", "sysid", "simulate", "--help"], capture_output=True, text=True,
                          env={"COLUMNS": "200", "PATH": ""})
    assert done.returncode == 0, done.stderr
    for unit in ("[s]", "[Hz]"):
        assert unit in done.stdout
