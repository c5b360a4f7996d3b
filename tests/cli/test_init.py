"""``sysid init DIR [--ship NAME]``: a project of one's own that loads as written, from any
working directory, and never overwrites a file."""
from __future__ import annotations

import tomllib

import pytest

from cli_harness import assert_refused, in_process
from sysid.config.experiment import load_experiment
from sysid.config.reference import config_keys
from sysid.mmg.ship import active_parameters, load_ship
from sysid.mmg.ship_check import check_ship
from sysid.store.manifest import write_manifest


def test_init_writes_a_project_that_loads_from_another_working_directory(tmp_path, monkeypatch, capsys):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(tmp_path)
    out = in_process(capsys, "init", "tanker", "--ship", "my_tanker")
    assert out.code == 0, out.err
    project = tmp_path / "tanker"
    assert sorted(p.name for p in project.iterdir()) == ["NEXT_STEPS.md", "experiment.toml", "logs", "my_tanker.toml",
                                                         "test"]
    assert "sysid ship check tanker/my_tanker.toml" in out.out  # the next steps, with the user's paths
    assert (project / "NEXT_STEPS.md").read_text() in out.out

    monkeypatch.chdir(elsewhere)  # paths in the config resolve against the config, not the cwd
    exp = load_experiment(project / "experiment.toml")
    assert exp.experiment.ship == str(project / "my_tanker.toml")
    assert exp.data.train == (str(project / "logs" / "*.csv"),)
    assert exp.experiment.model == "hybrid" and exp.experiment.name == "tanker"

    # every key of the typed config is in the file, written or (two) commented out
    doc = tomllib.loads((project / "experiment.toml").read_text())
    text = (project / "experiment.toml").read_text()
    for ref in config_keys():
        present = ref.key in doc.get(ref.section, {})
        commented = f"# {ref.key} = " in text or f"# [{ref.section}.{ref.key}]" in text
        assert present or commented, f"[{ref.section}] {ref.key} missing"
        assert ref.meaning and ref.meaning.split()[0] in text

    # one definition of good: the horizons are written once, and the validation loss judges them
    assert text.count("\nhorizons = ") == 1 and exp.evaluation.horizons == (30.0, 100.0)
    assert exp.training.objective_s == 0
    from sysid.identify.trainer import objective_horizons
    assert objective_horizons(exp) == exp.evaluation.horizons

    ship = load_ship(project / "my_tanker.toml")  # the template validates as a ship file
    assert ship.name == "my_tanker" and dict(ship.models) == {"hull": "standard", "propeller": "standard",
                                                              "rudder": "standard"}
    assert set(ship.parameters) == set(active_parameters(ship.models))
    kvlcc2 = load_ship("kvlcc2_l7")  # its values are the bundled KVLCC2's, said so in the file
    assert dict(ship.parameters) == dict(kvlcc2.parameters) and ship.sensors == kvlcc2.sensors
    # `sysid maneuver`'s defaults are there too (the README's own-ship path runs it with no --speed)
    assert dict(ship.maneuvering) == dict(kvlcc2.maneuvering) and "approach_speed" in ship.maneuvering
    ship_text = (project / "my_tanker.toml").read_text()
    assert "KVLCC2" in ship_text.splitlines()[1]
    for line in ship_text.splitlines():  # every value line has its comment (inline or above)
        if " = " in line and not line.startswith("#") and not line.startswith(("name", "description")):
            assert "#" in line or previous.startswith("#"), line
        previous = line
    assert check_ship(ship).text()


def test_init_refuses_an_existing_file_and_writes_nothing(tmp_path, capsys):
    project = tmp_path / "p"
    project.mkdir()
    (project / "experiment.toml").write_text("mine\n")
    out = in_process(capsys, "init", project)
    assert_refused(out, 2, str(project / "experiment.toml"), "never overwrites")
    assert (project / "experiment.toml").read_text() == "mine\n"
    assert sorted(p.name for p in project.iterdir()) == ["experiment.toml"]


def test_init_refuses_a_link_and_a_sealed_run(tmp_path, capsys):
    project = tmp_path / "p"
    project.mkdir()
    (tmp_path / "mine.toml").write_text("mine\n")
    (project / "my_ship.toml").symlink_to(tmp_path / "mine.toml")
    assert_refused(in_process(capsys, "init", project), 2, str(project / "my_ship.toml"))
    assert (tmp_path / "mine.toml").read_text() == "mine\n"
    run = tmp_path / "run"
    run.mkdir()
    write_manifest(run, "run")  # a directory sysid sealed: nothing else is written into it
    out = in_process(capsys, "init", run / "inside")
    assert out.code == 2 and not (run / "inside").exists(), out.err


@pytest.mark.parametrize("name", ["../escape", "my ship", ""])
def test_init_refuses_a_ship_name_that_is_no_file_name(tmp_path, capsys, name):
    out = in_process(capsys, "init", tmp_path / "p", "--ship", name)
    assert_refused(out, 2, "--ship")
    assert not (tmp_path / "p").exists()
