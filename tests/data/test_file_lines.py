"""Every reader names a bad row by the same number: the file's line ("line N", the header is
line 1), so `sysid preprocess` (raw logs) and `read_run` (processed logs) agree for the same
row, and the line an editor opens holds the bad value."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analytic_runs import analytic_run
from preprocessing import synth
from preprocessing.schema import RawLogError, read_raw
from preprocessing.sensors import SensorLayout
from preprocessing.synth import SynthSettings, synthesise
from sysid.data.recordings import read_run
from sysid.errors import DataError

ZIGZAG = "zigzag/zigzag_31-Jul-2020_13_14_21.csv"


def _line(path, number: int) -> str:
    return path.read_text().splitlines()[number - 1]


def test_raw_and_processed_logs_name_the_same_line(tmp_path, dataset_dir):
    raw = synthesise(analytic_run(), SensorLayout(), SynthSettings(seed=2)).raw.copy()
    raw.loc[500, "t [s]"] = raw.loc[498, "t [s]"]   # pandas index 500 goes back in time
    raw_path = tmp_path / "raw.csv"
    raw.to_csv(raw_path, index=False)
    with pytest.raises(RawLogError, match=r"raw.csv: column t: line 502: time goes backwards"):
        read_raw(raw_path)
    assert float(_line(raw_path, 502).split(",")[0]) == raw.loc[498, "t [s]"]

    processed = pd.read_csv(dataset_dir / ZIGZAG).dropna()
    processed.loc[500, "t [s]"] = processed.loc[499, "t [s]"]  # the same pandas index repeats a time
    path = tmp_path / "processed.csv"
    processed.to_csv(path, index=False)
    with pytest.raises(DataError, match=r"processed.csv: column 't \[s\]' \(channel t\) is not strictly increasing "
                                        r"at line 502 "):
        read_run(path, warn=None)
    assert float(_line(path, 502).split(",")[0]) == float(_line(path, 501).split(",")[0])


def test_an_empty_cell_is_named_at_its_line(tmp_path, dataset_dir):
    processed = pd.read_csv(dataset_dir / ZIGZAG).dropna()
    processed.loc[120, "u_velo [m/s]"] = np.nan
    path = tmp_path / "hole.csv"
    processed.to_csv(path, index=False)
    with pytest.raises(DataError, match=r"\(channel u\) is empty, NaN or inf at line 122 \(1 bad rows\)"):
        read_run(path, warn=None)
    assert _line(path, 122).split(",")[2] == ""


def test_blank_lines_before_a_bad_value_do_not_shift_its_line(tmp_path):
    """A processed log written from a synthetic run, then three blank lines (one empty, one of
    spaces, one a tab) put in by hand before a text cell and a repeated time: the
    messages name the lines a text editor shows for them, counted here from the file's text."""
    run = analytic_run(60.0).iloc[::10].reset_index(drop=True)   # 61 rows at 1 Hz
    header = ",".join(f"{c} [{u}]" for c, u in synth.schema.PROCESSED.items())
    rows = [",".join(f"{v:.9g}" for v in run.loc[i, list(synth.schema.PROCESSED)]) for i in range(len(run))]
    cells = rows[40].split(",")
    rows[40] = ",".join(cells[:1] + ["oops"] + cells[2:])   # column x of data row 40
    lines = [header] + rows[:10] + [""] + rows[10:20] + ["   "] + rows[20:30] + ["\t"] + rows[30:]
    path = tmp_path / "blanks.csv"
    path.write_text("\n".join(lines) + "\n")
    bad = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if "oops" in text)
    assert bad == 1 + 40 + 3 + 1   # header, 40 data rows, 3 blank lines: the 45th line of the file
    with pytest.raises(DataError, match=rf"column 'x_position_mid \[m\]' \(channel x\) holds 'oops' at line {bad}; "):
        read_run(path, warn=None)

    rows[40] = ",".join(rows[39].split(",")[:1] + rows[41].split(",")[1:])   # data row 40 repeats row 39's time
    lines = [""] + [header] + rows[:10] + ["", ""] + rows[10:]   # blank lines before the header too
    path.write_text("\n".join(lines) + "\n")
    repeated = [n for n, text in enumerate(path.read_text().splitlines(), 1)
                if text.split(",")[0] == rows[39].split(",")[0]]
    assert repeated == [1 + 1 + 40 + 2, 1 + 1 + 41 + 2]   # a blank line, the header, two blank lines
    with pytest.raises(DataError, match=rf"\(channel t\) is not strictly increasing at line {repeated[1]} "):
        read_run(path, warn=None)
