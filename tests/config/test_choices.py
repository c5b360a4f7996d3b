"""The closed choices as enums: read from the words of the TOML files, written back as the
same words (configs, JSON summaries), one clear line for a word that is not a choice.

Truth: the config files themselves (the words they hold) and the enum members' values."""
from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

import pytest

from sysid.config.choices import DType, GateSpace, Method, ModelKind, Search, Solver, Stage, StartStates
from sysid.config.experiment import load_experiment, parse_experiment
from sysid.errors import ConfigError

CONFIGS = sorted((Path(__file__).resolve().parents[2] / "configs" / "experiments").glob("*.toml"))
CHOICE_KEYS = {("experiment", "model"): ModelKind, ("training", "dtype"): DType, ("gate", "space"): GateSpace,
               ("identify", "stage"): Stage, ("identify", "solver"): Solver,
               ("identify", "start_states"): StartStates, ("evaluation", "integrator"): Method}


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_choices_are_enums_written_as_the_files_words(path):
    written = tomllib.loads(path.read_text())
    exp = load_experiment(path)
    resolved = tomllib.loads(exp.to_toml())
    for (section, key), kind in CHOICE_KEYS.items():
        value = getattr(getattr(exp, section), key)
        assert type(value) is kind, (section, key, value)
        if key in written.get(section, {}):  # the file's word, read and written back
            assert resolved[section][key] == written[section][key] == value.value
        assert json.loads(json.dumps({"v": value}))["v"] == value.value  # summary.json form
    assert parse_experiment(resolved, str(path)) == exp  # the written config reads back the same
    assert exp.to_table() == resolved  # the typed document is what a TOML reader makes of the text
    assert all(type(v) in (str, int, float, bool, list, dict) for t in exp.to_table().values() for v in t.values())


def test_python_callers_may_name_choices():
    exp = parse_experiment({"experiment": {"model": "mmg"}}).replace(
        gate={"space": "inputs"}, identify={"solver": "levenberg_marquardt", "start_states": "estimated"})
    assert exp.experiment.model is ModelKind.MMG and exp.gate.space is GateSpace.INPUTS
    assert exp.identify.solver is Solver.LEVENBERG_MARQUARDT and exp.identify.start_states is StartStates.ESTIMATED
    assert not exp.needs_training  # an MMG with nothing to identify
    with pytest.raises(ValueError, match="space = 'outputs': choose one of features, inputs"):
        exp.replace(gate={"space": "outputs"})


@pytest.mark.parametrize("section, key, word, choices", [
    ("training", "dtype", "float16", "float32, float64"),
    ("identify", "stage", "after", "before, joint"),
    ("gate", "space", "weights", "features, inputs"),
    ("training", "validation", "maneuvers", "blocks, files"),
    ("evaluation", "integrator", "rk4_3/8", "euler, rk4"),  # the 3/8 rule is offered in Python only
])
def test_a_word_that_is_not_a_choice_is_one_line(section, key, word, choices):
    doc = {"experiment": {"model": "hybrid"}, section: {key: word}}
    with pytest.raises(ConfigError) as err:
        parse_experiment(doc, "cfg.toml")
    assert str(err.value) == f"cfg.toml: [{section}] {key} = {word!r}: choose one of {choices}"
    doc[section][key] = 3
    with pytest.raises(ConfigError, match=re.escape(f"[{section}] {key}: expected a string")):
        parse_experiment(doc, "cfg.toml")


def test_integrator_rules_and_what_is_offered():
    assert [m.value for m in Method] == ["euler", "rk4", "rk4_3/8"]
    assert Method.offered() == (Method.EULER, Method.RK4) and Method.listing() == "euler, rk4"
    assert Method.parse("rk4_3/8") is Method.RK4_38
    with pytest.raises(ValueError, match=r"^--integrator 'rk4_3/8': choose one of euler, rk4$"):
        Method.parse("rk4_3/8", "--integrator", offered_only=True)
    assert StartStates.ESTIMATED.other is StartStates.RECORDED and StartStates.RECORDED.other is StartStates.ESTIMATED
    assert [s.value for s in Search] == ["grid", "random", "optuna"]
