"""Logs checked against their own GNSS track (`sysid.data.consistency`), on the real logs:
every FRT-DS-ESSO log passes; the same logs with a wrong unit, a flipped sign, swapped
channels or time in ms are found, with the factor of the fault; `sysid train` on a log in
knots beside one with r flipped stops with one line each (exit 2)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from sysid.data.consistency import (CORRELATION_MARGINAL, FACTOR_MARGINAL, Verdict, check_track,
                                    scale_factor)
from sysid.data.recordings import read_runs
from tests.support.tiny_experiment import one_epoch_config

KNOT = 1852.0 / 3600.0  # m/s
HEADERS = {"t": "t [s]", "x": "x_position_mid [m]", "y": "y_position_mid [m]", "psi": "psi_hat [rad]",
           "u": "u_velo [m/s]", "v": "vm_velo [m/s]", "r": "r_angvelo [rad/s]"}
RANDOM = "random/random_31-Jul-2020_12_29_58.csv"
TURN = "turning/turn_14-Sep-2020_13_39_32.csv"


def _channels(path) -> dict[str, np.ndarray]:
    frame = pd.read_csv(path).dropna()
    return {k: frame[h].to_numpy(float) for k, h in HEADERS.items()}


def _check(path, **changed):
    c = {**_channels(path), **changed}
    return check_track(path, c["t"], c["x"], c["y"], c["psi"], c["u"], c["v"], c["r"])


def test_scale_factor_of_a_known_line_with_outliers():
    rng = np.random.default_rng(0)
    track = rng.normal(0.0, 1.0, 2000)
    log = 1.944 * track
    spoiled = track.copy()
    spoiled[::50] += 30.0  # GNSS jumps: 2 % of the samples
    k, corr, kept = scale_factor(log, spoiled)
    assert k == pytest.approx(1.944, rel=1e-9)
    assert corr == pytest.approx(1.0, abs=1e-12) and kept == 1960


def test_every_real_log_agrees_with_its_track(dataset_dir):
    files = sorted(dataset_dir.rglob("*.csv"))
    assert len(files) == 39
    seen = {"u": [], "v": [], "r": []}
    for path in files:
        found = _check(path)
        assert found.checked, path
        for c in found.channels:
            assert c.verdict in (Verdict.CONSISTENT, Verdict.UNCHECKED), (path, c)
            if c.verdict is Verdict.CONSISTENT:
                seen[c.channel].append(c.factor)
                assert c.correlation >= CORRELATION_MARGINAL
    # the measured spread the bounds stand well outside (docs: Input formats)
    assert 0.98 < min(seen["u"]) and max(seen["u"]) < 1.01 and len(seen["u"]) == 39
    assert 0.97 < min(seen["r"]) and max(seen["r"]) < 1.02 and len(seen["r"]) == 39
    assert 1.0 < min(seen["v"]) and max(seen["v"]) < 1.32 < FACTOR_MARGINAL["v"] and len(seen["v"]) == 38


@pytest.mark.parametrize("case, channel, factor, hint", [
    ("u in knots", "u", 1.0 / KNOT, "knots under an m/s name?"),
    ("u in km/h", "u", 3.6, "km/h under an m/s name?"),
    ("u flipped", "u", -1.0, "a flipped sign (astern positive)?"),
    ("v flipped", "v", -1.0, "a flipped sign (positive to port)?"),
    ("r flipped", "r", -1.0, "a flipped sign (positive to port)?"),
    ("r in deg/s", "r", 180.0 / math.pi, "deg/s under a rad/s name?"),
    ("psi in deg", "psi", 180.0 / math.pi, "deg under a rad name?"),
    ("t in ms", "t", 1000.0, "ms under an s name?"),
])
def test_a_fault_is_found_with_its_factor(dataset_dir, case, channel, factor, hint):
    for name in (RANDOM, TURN):
        path = dataset_dir / name
        c = _channels(path)
        found = _check(path, **{channel: c[channel] * factor})
        bad = found.worst(Verdict.MISMATCH)
        assert [b.channel for b in bad] == [channel], (case, found)
        truth = _check(path)  # the channel's own factor on the clean log
        own = {x.channel: x.factor for x in truth.channels}
        expected = factor * own[channel] if channel in "uvr" else factor / own["r"] if channel == "psi" else factor
        assert bad[0].factor == pytest.approx(expected, rel=0.03 if channel == "t" else 1e-3 if channel == "psi" else 1e-6)
        assert bad[0].hint == hint
        line = found.lines(Verdict.MISMATCH)[0]
        assert line.startswith(f"{path}: {channel}") and hint in line


def test_swapped_u_and_v_and_a_heading_counted_to_port(dataset_dir):
    path = dataset_dir / RANDOM
    c = _channels(path)
    swapped = _check(path, u=c["v"], v=c["u"]).worst(Verdict.MISMATCH)
    assert [b.channel for b in swapped] == ["uv"] and "swapped" in swapped[0].hint
    port = _check(path, psi=-c["psi"], r=-c["r"])
    assert [b.channel for b in port.worst(Verdict.MISMATCH)] in (["u", "v"], ["u"], ["v"])
    flipped = _check(path, psi=-c["psi"]).worst(Verdict.MISMATCH)
    assert [b.channel for b in flipped] == ["psi"] and "anticlockwise" in flipped[0].hint


def test_a_log_without_a_track_is_said_once_and_read(tmp_path, dataset_dir):
    said = []
    paths = []
    for i in range(2):
        frame = pd.read_csv(dataset_dir / RANDOM).dropna()
        frame[HEADERS["x"]] = 0.0
        frame[HEADERS["y"]] = 0.0
        paths.append(tmp_path / f"still{i}.csv")
        frame.to_csv(paths[-1], index=False)
    runs = read_runs(paths, warn=said.append)
    assert len(runs) == 2 and not runs[0].track.checked
    assert said == [f"{paths[0]} and 1 more log(s): not checked against the GNSS track "
                    "(x, y constant: no track to check u, v and r against)"]


def _spoiled(tmp_path, dataset_dir):
    knots = pd.read_csv(dataset_dir / RANDOM)
    knots[HEADERS["u"]] /= KNOT
    flipped = pd.read_csv(dataset_dir / TURN)
    flipped[HEADERS["r"]] *= -1.0
    paths = tmp_path / "knots.csv", tmp_path / "r_flipped.csv"
    knots.to_csv(paths[0], index=False)
    flipped.to_csv(paths[1], index=False)
    return paths


def test_training_on_a_log_in_knots_beside_one_with_r_flipped_stops(tmp_path, dataset_dir, capsys):
    from sysid.cli import main
    paths = _spoiled(tmp_path, dataset_dir)
    config = one_epoch_config(tmp_path / "bad.toml", paths)
    with pytest.raises(SystemExit) as stop:
        main(["train", str(config), "-o", str(tmp_path / "run")])
    assert stop.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith(f"error: {paths[0]}: u is 1.9")
    assert "x the track's speed" in lines[0] and "knots under an m/s name?" in lines[0]
    assert lines[1].startswith(f"{paths[1]}: r is -0.98") and "a flipped sign" in lines[1]
    assert not (tmp_path / "run").exists()


def test_logs_check_prints_the_table(tmp_path, dataset_dir, capsys):
    from sysid.cli import main
    _spoiled(tmp_path, dataset_dir)
    with pytest.raises(SystemExit) as stop:
        main(["logs", "check", str(tmp_path)])
    assert stop.value.code == 2
    out = capsys.readouterr().out.splitlines()
    rows = {tuple(line.split()[:2]): line.split() for line in out[1:-1]}
    assert rows[("knots.csv", "u")][2:5] == ["1.933", "0.999", "mismatch"]
    assert rows[("r_flipped.csv", "r")][4] == "mismatch" and float(rows[("r_flipped.csv", "r")][2]) < -0.98
    assert rows[("knots.csv", "r")][4] == "ok"
    assert out[-1] == "logs check: 2 log(s), 2 clear mismatch(es), 0 marginal, 0 unreadable, 0 without a track"


def test_preprocess_output_is_checked(tmp_path, dataset_dir):
    """`sysid preprocess` checks each processed log it wrote: a clear mismatch names the raw
    log and the output (nothing is moved into place); a consistent output passes."""
    from sysid.cli.preprocess_commands import _check_tracks
    from sysid.errors import DataError
    knots, _ = _spoiled(tmp_path, dataset_dir)
    good = dataset_dir / TURN
    _check_tracks([{"ok": True, "file": "raw/good.csv", "outputs": [str(good), str(tmp_path / "good.report.json")]}])
    with pytest.raises(DataError) as bad:
        _check_tracks([{"ok": True, "file": "raw/run3.csv", "outputs": [str(knots)]},
                       {"ok": False, "file": "raw/broken.csv", "error": "raw/broken.csv: no GNSS"}])
    assert str(bad.value).startswith("raw/run3.csv: its processed log knots.csv: u is 1.93 x the track's speed")
    assert "knots under an m/s name?" in str(bad.value) and "\n" not in str(bad.value)
