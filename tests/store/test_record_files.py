"""One record name per kind of directory (`sysid.store.target.RECORD_FILES`): a run's
summary.json, a reproduction's reproduction.json, a sweep's sweep.json, a comparison's
comparison.json, a maneuvers directory's maneuvers.json. Directories written before hold
theirs as summary.json and still read."""
from __future__ import annotations

import json

from sysid.runs.reproduction import Reproduction
from sysid.store.target import LEGACY_RECORD, RECORD_FILES, OutputKind, record_file


def test_every_kind_has_its_own_record_name():
    names = list(RECORD_FILES.values())
    assert len(set(names)) == len(names)
    assert RECORD_FILES[OutputKind.RUN] == "summary.json"
    assert [n for n in names if n == LEGACY_RECORD] == ["summary.json"]   # only a run keeps the old name


def test_the_record_is_found_under_its_name_or_the_old_one(tmp_path):
    assert record_file(tmp_path, OutputKind.SWEEP) == tmp_path / "sweep.json"        # neither: the new name
    (tmp_path / "summary.json").write_text("{}")
    assert record_file(tmp_path, OutputKind.SWEEP) == tmp_path / "summary.json"      # written before
    (tmp_path / "sweep.json").write_text("{}")
    assert record_file(tmp_path, OutputKind.SWEEP) == tmp_path / "sweep.json"        # its own name wins


def test_a_reproduction_record_reads_under_either_name(tmp_path):
    """As the report reads it (`sysid.report.source`): the record of a reproduction written
    before (summary.json) and after (reproduction.json)."""
    doc = {"seconds": 987.6, "runs": ["mmg_paper", "hybrid_D1"], "protocol": ["mmg_paper", "hybrid_D1", "nn_D1"]}
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "summary.json").write_text(json.dumps(doc))
    old = Reproduction.read(record_file(tmp_path / "old", OutputKind.REPRODUCTION))
    assert old.seconds == 987.6 and old.runs == ("mmg_paper", "hybrid_D1") and len(old.protocol) == 3
    (tmp_path / "new").mkdir()
    (tmp_path / "new" / "reproduction.json").write_text(json.dumps({**doc, "seconds": 12.5}))
    assert Reproduction.read(record_file(tmp_path / "new", OutputKind.REPRODUCTION)).seconds == 12.5
