"""`OutputTarget` (`sysid.store.target`) on its own: every refusal is one `OutputError` line
naming the output and the path at fault, and what it protects is byte-identical after."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from sysid.errors import OutputError
from sysid.store.files import write_text
from sysid.store.manifest import MANIFEST, write_manifest
from sysid.store.target import OutputKind, OutputTarget, exclusive_lock, real_path

FOREIGN_MANIFEST = json.dumps({"name": "My App", "start_url": "/", "icons": []})


def sealed(directory, kind="run", names=("metrics.csv", "model.pt")):
    """A directory sysid wrote completely: files, then its manifest."""
    for name in names:
        write_text(f"content of {name}", directory / name)
    write_manifest(directory, kind)
    return directory


def user_folder(directory, manifest: str | None = FOREIGN_MANIFEST):
    """A user's folder: a thesis and (by default) a web app's manifest.json."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "thesis.tex").write_text("years of work")
    if manifest is not None:
        (directory / MANIFEST).write_text(manifest)
    return directory


def refused(target_args: dict, *named) -> str:
    with pytest.raises(OutputError) as info:
        OutputTarget.checked(**target_args)
    line = str(info.value)
    assert "\n" not in line
    for name in named:
        assert str(name) in line, f"{name} not named in: {line}"
    return line


# -- inputs ----------------------------------------------------------------------------------
def test_a_file_output_that_is_an_input_under_any_name(tmp_path, monkeypatch):
    data = tmp_path / "in.csv"
    data.write_text("x\n1\n")
    monkeypatch.chdir(tmp_path)
    for spelling in (data, "in.csv", "./in.csv", tmp_path / "sub" / ".." / "in.csv"):
        (tmp_path / "sub").mkdir(exist_ok=True)
        refused(dict(path=spelling, kind="file", inputs=[data]), Path(spelling), data, "an input of this command")
    os.link(data, tmp_path / "hard.csv")  # the same file under another name
    refused(dict(path=tmp_path / "hard.csv", kind="file", inputs=[data]), "hard.csv", "is", data)
    assert data.read_text() == "x\n1\n"


def test_an_output_inside_or_holding_an_input_directory(tmp_path):
    data = tmp_path / "data"
    (data / "turning").mkdir(parents=True)
    (data / "turning" / "a.csv").write_text("t\n0\n")
    refused(dict(path=data / "metrics.csv", kind="file", inputs=[data]), "metrics.csv", "lies inside", data)
    refused(dict(path=data / "turning" / "runs", kind="run", inputs=[data]), "lies inside", data)
    refused(dict(path=tmp_path, kind="run", inputs=[data / "turning" / "a.csv"], overwrite=True),
            tmp_path, "holds", "a.csv")
    OutputTarget.checked(tmp_path / "elsewhere.csv", "file", [data])  # beside it: fine


# -- links -----------------------------------------------------------------------------------
def test_an_output_that_is_a_link_is_refused_whatever_it_points_to(tmp_path):
    thesis = tmp_path / "home" / "thesis.tex"
    thesis.parent.mkdir()
    thesis.write_text("years of work")
    out = tmp_path / "out"
    out.mkdir()
    (out / "model.pt2").symlink_to(thesis)
    (out / "dangling.csv").symlink_to(tmp_path / "nowhere.csv")
    (out / "run").symlink_to(thesis.parent, target_is_directory=True)
    refused(dict(path=out / "model.pt2", kind="file"), "model.pt2", "symbolic link", thesis)
    refused(dict(path=out / "dangling.csv", kind="file"), "dangling.csv", "nowhere.csv")
    with pytest.raises(OutputError, match="run: is a symbolic link"):
        OutputTarget.checked(out / "run", "run", overwrite=True)
    refused(dict(path=out / "run", kind="report"), out / "run", "symbolic link", thesis.parent)
    assert thesis.read_text() == "years of work" and not (tmp_path / "nowhere.csv").exists()


def test_real_path_resolves_every_component_but_the_last(tmp_path):
    (tmp_path / "real").mkdir()
    (tmp_path / "alias").symlink_to(tmp_path / "real", target_is_directory=True)
    (tmp_path / "real" / "link.csv").symlink_to(tmp_path / "x.csv")
    assert real_path(tmp_path / "alias" / "link.csv") == tmp_path.resolve() / "real" / "link.csv"


# -- sealed directories ----------------------------------------------------------------------
def test_nothing_is_written_inside_a_sealed_directory(tmp_path):
    run = sealed(tmp_path / "run")
    before = (run / "metrics.csv").read_bytes()
    refused(dict(path=run / "metrics.csv", kind="file"), run / "metrics.csv", f"lies inside {run}", "run directory")
    refused(dict(path=run / "traces" / "new.csv", kind="file"), "sysid sealed")
    refused(dict(path=run / "sub", kind="run"), "sysid sealed")
    (tmp_path / "alias").symlink_to(run, target_is_directory=True)
    refused(dict(path=tmp_path / "alias" / "metrics.csv", kind="file"), "sysid sealed")  # through a link too
    assert (run / "metrics.csv").read_bytes() == before


def test_a_foreign_manifest_does_not_seal_a_folder(tmp_path):
    site = user_folder(tmp_path / "site")
    assert OutputTarget.checked(site / "forces.csv", "file").path == site / "forces.csv"


def test_a_report_is_added_only_to_the_directory_it_reports_on(tmp_path):
    rep = sealed(tmp_path / "rep", "reproduction", ("comparison.csv",))
    OutputTarget.checked(rep, "report", [rep], adds_to=rep)
    refused(dict(path=rep / "report", kind="report", inputs=[rep], adds_to=rep), "lies inside")
    other = sealed(tmp_path / "other")
    refused(dict(path=rep, kind="report", inputs=[other], adds_to=other), "sysid sealed")


def test_an_existing_report_file_sysid_did_not_write_is_kept(tmp_path):
    folder = tmp_path / "site"
    folder.mkdir()
    (folder / "report.html").write_text("<html><title>My own report</title></html>")
    refused(dict(path=folder, kind="report"), folder / "report.html", "not a report sysid wrote")
    (folder / "report.html").write_text("<html><head><title>sysid accuracy report: run x</title>")
    OutputTarget.checked(folder, "report")


# -- --overwrite -----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["run", "preprocessing", "reproduction"])
def test_overwrite_replaces_only_a_complete_sysid_output_of_the_same_kind(tmp_path, kind):
    site = user_folder(tmp_path / "site")
    refused(dict(path=site, kind=kind, overwrite=True), site, "not written by sysid", "not a sysid manifest")
    plain = user_folder(tmp_path / "plain", manifest=None)
    refused(dict(path=plain, kind=kind, overwrite=True), "no manifest.json")
    other = "preprocessing" if kind == "run" else "run"
    refused(dict(path=sealed(tmp_path / "other", other), kind=kind, overwrite=True), f"a '{other}' output")
    changed = sealed(tmp_path / "changed", kind)
    (changed / "model.pt").write_text("content of model.pX")
    refused(dict(path=changed, kind=kind, overwrite=True), "model.pt does not match its checksum")
    refused(dict(path=sealed(tmp_path / "mine", kind), kind=kind), "already exists; pass --overwrite")
    OutputTarget.checked(tmp_path / "mine", kind, overwrite=True)
    (tmp_path / "empty").mkdir()
    OutputTarget.checked(tmp_path / "empty", kind, overwrite=True)  # nothing there to lose
    assert (site / "thesis.tex").read_text() == "years of work" and (site / MANIFEST).read_text() == FOREIGN_MANIFEST


def test_a_sweep_folder_is_continued_or_replaced_only_when_sysid_sealed_it(tmp_path):
    folder = user_folder(tmp_path / "folder", manifest=None)
    (folder / "sweep.toml").write_text("[sweep]\n")  # a file of the sweep marker's name
    refused(dict(path=folder, kind="sweep"), "--resume to continue")
    refused(dict(path=folder, kind="sweep", overwrite=True), "not written by sysid")
    OutputTarget.checked(folder, "sweep", resume=True)  # the sweep itself then compares its sweep file
    OutputTarget.checked(sealed(tmp_path / "sweep", "sweep", ("sweep.toml", "base.toml")), "sweep", overwrite=True)


def test_a_file_written_beside_the_named_output_is_replaced_only_with_overwrite(tmp_path):
    truth = tmp_path / "raw.truth.csv"
    truth.write_text("my own notes")
    refused(dict(path=truth, kind="file", companion=tmp_path / "raw.csv"), truth, "raw.csv", "--overwrite")
    assert truth.read_text() == "my own notes"
    OutputTarget.checked(truth, "file", overwrite=True, companion=tmp_path / "raw.csv")


def test_an_output_file_that_is_a_directory(tmp_path):
    (tmp_path / "taken").mkdir()
    refused(dict(path=tmp_path / "taken", kind="file"), "taken: is a directory")


# -- one writer at a time --------------------------------------------------------------------
def test_a_second_writer_is_refused_and_the_lock_file_goes_at_the_end(tmp_path):
    first = OutputTarget.checked(tmp_path / "run", OutputKind.RUN)
    with first.lock():
        assert first.lock_path() == tmp_path / ".run.lock"
        assert first.lock_path().read_text().strip() == str(os.getpid())
        second = OutputTarget.checked(tmp_path / "run", OutputKind.RUN, overwrite=True)
        with pytest.raises(OutputError) as info:
            with second.lock():
                pass
        line = str(info.value)
        assert f"{tmp_path / 'run'}: another sysid process (pid {os.getpid()})" in line
        assert str(tmp_path / ".run.lock") in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_the_target_is_checked_again_under_the_lock(tmp_path):
    target = OutputTarget.checked(tmp_path / "run", "run")
    sealed(tmp_path / "run")  # another job finished it between the check and the lock
    with pytest.raises(OutputError, match="already exists"):
        with target.lock():
            pass
    assert not target.lock_path().exists()


def test_a_lock_file_left_by_a_killed_writer_is_taken_over(tmp_path):
    lock = tmp_path / ".run.lock"
    lock.write_text("12345\n")  # its holder was killed: nobody holds the flock
    with exclusive_lock(lock, tmp_path / "run"):
        assert lock.read_text().strip() == str(os.getpid())
    assert not lock.exists()
