"""Modules a program may import first import on their own: no circle hidden by the order in
which `sysid/__init__` (now lazy) used to import things."""
from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["sysid.mmg.ship", "sysid.mmg.families", "sysid.mmg.coefficients",
                                    "sysid.config.experiment"])
def test_module_imports_as_the_first_import(module):
    done = subprocess.run([sys.executable, "-c", f"import {module}"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
