"""`RunDir` lives in `sysid.runs.rundir`, the layout and writer in `sysid.runs.layout`; the
writer's names still import from `sysid.runs.rundir` (where they lived before), loaded only
when asked for, so importing `RunDir` loads no torch."""
from __future__ import annotations

import subprocess
import sys


def test_the_writer_names_still_import_from_rundir_and_load_torch_only_then():
    code = ("import sys; from sysid.runs.rundir import RunDir; before = 'torch' in sys.modules; "
            "from sysid.runs.rundir import load_model, write_run; import sysid.runs.layout as layout; "
            "print(before, load_model is layout.load_model and write_run is layout.write_run, RunDir.__module__)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr.strip().splitlines()[-1:]
    assert done.stdout.split() == ["False", "True", "sysid.runs.rundir"]
    missing = subprocess.run([sys.executable, "-c", "from sysid.runs.rundir import no_such_name"],
                             capture_output=True, text=True)
    assert missing.returncode == 1 and "no_such_name" in missing.stderr
