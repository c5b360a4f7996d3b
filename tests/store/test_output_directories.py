"""Staged output directories and their completeness manifests (`sysid.store.staging`,
`sysid.store.manifest`): all-or-nothing, never stale, refused when incomplete or changed."""
from __future__ import annotations

import json
import os

import pytest

from sysid.errors import IncompleteOutputError, OutputError
from sysid.store.files import write_text
from sysid.store.manifest import MANIFEST, verify_manifest
from sysid.store.staging import check_target, staged_directory


def fill(directory, names):
    for name in names:
        write_text(f"content of {name}", directory / name)


def test_complete_directory_moves_into_place_with_a_manifest(tmp_path):
    target = tmp_path / "runs" / "a"
    with staged_directory(target, "run") as staging:
        assert staging.parent == target.parent and staging.name.startswith(".a.staging-")
        fill(staging, ["model.pt", "traces/x_h30.csv"])
        assert not target.exists()
    doc = verify_manifest(target, "run", required=["model.pt"])
    assert sorted(doc["files"]) == ["model.pt", "traces/x_h30.csv"]
    assert sorted(p.name for p in target.parent.iterdir()) == ["a"]  # no staging left


def test_failure_or_interrupt_leaves_nothing(tmp_path):
    target = tmp_path / "out"
    for exc in (ValueError("bad input"), KeyboardInterrupt()):
        with pytest.raises(type(exc)):
            with staged_directory(target, "run") as staging:
                fill(staging, ["model.pt"])
                raise exc
        assert list(tmp_path.iterdir()) == []


def test_existing_target_is_refused_without_overwrite(tmp_path):
    target = tmp_path / "out"
    with staged_directory(target, "run") as staging:
        fill(staging, ["old.csv"])
    with pytest.raises(OutputError, match=r"out: already exists; pass --overwrite"):
        with staged_directory(target, "run") as staging:
            fill(staging, ["new.csv"])
    assert (target / "old.csv").is_file() and not (target / "new.csv").exists()


def test_overwrite_replaces_the_whole_directory(tmp_path):
    target = tmp_path / "out"
    with staged_directory(target, "run") as staging:
        fill(staging, ["old.csv", "seg2.csv"])
    with staged_directory(target, "run", overwrite=True) as staging:
        fill(staging, ["new.csv"])
    assert sorted(p.name for p in target.iterdir()) == [MANIFEST, "new.csv"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_overwrite_refuses_a_directory_sysid_did_not_write(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("years of work")
    with pytest.raises(OutputError, match="not written by sysid"):
        check_target(tmp_path / "mine", overwrite=True)


def test_overwrite_refuses_to_delete_the_jobs_inputs(tmp_path):
    target = tmp_path / "out"
    with staged_directory(target, "preprocessing") as staging:
        fill(staging, ["raw.csv"])
    with pytest.raises(OutputError, match="would delete .*raw.csv"):
        check_target(target, overwrite=True, keep=[target / "raw.csv"])


def test_target_that_is_a_file(tmp_path):
    target = tmp_path / "out"
    assert check_target(target) == target  # a new directory is fine
    target.write_text("a file")
    with pytest.raises(OutputError, match="out: exists and is not a directory"):
        check_target(target, overwrite=True)


def test_parent_that_is_a_file_or_unwritable(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="a file of that name exists"):
        check_target(tmp_path / "file" / "out")
    with pytest.raises(OutputError, match=r"/proc/sysid-out: cannot"):
        with staged_directory("/proc/sysid-out", "run"):
            pass


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_read_only_parent(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputError, match="ro/out: cannot write in .*ro \\(Permission denied\\)"):
            check_target(ro / "out")
    finally:
        ro.chmod(0o755)


@pytest.fixture
def sealed(tmp_path):
    target = tmp_path / "run"
    with staged_directory(target, "run") as staging:
        fill(staging, ["model.pt", "metrics.csv", "traces/a_h30.csv"])
    return target


def test_manifest_missing(sealed):
    (sealed / MANIFEST).unlink()
    with pytest.raises(IncompleteOutputError, match=rf"{sealed}: incomplete run directory: no manifest.json"):
        verify_manifest(sealed, "run")


def test_listed_file_missing(sealed):
    (sealed / "traces" / "a_h30.csv").unlink()
    with pytest.raises(IncompleteOutputError, match=r"traces/a_h30.csv is missing \(listed in manifest.json\)"):
        verify_manifest(sealed, "run")


def test_checksum_mismatch(sealed):
    (sealed / "model.pt").write_text("content of model.pX")  # same size, other bytes
    with pytest.raises(IncompleteOutputError, match=r"run: model.pt does not match its checksum"):
        verify_manifest(sealed, "run")


def test_required_file_and_kind(sealed):
    with pytest.raises(IncompleteOutputError, match="knn.pt is missing"):
        verify_manifest(sealed, "run", required=["knn.pt"])
    with pytest.raises(IncompleteOutputError, match="a 'run' directory, not a reproduction directory"):
        verify_manifest(sealed, "reproduction")


def test_corrupt_manifest(sealed):
    (sealed / MANIFEST).write_text("{not json")
    with pytest.raises(IncompleteOutputError, match="manifest.json: corrupt manifest"):
        verify_manifest(sealed)
    (sealed / MANIFEST).write_text(json.dumps({"files": []}))
    with pytest.raises(IncompleteOutputError, match="not a sysid manifest"):
        verify_manifest(sealed)


def test_files_added_after_the_manifest_are_not_checked(sealed):
    write_text("a report written later, and again", sealed / "report.html")
    assert "report.html" not in verify_manifest(sealed, "run")["files"]
