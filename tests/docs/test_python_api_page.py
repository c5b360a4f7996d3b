"""The docs' Python API page runs as written: its code blocks, in order, in a folder holding
logs/ and test/ with real FRT-DS-ESSO logs under new names."""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

PAGE = Path(__file__).resolve().parents[2] / "docs" / "python-api.md"
LOGS = {"logs/zigzag_a.csv": "zigzag/zigzag_31-Jul-2020_13_22_52.csv",
        "logs/zigzag_b.csv": "zigzag/zigzag_31-Jul-2020_13_42_53.csv",
        "test/zigzag_c.csv": "zigzag/zigzag_31-Jul-2020_13_29_19.csv"}


def code_blocks(text: str) -> list[str]:
    """The ```python blocks of a Markdown page, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


@pytest.mark.slow
def test_python_api_example_runs(tmp_path, dataset_dir, monkeypatch):
    for new, old in LOGS.items():
        (tmp_path / new).parent.mkdir(exist_ok=True)
        shutil.copy(dataset_dir / old, tmp_path / new)
    monkeypatch.chdir(tmp_path)
    blocks = code_blocks(PAGE.read_text())
    assert len(blocks) >= 2 and "Trainer(" in blocks[0] and "load_model(" in blocks[0]
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), namespace)
    assert (tmp_path / "runs" / "example" / "manifest.json").is_file()
    metrics = namespace["evaluation"].metrics
    assert list(metrics.file) == ["zigzag_c"] and (metrics.rmse_u > 0).all()
    # the trained hybrid predicts the held-back zigzag's surge speed to within 0.1 m/s over 59 s
    assert abs(float(namespace["states"][-1, 1]) - float(namespace["run"].states[59, 1])) < 0.1
