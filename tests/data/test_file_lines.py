"""Every reader names a bad row by the same number: the file's line ("line N", the header is
line 1), so `sysid preprocess` (raw logs) and `read_run` (processed logs) agree for the same
row, and the line an editor opens holds the bad value."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from analytic_runs import analytic_run
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
