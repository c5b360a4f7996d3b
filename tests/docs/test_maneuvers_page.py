"""The docs' standard-maneuvers page runs as written: its Python block on the bundled KVLCC2,
with the numbers it prints being a real turn and a real zig-zag."""
from __future__ import annotations

import re
from pathlib import Path

PAGE = Path(__file__).resolve().parents[2] / "docs" / "maneuvers.md"


def test_maneuvers_page_example_runs(monkeypatch):
    monkeypatch.setenv("SYSID_COMPILE", "0")
    blocks = re.findall(r"^```python\n(.*?)^```", PAGE.read_text(), flags=re.S | re.M)
    assert len(blocks) == 1
    namespace: dict = {}
    exec(compile(blocks[0], str(PAGE), "exec"), namespace)
    turn = namespace["turn"]
    assert turn.maneuver.name == "turning_35_starboard" and turn.gate_off_share is None
    assert 2.5 * 7.0 < turn.indices.tactical_diameter_m < 4.0 * 7.0  # KVLCC2: about 3 L
    assert 0.0 < namespace["zigzag"][0].indices.first_overshoot_deg < 10.0
    assert namespace["sources"]["rps"] == "straight running of the model"
