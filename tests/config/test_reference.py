"""The config reference and the ship-file template cover every key the parsers know, and
nothing else."""
from __future__ import annotations

import dataclasses

from sysid.config import experiment
from sysid.config.reference import KEYS, SECTIONS, config_keys, markdown
from sysid.config.templates import SENSOR_KEYS, SHIP_KEYS, STANDARD_MODELS
from sysid.mmg.ship import _SENSOR_KEYS, active_parameters

DATA_SPELLINGS = {("data", k) for k in ("files", "train", "validation", "test", "columns")}


def test_every_config_key_is_documented_and_no_entry_is_left_over():
    typed = {(section.name, f.name) for section in dataclasses.fields(experiment.Experiment)
             if section.name != "source" for f in dataclasses.fields(getattr(experiment.Experiment(), section.name))}
    assert typed <= set(KEYS), f"undocumented: {sorted(typed - set(KEYS))}"
    # the one exception: [data] is documented in both spellings while the own-logs keys land
    # (files, or train / validation / test / columns); any other entry must be a key
    stale = set(KEYS) - typed
    assert stale <= DATA_SPELLINGS and len(stale) in (0, 1, 4), f"stale: {sorted(stale)}"
    assert {s for s, _ in typed} == set(SECTIONS)
    assert all(doc.meaning.strip() for doc in KEYS.values())


def test_reference_defaults_are_what_the_parser_gives_a_config_that_names_nothing():
    minimal = experiment.parse_experiment({"experiment": {"model": "hybrid"}})
    for ref in config_keys():
        if (ref.section, ref.key) == ("identify", "start_states"):
            continue  # "" resolves to the solver's default; the meaning says so
        assert getattr(getattr(minimal, ref.section), ref.key) == ref.default, (ref.section, ref.key)


def test_markdown_has_one_row_per_key():
    text = markdown()
    for ref in config_keys():
        assert f"| `{ref.key}` | {ref.type} | `{ref.default_toml}` |" in text
    assert text.count("\n| `") == len(config_keys())


def test_ship_template_describes_every_key_of_the_standard_families():
    needed = set(active_parameters(STANDARD_MODELS))
    assert needed == set(SHIP_KEYS), f"missing: {sorted(needed - set(SHIP_KEYS))}"
    assert set(SENSOR_KEYS) == set(_SENSOR_KEYS)
