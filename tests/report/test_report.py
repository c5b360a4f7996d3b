"""Accuracy reports: built from synthetic run and reproduction directories (no real data),
checked for parseable self-contained HTML, table values equal to metrics.csv, and a
page-numbered PDF holding the same numbers."""
from __future__ import annotations

import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from sysid.errors import CheckpointError, IncompleteOutputError
from sysid.store.manifest import write_manifest
from sysid.report import build_report
from sysid.report.tables import format_rmse

from synthetic_rundir import measured_runs, write_reproduction, write_run

pypdf = pytest.importorskip("pypdf")

STRUCTURE_TAGS = {"html", "body", "main", "section", "table", "thead", "tbody", "tr", "td", "th",
                  "figure", "figcaption", "svg", "nav", "ol", "ul", "style"}


class ReportParser(HTMLParser):
    """Collects every link-like attribute, tag balance, and the 'ours' values per RMSE table."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.links: list[str] = []
        self.depth: dict[str, int] = {}
        self.tables: dict[str, list[str]] = {}
        self._table_id = None
        self._pending_id = None
        self._in_ours = False
        self.ids: list[str] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag in STRUCTURE_TAGS:
            self.depth[tag] = self.depth.get(tag, 0) + 1
        for name, value in attrs.items():
            if name in ("src", "href", "xlink:href", "data", "action", "poster") and value is not None:
                self.links.append(value)
        if tag == "h3" and attrs.get("id", "").startswith("table_"):
            self._pending_id = attrs["id"]
        if tag == "table" and "rmse" in (attrs.get("class") or ""):
            self._table_id = self._pending_id
            self.tables[self._table_id] = []
        if tag == "span" and attrs.get("class") == "ours":
            self._in_ours = True

    def handle_startendtag(self, tag, attrs):
        for name, value in attrs:
            if name in ("src", "href", "xlink:href") and value is not None:
                self.links.append(value)

    def handle_endtag(self, tag):
        if tag in STRUCTURE_TAGS:
            self.depth[tag] = self.depth.get(tag, 0) - 1
        if tag == "table":
            self._table_id = None
        if tag == "span":
            self._in_ours = False

    def handle_data(self, data):
        if self._in_ours and self._table_id:
            self.tables[self._table_id].append(data.strip())


def _parse(path: Path) -> ReportParser:
    text = path.read_text()
    parser = ReportParser()
    parser.feed(text)
    parser.close()
    assert all(v == 0 for v in parser.depth.values()), f"unbalanced tags: {parser.depth}"
    external = [link for link in parser.links if not (link.startswith("#") or link.startswith("data:"))]
    assert not external, f"external references: {external[:5]}"
    assert not re.search(r"url\((?!['\"]?(#|data:))", text), "CSS url() to an external resource"
    assert "<link" not in text and "<script" not in text and "<img" not in text.replace("<img src=\"data:", "")
    return parser


def _metrics_values(run_dir: Path, horizon: int | None = None) -> list[str]:
    frame = pd.read_csv(run_dir / "metrics.csv")
    if horizon is not None:
        frame = frame[frame["horizon_s"] == horizon]
    return [format_rmse(v) for col in ("rmse_u", "rmse_v", "rmse_r") for v in frame[col]]


def _pdf_text(path: Path) -> tuple[list[str], int]:
    reader = pypdf.PdfReader(str(path))
    return [page.extract_text() or "" for page in reader.pages], len(reader.pages)


def _check_pdf(path: Path, values: list[str]) -> None:
    pages, n = _pdf_text(path)
    assert n >= 3
    for i, text in enumerate(pages, 1):
        assert f"page {i} of {n}" in text, f"page {i} has no page number"
    full = "\n".join(pages)
    missing = [v for v in values if v not in full]
    assert not missing, f"table values missing from the PDF text: {missing[:5]}"


@pytest.fixture(scope="module")
def small_runs():
    return measured_runs(scale=0.4)


@pytest.fixture(scope="module")
def reproduction(tmp_path_factory) -> Path:
    return write_reproduction(tmp_path_factory.mktemp("repro"), scale=0.5)


@pytest.fixture(scope="module")
def reproduction_report(reproduction, tmp_path_factory):
    out = tmp_path_factory.mktemp("repro_report")
    return build_report(reproduction, out)


@pytest.mark.slow
def test_reproduction_html_tables_equal_metrics(reproduction, reproduction_report):
    paths = reproduction_report
    assert not [n for n in paths.notes if "failed" in n], paths.notes
    parser = _parse(paths.html)
    assert set(parser.tables) == {"table_30s", "table_100s"}
    for horizon in (30, 100):
        ours = parser.tables[f"table_{horizon}s"]
        expected = set()
        for run_dir in (reproduction / "runs").iterdir():
            values = _metrics_values(run_dir, horizon)
            expected |= set(values)
            missing = [v for v in values if v not in ours]
            assert not missing, f"{run_dir.name} {horizon} s: {missing[:5]} not in the table"
        assert set(ours) - {"-"} <= expected, "a table value that is in no metrics.csv"
    html = paths.html.read_text()
    assert html.count("<svg") == paths.n_figures >= 15
    for word in ("Summary", "Methods", "Configuration digest", "Software (report)", "kNN distance",
                 "Trajectories", "Forces by module", "Training and early-stopping loss", "0.0069"):
        assert word in html, word


@pytest.mark.slow
def test_reproduction_pdf_numbered_with_table_values(reproduction, reproduction_report):
    values = [v for d in (reproduction / "runs").iterdir() for v in _metrics_values(d)]
    _check_pdf(reproduction_report.pdf, values)
    assert reproduction_report.n_pages == len(pypdf.PdfReader(str(reproduction_report.pdf)).pages)


@pytest.mark.slow
def test_figures_drawn_in_workers_give_the_same_report(reproduction, reproduction_report, tmp_path):
    """The HTML's figures drawn in a worker process beside this one's PDF pages: the HTML equal
    to the one drawn here to the byte (but its "built" minute), the PDF's text page by page."""
    paths = build_report(reproduction, tmp_path, workers=2)
    built = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC")
    assert built.sub("", paths.html.read_text()) == built.sub("", reproduction_report.html.read_text())
    assert (paths.n_figures, paths.n_pages, paths.notes) == (reproduction_report.n_figures,
                                                             reproduction_report.n_pages, reproduction_report.notes)
    ours, theirs = _pdf_text(paths.pdf)[0], _pdf_text(reproduction_report.pdf)[0]
    assert [built.sub("", t) for t in ours] == [built.sub("", t) for t in theirs]


@pytest.mark.slow
def test_single_run_report(tmp_path, small_runs):
    runs = small_runs
    run_dir = write_run(tmp_path / "hybrid_D2", "hybrid_D2", runs)
    # a held-out file outside the paper's scenarios: empty scenario, its own trace
    metrics = pd.read_csv(run_dir / "metrics.csv")
    held = metrics[metrics["scenario"] == "Berthing"].assign(scenario="", file="heldout_file",
                                                              rmse_u=0.0123456, rmse_v=0.0234567)
    pd.concat([metrics, held]).to_csv(run_dir / "metrics.csv", index=False)
    for h in (30, 100):
        stem = runs["Berthing"].name
        shutil.copy(run_dir / "traces" / f"{stem}_h{h}.csv", run_dir / "traces" / f"heldout_file_h{h}.csv")
    write_manifest(run_dir, "run")  # sealed again after the edit
    paths = build_report(run_dir, tmp_path / "report")
    assert "heldout_file" in paths.html.read_text() and "0.01235" in paths.html.read_text()
    assert not [n for n in paths.notes if "failed" in n], paths.notes
    parser = _parse(paths.html)
    assert list(parser.tables) == ["table_run"]
    values = _metrics_values(run_dir)
    assert sorted(parser.tables["table_run"]) == sorted(values)
    _check_pdf(paths.pdf, values)


def test_mmg_only_run_degrades_gracefully(tmp_path, small_runs):
    runs = dict(list(small_runs.items())[:2])
    run_dir = write_run(tmp_path / "mmg_lab", "mmg_lab", runs, horizons=(30,))
    paths = build_report(run_dir, tmp_path / "report")
    assert paths.html.is_file() and paths.pdf.is_file()
    assert any("Loss curves" in n for n in paths.notes)
    assert not [n for n in paths.notes if "failed" in n], paths.notes
    _parse(paths.html)


def test_missing_and_corrupt_inputs_name_the_file(tmp_path, reproduction):
    with pytest.raises(CheckpointError, match="no such directory"):
        build_report(tmp_path / "absent", tmp_path / "out")
    broken = tmp_path / "broken"
    shutil.copytree(reproduction / "runs" / "nn_D1", broken)
    (broken / "metrics.csv").write_text("scenario,file\nBerthing,x\n")
    with pytest.raises(IncompleteOutputError, match=r"broken: metrics.csv does not match its checksum"):
        build_report(broken, tmp_path / "out")
    write_manifest(broken, "run")  # sealed as it is: the reader still checks the columns
    with pytest.raises(CheckpointError, match=r"broken/metrics.csv: missing column"):
        build_report(broken, tmp_path / "out")
    (broken / "summary.json").write_text("{not json")
    write_manifest(broken, "run")
    with pytest.raises(CheckpointError, match=r"broken/summary.json: not valid JSON"):
        build_report(broken, tmp_path / "out")
    assert not (tmp_path / "out" / "report.html").exists()


@pytest.mark.slow
def test_cli_report(tmp_path, small_runs, capsys):
    from sysid.cli import main
    run_dir = write_run(tmp_path / "mmg_paper", "mmg_paper", dict(list(small_runs.items())[:1]), horizons=(30,))
    main(["report", str(run_dir), "-o", str(tmp_path / "r"), "--quiet"])
    assert (tmp_path / "r" / "report.html").is_file() and (tmp_path / "r" / "report.pdf").is_file()
    assert "pages" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:
        main(["report", str(tmp_path / "nope"), "-o", str(tmp_path / "r2")])
    assert exit_info.value.code == 2
    assert "nope: no such directory" in capsys.readouterr().err


def test_preprocessing_quality_report(tmp_path):
    import json
    out = tmp_path / "processed"
    out.mkdir()
    for i in range(3):
        report = {"file": f"raw/run_{i}.csv", "settings": {"output_rate": 1.0}, "repairs": [],
                  "gaps": [{"channel": "gnss", "t_start": 12.0, "t_end": 12.5, "duration_s": 0.5,
                            "action": "interpolated"},
                           {"channel": "gnss", "t_start": 40.0, "t_end": 44.0, "duration_s": 4.0, "action": "split"}],
                  "segments": [{"t_start": 0.0, "t_end": 39.9, "samples": 400},
                               {"t_start": 44.1, "t_end": 90.0 + i, "samples": 460}],
                  "dropped_segments": [], "rows": 900, "missing_rows": 3,
                  "baseline": {"rejected": 1, "rejected_t": [20.0]},
                  "heading_gate": {"rejected": 1, "rejected_t": [30.0]}, "fix_rejected": 0,
                  "gaps_interpolated": 1, "gaps_split": 1}
        (out / f"run_{i}.report.json").write_text(json.dumps(report))
    paths = build_report(out, tmp_path / "report")
    assert paths.n_figures == 1 and not paths.notes
    html = paths.html.read_text()
    _parse(paths.html)
    assert "run_2" in html and "Preprocessing quality" in html
    pages, n = _pdf_text(paths.pdf)
    assert all(f"page {i} of {n}" in p for i, p in enumerate(pages, 1))


def test_figures_cover_every_test_log_of_a_users_run(tmp_path, small_runs):
    """A run on the user's own test logs (none of them a paper scenario): the per-log figures
    (time series, trajectories, forces, kNN distance) are drawn for every test log, not only
    the first."""
    import copy

    picked = list(small_runs.values())[:2]
    runs = {}
    for name, run in zip(("harbour_a", "harbour_b"), picked):
        mine = copy.copy(run)
        mine.name, mine.path = name, Path(f"{name}.csv")
        runs[name] = mine
    run_dir = write_run(tmp_path / "hybrid_D2", "hybrid_D2", runs)
    paths = build_report(run_dir, tmp_path / "report")
    captions = re.findall(r"<figcaption>(.*?)</figcaption>", paths.html.read_text(), flags=re.S)
    for name in runs:
        assert sum(name in c for c in captions) >= 2, (name, captions)
    assert not [n for n in paths.notes if "failed" in n], paths.notes
