"""Bad raw logs: each gets one clear error (file, column, row) or a logged repair.

Uses a small analytic run (no dataset needed): 120 s at 10 Hz, ahead at ~0.5 m/s with a
gentle sinusoidal yaw, wind 2 m/s.
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from preprocessing import synth
from preprocessing.pipeline import Pipeline, PreprocessSettings
from preprocessing.schema import RawLogError
from preprocessing.sensors import SensorLayout
from sysid.store.manifest import verify_manifest

from analytic_runs import analytic_run

LAYOUT = SensorLayout()


@pytest.fixture(scope="module")
def synthetic():
    return synth.synthesise(analytic_run(), LAYOUT, synth.SynthSettings(seed=2))


@pytest.fixture
def raw(synthetic):
    return synthetic.raw.copy()


def run(raw, **settings):
    return Pipeline(LAYOUT, PreprocessSettings(**settings)).run(raw, name="log.csv")


def error_of(raw, **settings) -> str:
    with pytest.raises(RawLogError) as info:
        run(raw, **settings)
    return str(info.value)


def test_clean_log_matches_truth(synthetic, raw):
    out = run(raw)
    s = synth.score(out.segments, synthetic.truth)
    assert s["psi_deg"] < 0.3 and s["u"] < 5e-3 and s["r"] < 1e-3
    assert out.report.repairs == []


def test_missing_column(raw):
    msg = error_of(raw.drop(columns=["anemo_2_dir [rad]"]))
    assert "log.csv" in msg and "anemo_2_dir" in msg and "missing" in msg and "add it" in msg


def test_processed_log_is_named_as_one():
    processed = analytic_run(20.0)
    processed.columns = [f"{c} [{u}]" for c, u in synth.schema.PROCESSED.items()]
    msg = error_of(processed)
    assert "a processed log, not a raw" in msg and "u_velo" in msg


def test_rpm_in_rps_column_names_the_unit_and_the_largest_value(raw):
    raw["n_prop [rps]"] = raw["n_prop [rps]"] * 60.0  # 10 rps logged as 600 rpm
    msg = error_of(raw)
    assert "column n_prop" in msg and "rpm / 60" in msg and "degrees" not in msg
    assert f"{len(raw)} row(s) outside" in msg and "up to 600 " in msg


def test_knots_in_anemometer_speed_beyond_range(raw):
    raw["anemo_1_speed [m/s]"] = 31.0 * 1.943844  # 31 m/s, a gale, logged in knots: 60.3
    msg = error_of(raw)
    assert "anemo_1_speed" in msg and "knots" in msg and "up to 60.2592 " in msg


def test_misnamed_column(raw):
    msg = error_of(raw.rename(columns={"fog_yaw_rate [rad/s]": "fog_yawrate [rad/s]"}))
    assert "fog_yaw_rate" in msg and "misnamed" in msg and "fog_yawrate" in msg


def test_missing_gnss_column(raw):
    msg = error_of(raw.drop(columns=["gnss_aft_y [m]"]))
    assert "gnss_aft_y" in msg and "missing" in msg


def test_wrong_unit_header(raw):
    msg = error_of(raw.rename(columns={"n_prop [rps]": "n_prop [rad/s]"}))   # [rpm] is converted
    assert msg == "log.csv: column n_prop: unit [rad/s], expected [rps]"


def test_degree_header_is_converted_and_logged(synthetic, raw):
    raw["fog_yaw_rate [rad/s]"] = np.degrees(raw["fog_yaw_rate [rad/s]"])
    out = run(raw.rename(columns={"fog_yaw_rate [rad/s]": "fog_yaw_rate [deg/s]"}))
    assert any("fog_yaw_rate" in r and "deg/s" in r for r in out.report.repairs)
    assert synth.score(out.segments, synthetic.truth)["r"] < 1e-3


def test_degrees_in_radian_fog_column(raw):
    raw["fog_yaw_rate [rad/s]"] = np.degrees(raw["fog_yaw_rate [rad/s]"])
    msg = error_of(raw)
    assert "fog_yaw_rate" in msg and "degrees" in msg


def test_gyro_positive_to_port_or_mirrored_frame(raw):
    """A gyro counted positive to port (z up), or antenna x, y in a frame with x east and y
    north, turns the heading against the gyro: both were processed without a word (a 'gyro
    bias' of 1.6 deg/s on the known-truth probe) and now get one line naming the two causes."""
    port = raw.copy()
    port["fog_yaw_rate [rad/s]"] = -port["fog_yaw_rate [rad/s]"]
    mirrored = raw.copy()
    for a in ("fore", "aft"):
        mirrored[[f"gnss_{a}_x [m]", f"gnss_{a}_y [m]"]] = raw[[f"gnss_{a}_y [m]", f"gnss_{a}_x [m]"]].to_numpy()
    for bad in (port, mirrored):
        msg = error_of(bad)
        assert msg.startswith("log.csv: column fog_yaw_rate: the gyro turns against the two-antenna heading")
        assert "negate the column" in msg and "swap the x and y columns" in msg


def test_degrees_in_radian_rudder_column(raw):
    raw["delta_rudder [rad]"] = np.degrees(raw["delta_rudder [rad]"])
    msg = error_of(raw)
    assert "delta_rudder" in msg and "line " in msg and "degrees" in msg


def test_degrees_in_radian_wind_column(raw):
    raw["anemo_1_dir [rad]"] = np.degrees(raw["anemo_1_dir [rad]"])
    assert "anemo_1_dir" in error_of(raw)


def test_text_in_numeric_column(raw):
    raw["n_prop [rps]"] = raw["n_prop [rps]"].astype(object)
    raw.loc[41, "n_prop [rps]"] = "ten"
    msg = error_of(raw)
    assert "n_prop" in msg and "line 43" in msg


def test_time_going_backwards(raw):
    raw.loc[500, "t [s]"] = raw.loc[498, "t [s]"]
    msg = error_of(raw)
    assert "column t" in msg and "line 502" in msg


def test_repeated_time_with_other_values(raw):
    dup = raw.iloc[[300]].copy()
    dup["n_prop [rps]"] = 3.0
    bad = pd.concat([raw.iloc[:301], dup, raw.iloc[301:]], ignore_index=True)
    msg = error_of(bad)
    assert "column t" in msg and "line 303" in msg


def test_exact_duplicate_rows_are_dropped_and_logged(synthetic, raw):
    bad = pd.concat([raw.iloc[:301], raw.iloc[[300, 300]], raw.iloc[301:]], ignore_index=True)
    out = run(bad)
    assert any("duplicate" in r for r in out.report.repairs)
    assert synth.score(out.segments, synthetic.truth)["u"] < 5e-3


def test_empty_time_stamps_are_counted_with_the_fix(raw):
    raw.loc[500:520, "t [s]"] = np.nan   # lines 502-522
    assert error_of(raw) == ("log.csv: column t: line 502: empty time (21 row(s); every row needs its time stamp: "
                             "fill it in, or delete the row)")


def test_clock_time_is_counted_from_the_first_sample(synthetic, raw):
    shifted = raw.copy()
    shifted["t [s]"] = shifted["t [s]"] + 1_700_000_000.0   # Unix seconds of the logger's clock
    out, plain = run(shifted), run(raw)
    assert out.report.repairs == ["column t: starts at 1700000000.0 s, a clock time; counted from the first sample"]
    assert len(out.segments) == len(plain.segments) == 1
    assert out.segments[0]["t"].iloc[0] == 0.0
    pd.testing.assert_frame_equal(out.segments[0], plain.segments[0], rtol=1e-6)


def test_time_in_milliseconds(raw):
    raw["t [s]"] = raw["t [s]"] * 1000.0
    assert "median step" in error_of(raw)


def test_short_nan_burst_interpolated_long_one_splits(synthetic, raw):
    raw.loc[200:204, "fog_yaw_rate [rad/s]"] = np.nan          # 0.5 s
    raw.loc[600:629, "anemo_1_speed [m/s]"] = np.nan           # 3 s
    out = run(raw)
    gaps = {g.channel: g for g in out.report.gaps}
    assert gaps["fog_yaw_rate"].action == "interpolated"
    assert gaps["anemo_1_speed"].action == "split"
    assert len(out.segments) == 2
    s = synth.score(out.segments, synthetic.truth, dropouts=[(60.0, 62.9)])
    assert s["r"] < 1e-3 and s["wind_speed"] < 0.05


def test_every_row_empty(raw):
    raw.iloc[:, :] = np.nan
    assert error_of(raw) == f"log.csv: no data: every one of its {len(raw)} rows is empty (no number in any column)"


def test_all_nan_channel(raw):
    raw["anemo_2_speed [m/s]"] = np.nan
    assert "anemo_2_speed" in error_of(raw)


def test_swapped_antennas_error_and_repair(synthetic, raw):
    cols = ["gnss_fore_x [m]", "gnss_fore_y [m]", "gnss_aft_x [m]", "gnss_aft_y [m]"]
    swapped = raw.copy()
    swapped[cols] = raw[[cols[2], cols[3], cols[0], cols[1]]].to_numpy()
    msg = error_of(swapped)
    assert "swapped" in msg and "gnss_fore" in msg
    out = run(swapped, swapped_antennas="repair")
    assert out.report.swapped_antennas is True
    assert synth.score(out.segments, synthetic.truth)["psi_deg"] < 0.3


def test_antenna_positions_in_feet(raw):
    for column in ("gnss_fore_x [m]", "gnss_fore_y [m]", "gnss_aft_x [m]", "gnss_aft_y [m]"):
        raw[column] = raw[column] / 0.3048
    msg = error_of(raw)
    assert "gnss_fore_x" in msg and "3.28 x the nominal: positions in feet? convert the antenna columns to metres" in msg


def test_baseline_never_matches(raw):
    with pytest.raises(RawLogError, match="gnss_baseline"):
        Pipeline(SensorLayout(gnss_fore=(1.0, 0.0), gnss_aft=(-1.0, 0.0), gnss_baseline=2.0)).run(raw)


def test_cli_failed_file_leaves_no_output(synthetic, tmp_path, capsys):
    from sysid.cli import main
    good = tmp_path / "good.csv"
    bad = tmp_path / "bad.csv"
    synthetic.raw.to_csv(good, index=False)
    broken = synthetic.raw.copy()
    broken.loc[700, "t [s]"] = 0.0
    broken.to_csv(bad, index=False)
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        main(["preprocess", str(good), str(bad), "--ship", "esso_osaka", "-o", str(out), "--jobs", "2"])
    assert info.value.code == 2  # the bad log's fault (bad input), the good one kept
    names = sorted(p.name for p in out.iterdir())
    assert names == ["good.csv", "good.report.json", "manifest.json"]  # complete, sealed
    assert sorted(verify_manifest(out, "preprocessing")["files"]) == ["good.csv", "good.report.json"]
    err = capsys.readouterr().err
    assert "bad.csv" in err and "column t" in err and "line 702" in err
    report = json.loads((out / "good.report.json").read_text())
    assert report["outputs"] == ["good.csv"]
    processed = pd.read_csv(out / "good.csv")
    assert list(processed.columns)[:3] == ["t [s]", "x_position_mid [m]", "u_velo [m/s]"]
    assert len(processed.columns) == 13
    from sysid.data.recordings import read_run                  # loads straight into training/evaluation
    loaded = read_run(out / "good.csv")
    assert len(loaded) == len(processed) and loaded.dt == pytest.approx(1.0)


def test_truncated_file_is_refused(synthetic, tmp_path):
    from preprocessing.schema import read_raw
    path = tmp_path / "cut.csv"
    synthetic.raw.to_csv(path, index=False)
    text = path.read_text()
    lines = text.splitlines()
    cut = "\n".join(lines[:501]) + "\n" + lines[501][: len(lines[501]) // 3]  # header, 500 rows, a third of data row 501 (line 502)
    path.write_text(cut)
    with pytest.raises(RawLogError) as info:
        read_raw(path)
    assert "cut.csv: line 502:" in str(info.value) and "cut off" in str(info.value)
    path.write_text("\n".join(lines[:501]))  # the last row complete, no line end: read as it is
    assert len(read_raw(path)[0]) == 500


def test_cli_bad_inputs_exit_2_and_write_nothing(synthetic, tmp_path, capsys):
    from sysid.cli import main
    logs = tmp_path / "logs"
    logs.mkdir()
    broken = synthetic.raw.copy()
    broken["delta_rudder [rad]"] = np.degrees(broken["delta_rudder [rad]"])
    broken.to_csv(logs / "deg.csv", index=False)
    before = (logs / "deg.csv").read_bytes()
    for args, said in ((["preprocess", str(logs / "deg.csv")], "delta_rudder"),
                       (["preprocess", str(logs)], "is a directory, not a raw log; it holds 1 .csv file(s)"),
                       (["preprocess", str(tmp_path)], "it holds no .csv file")):
        with pytest.raises(SystemExit) as info:
            main([*args, "-o", str(tmp_path / "out")])
        assert info.value.code == 2
        assert said in capsys.readouterr().err
        assert not (tmp_path / "out").exists()
    assert (logs / "deg.csv").read_bytes() == before


def test_cli_internal_failure_exits_1(synthetic, tmp_path, monkeypatch):
    from preprocessing import pipeline
    from sysid.cli import main
    synthetic.raw.to_csv(tmp_path / "good.csv", index=False)

    def broken(self, path, name=None):
        raise RuntimeError("a bug")
    monkeypatch.setattr(pipeline.Pipeline, "run", broken)
    with pytest.raises(SystemExit) as info:
        main(["preprocess", str(tmp_path / "good.csv"), "-o", str(tmp_path / "out")])
    assert info.value.code == 1


def test_cli_synth_raw_writes_truth(tmp_path, capsys):
    from sysid.cli import main
    src = tmp_path / "run.csv"
    run_df = analytic_run(60.0)
    run_df.columns = [f"{c} [{u}]" for c, u in synth.schema.PROCESSED.items()]
    run_df.to_csv(src, index=False)
    raw = tmp_path / "raw.csv"
    main(["synth-raw", str(src), "-o", str(raw), "--seed", "4", "--outliers", "3",
          "--dropout", "20:2", "--latlon"])
    assert "3 outlier(s)" in capsys.readouterr().out
    df = pd.read_csv(raw)
    assert "gnss_aft_lon [deg]" in df.columns and df["gnss_aft_lon [deg]"].isna().sum() == 20
    assert (tmp_path / "raw.truth.csv").is_file()


def test_poor_gnss_fix_rejected(synthetic, raw):
    raw["gnss_fore_fix"] = 4
    raw["gnss_aft_fix"] = 4
    raw.loc[300:304, "gnss_aft_fix"] = 5                          # RTK float for 0.5 s
    out = run(raw)
    assert out.report.fix_rejected == 5
    assert len(out.segments) == 1
    assert synth.score(out.segments, synthetic.truth)["pos"] < 0.02


def test_heading_offset_and_offcentre_antennas():
    layout = SensorLayout(gnss_fore=(1.0, 0.3), gnss_aft=(-1.3, 0.3), gnss_baseline=2.3,
                          heading_offset=0.05, anemometer_1=(0.5, 0.2))
    res = synth.synthesise(analytic_run(), layout, synth.SynthSettings(seed=1))
    s = synth.score(Pipeline(layout).run(res.raw).segments, res.truth)
    assert s["psi_deg"] < 0.3 and s["pos"] < 0.02 and s["wind_speed"] < 0.05


def test_empty_rows_dropped_and_logged(synthetic, raw, tmp_path):
    path = tmp_path / "log.csv"
    raw.to_csv(path, index=False)
    with open(path, "a") as fh:
        fh.write("," * (len(raw.columns) - 1) + "\n" + "," * (len(raw.columns) - 1) + "\n")
    out = Pipeline(LAYOUT).run(path)
    assert any("empty row" in r for r in out.report.repairs)
    assert synth.score(out.segments, synthetic.truth)["u"] < 5e-3


def test_no_gnss_at_all(raw):
    raw[["gnss_fore_x [m]", "gnss_aft_x [m]"]] = np.nan
    assert "no usable GNSS fix" in error_of(raw)


def test_a_blank_line_keeps_the_lines_named_those_of_the_file(synthetic, tmp_path):
    """A blank line inside a raw log (line 101) is an empty row, dropped and said at its line;
    a bad time stamp after it is named at its own line of the file (703), as an editor shows it."""
    from preprocessing.schema import read_raw
    broken = synthetic.raw.copy()
    broken.loc[700, "t [s]"] = 0.0          # data row 700: line 702 of the file as written
    path = tmp_path / "blank.csv"
    broken.to_csv(path, index=False)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:100] + [""] + lines[100:]) + "\n")
    assert path.read_text().splitlines()[702].startswith("0.0,")   # line 703 (1-based)
    with pytest.raises(RawLogError, match=r"blank.csv: column t: line 703: time goes backwards"):
        read_raw(path)
    good = tmp_path / "good.csv"
    synthetic.raw.to_csv(good, index=False)
    lines = good.read_text().splitlines()
    good.write_text("\n".join(lines[:100] + [""] + lines[100:]) + "\n")
    repairs: list[str] = []
    frame, _ = read_raw(good, repairs)
    assert len(frame) == len(synthetic.raw) and "dropped 1 empty row(s), first at line 101" in repairs
