"""A folder of seed runs (``runs/NAME/seed0``, ... of ``sysid reproduce --seeds N``) given where
one run is read is named as such, with what to give instead, not called an incomplete run."""
from __future__ import annotations

import pytest

from sysid.store.manifest import seed_folder, write_manifest


@pytest.fixture
def seeds(tmp_path):
    group = tmp_path / "hybrid_D2"
    for k in (0, 1, 10):
        (group / f"seed{k}").mkdir(parents=True)
        (group / f"seed{k}" / "summary.json").write_text("{}")
        write_manifest(group / f"seed{k}", "run")
    return group


def test_a_seed_folder_is_named_with_its_seeds_in_order(seeds, tmp_path):
    assert seed_folder(seeds) == (f"{seeds}: a folder of 3 seed runs (seed0, seed1, seed10), not one run: give one "
                                  f"seed ({seeds / 'seed0'}); sysid compare and sysid maneuver take the folder, its "
                                  "seeds as members of one model")
    assert seed_folder(seeds / "seed0") is None  # a run
    assert seed_folder(tmp_path / "nothing") is None


@pytest.mark.parametrize("command", [["evaluate"], ["report"], ["export", "--portable"]])
def test_commands_reading_one_run_refuse_the_folder_in_one_line(seeds, tmp_path, capsys, command):
    from sysid.cli import main

    out = tmp_path / ("out.csv" if command[0] == "evaluate" else "out.pt2" if command[0] == "export" else "out")
    with pytest.raises(SystemExit) as info:
        main([command[0], str(seeds), "-o", str(out), *command[1:]])
    assert info.value.code == 2 and not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {seed_folder(seeds)}"]
