"""A sweep of two configurations on a user's own logs, on one machine (`--workers 1`): no
paper data set anywhere (SYSID_DATA names an empty folder), started from a project folder
that holds a folder named ``sysid`` which is not sysid, logs in knots and deg/s mapped by
``[data.columns]``, validated on ``[data] validation`` logs; both trials complete and each
was validated on the user's validation log (summary.json, its SHA-256 that of the file)."""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import tomllib

import pandas as pd
import pytest

from own_sweep import SYSID, no_paper_data, own_sweep_project, validation_files

pytestmark = pytest.mark.slow


def test_a_sweep_on_own_logs_with_no_paper_data_from_a_folder_holding_sysid(tmp_path, dataset_dir):
    pytest.importorskip("ray.tune")
    project = tmp_path / "project"
    sweep = own_sweep_project(project, dataset_dir)
    env = no_paper_data(dict(os.environ), tmp_path / "nowhere")
    out = tmp_path / "out"
    proc = subprocess.run([SYSID, "sweep", sweep.name, "-o", str(out), "--workers", "1"], cwd=project, env=env,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "2/2 trials complete" in proc.stdout
    results = pd.read_csv(out / "results.csv")
    assert sorted(results["training.learning_rate"]) == [1e-3, 3e-3] and (results.status == "complete").all()
    check = project / "my logs" / "harbour_check.csv"
    for run in sorted((out / "trials").glob("*/seed0")):
        assert validation_files(run) == ["harbour_check.csv"]
        shipped = json.loads((run / "summary.json").read_text())["data"]["validation"][0]["sha256"]
        assert shipped == hashlib.sha256(check.read_bytes()).hexdigest()
        # written in a trial's scratch folder, it names its logs relative to where it lives now
        named = tomllib.loads((run / "config.toml").read_text())["data"]["validation"]
        assert not os.path.isabs(named[0])
        assert [os.path.realpath(run / p) for p in named] == [os.path.realpath(check)]
    assert results.val_loss_multistep.notna().all() and (results.val_loss_multistep > 0).all()
