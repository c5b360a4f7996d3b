"""The user's units in the report: where [data.columns] reads u in knots and r in deg/s,
the verdict table shows its RMSE in knots and deg/s (files stay SI); SI without them."""
from __future__ import annotations

import math

import pandas as pd
import pytest

from own_logs import OWN_COLUMNS

from sysid.data.columns import parse_columns
from sysid.data.display_units import DisplayUnits
from sysid.evaluation.verdict import BaselineVerdict, ChannelCell
from sysid.report.tables import verdict_table

KNOT = 1852.0 / 3600.0  # m/s


def _verdict() -> BaselineVerdict:
    cells = (ChannelCell("test", 30.0, "u", 0.0185, {"MMG (ship file)": 0.0257}),
             ChannelCell("test", 30.0, "v_m", 0.0090, {"MMG (ship file)": 0.0110}),
             ChannelCell("test", 30.0, "r", 0.0040, {"MMG (ship file)": 0.0050}))
    return BaselineVerdict("hybrid", ("MMG (ship file)",), cells)


def test_own_units_from_the_columns_table():
    table = {c: {"column": column, "unit": unit} if unit else column for c, (column, unit, _) in OWN_COLUMNS.items()}
    units = DisplayUnits.of(parse_columns(table, "own.toml"))
    assert (units.unit("u"), units.unit("v_m"), units.unit("r")) == ("knots", "kn", "deg/s")
    assert units.value("u", KNOT) == pytest.approx(1.0, rel=1e-12)
    assert units.value("r", math.pi) == pytest.approx(180.0, rel=1e-12)
    assert DisplayUnits.of_config({"data": {"columns": table}}) == units
    assert DisplayUnits.of_config({"data": {}}).si and DisplayUnits.of(None).unit("u") == "m/s"


def test_verdict_table_in_knots_and_deg_per_s():
    units = DisplayUnits({"u": ("knots", KNOT), "r": ("deg/s", math.pi / 180.0)})
    table = verdict_table(_verdict(), "hybrid", units)
    rows = {r[3]: r for r in table.rows}      # split, log, horizon, channel, windows, model, baseline, change
    assert rows["u [knots]"][5:7] == [f"{0.0185 / KNOT:.5f}", f"{0.0257 / KNOT:.5f}"] == ["0.03596", "0.04996"]
    assert rows["r [deg/s]"][5:7] == ["0.22918", "0.28648"]
    assert rows["v_m [m/s]"][5:7] == ["0.00900", "0.01100"]  # not mapped: SI
    assert rows["u [knots]"][7] == verdict_table(_verdict(), "hybrid").rows[0][7]  # the change is unit-free
    si = {r[3]: r for r in verdict_table(_verdict(), "hybrid").rows}
    assert si["u [m/s]"][5] == "0.01850"
    assert units.verdict_cells(_verdict()) == ("u at 30 s: 0.03596 against 0.04996 knots; "
                                               "r at 30 s: 0.2292 against 0.2865 deg/s")


def test_run_table_in_the_run_s_units(tmp_path):
    """A run whose config reads u in knots: the report's RMSE table shows u in knots (the
    metrics file stays SI); r and v_m in SI; the same run without [data.columns] in SI."""
    from synthetic_rundir import measured_runs, write_run

    from sysid.report.source import read_run_dir
    from sysid.report.tables import run_table
    from sysid.store.manifest import write_manifest

    runs = {k: v for k, v in measured_runs(0.3).items() if k == "Berthing"}
    out = write_run(tmp_path / "run", "hybrid_D2", runs, horizons=(30,))
    si = run_table(read_run_dir(out), paper=False)
    config = out / "config.toml"
    config.write_text(config.read_text() + '\n[data.columns]\nu = { column = "u_velo [m/s]", unit = "knots" }\n')
    write_manifest(out, "run")
    own = run_table(read_run_dir(out), paper=False)
    assert "(u [knots], v_m [m/s], r [rad/s])" in own.title and "(u [m/s], v_m [m/s], r [rad/s])" in si.title
    for a, b in zip(si.rows, own.rows):
        assert b.cells[0].ours == pytest.approx(a.cells[0].ours / KNOT, rel=1e-12)  # u
        assert (b.cells[1].ours, b.cells[2].ours) == (a.cells[1].ours, a.cells[2].ours)  # v_m, r
    metrics = pd.read_csv(out / "metrics.csv")
    assert metrics["rmse_u"].iloc[0] == pytest.approx(si.rows[0].cells[0].ours, rel=1e-12)


def test_report_says_the_units_its_table_is_in(tmp_path):
    """The report of a run read in knots and evaluated with RK4: the note under the RMSE table
    names the table's units (u in knots), in the HTML and the PDF, not m/s; the run's u cell is
    its SI RMSE in knots; the methods name the run's integrator, not the protocol's Euler."""
    import pypdf
    from synthetic_rundir import measured_runs, write_run

    from sysid.report.build import build_report
    from sysid.store.manifest import write_manifest

    runs = {k: v for k, v in measured_runs(0.3).items() if k == "Berthing"}
    out = write_run(tmp_path / "run", "mmg_lab", runs, horizons=(30,))
    config = out / "config.toml"
    config.write_text(config.read_text() + '\n[evaluation]\nintegrator = "rk4"\n'
                      '\n[data.columns]\nu = { column = "u_velo [m/s]", unit = "knots" }\n')
    write_manifest(out, "run")
    paths = build_report(out, tmp_path / "report")
    html = paths.html.read_text()
    assert "Units: u in knots, v_m in m/s, r in rad/s." in html
    assert "u, v_m in m/s" not in html
    assert "integrated with classical RK4, dt = 1 s" in html and "explicit Euler" not in html
    u_knots = pd.read_csv(out / "metrics.csv")["rmse_u"].iloc[0] / KNOT
    assert f"{u_knots:.5f}" in html
    pdf = "\n".join(p.extract_text() or "" for p in pypdf.PdfReader(str(paths.pdf)).pages)
    assert "u in knots, v_m in m/s, r in rad/s" in " ".join(pdf.split())
    assert "u, v_m [m/s]" not in pdf


def test_methods_of_a_run_without_test_logs_say_so(tmp_path):
    """A run trained without test logs (a sweep's trial): metrics.csv holds its header only,
    and the methods say no test log was evaluated instead of "H =  s" windows of test files;
    the same run with its test metrics names their horizons."""
    from synthetic_rundir import measured_runs, write_run

    from sysid.report.methods import methods_paragraphs
    from sysid.report.source import read_source
    from sysid.store.manifest import write_manifest

    runs = {k: v for k, v in measured_runs(0.3).items() if k == "Berthing"}
    out = write_run(tmp_path / "run", "mmg_lab", runs, horizons=(30,))
    assert "(H = 30 s)" in methods_paragraphs(read_source(out))[0]
    metrics = pd.read_csv(out / "metrics.csv")
    metrics.iloc[:0].to_csv(out / "metrics.csv", index=False)
    write_manifest(out, "run")
    first = methods_paragraphs(read_source(out))[0]
    assert first.startswith("No test log was evaluated") and "H = " not in first
