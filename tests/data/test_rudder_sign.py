"""The rudder's sign read from a log's yaw response (`sysid.data.rudder_sign`, in the track
check of `sysid.data.consistency`), against known truth: the FRT-DS-ESSO logs follow sysid's
convention (positive rudder turns to starboard); the same logs with delta negated are found,
straight-running and berthing logs give no claim either way, and a flipped r is named as r's
own fault, not the rudder's. `sysid train`, `sysid logs check` and `sysid preprocess` say it
in one line naming the file, the column and the fix."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sysid.config.column_map import parse_columns
from sysid.data.consistency import Verdict, check_rudder
from sysid.data.recordings import log_track, read_run, read_runs
from sysid.data.rudder_sign import REVERSED_CORRELATION, RudderSign, rudder_response
from sysid.errors import DataError
from tests.support.tiny_experiment import one_epoch_config

T, U, R, DELTA = "t [s]", "u_velo [m/s]", "r_angvelo [rad/s]", "delta_rudder [rad]"
ZIGZAG = "zigzag/zigzag_31-Jul-2020_13_04_24.csv"   # the weakest zig-zag relation of the dataset
BERTHING = "berthing/berthing_12-Nov-2020_13_37_05.csv"  # the most rudder of the berthing logs: 16 s ahead


def _signals(path) -> tuple[np.ndarray, ...]:
    frame = pd.read_csv(path).dropna()
    return tuple(frame[h].to_numpy(float) for h in (T, U, R, DELTA))


def test_every_real_log_turns_to_starboard_and_negated_to_port(dataset_dir):
    files = sorted(dataset_dir.rglob("*.csv"))
    assert len(files) == 39
    read, correlations = [], []
    for path in files:
        t, u, r, delta = _signals(path)
        found, negated = rudder_response(t, u, r, delta), rudder_response(t, u, r, -delta)
        if found.sign is RudderSign.NOT_READ:  # too little rudder ahead: no claim either way
            assert negated.sign is RudderSign.NOT_READ and found.excited_s < 30.0, path
            continue
        read.append(path.parent.name)
        correlations.append(found.correlation)
        assert found.sign is RudderSign.STARBOARD, (path, found)
        assert negated.sign is RudderSign.PORT_CLEAR and negated.correlation == pytest.approx(-found.correlation)
    # every turning and zig-zag log is read; no berthing log is
    assert read.count("turning") == 15 and read.count("zigzag") == 8 and "berthing" not in read
    assert len(read) == 29
    assert min(correlations) > REVERSED_CORRELATION + 0.05 and max(correlations) < 1.0


def test_berthing_and_straight_running_give_no_claim(dataset_dir):
    t, u, r, delta = _signals(dataset_dir / BERTHING)
    for sign in (1.0, -1.0):
        found = check_rudder(t, u, r, sign * delta)
        assert found.verdict is Verdict.UNCHECKED and "too little" in found.hint
    # straight running: a zig-zag log's own motion with the rudder held at 1 deg
    t, u, r, _ = _signals(dataset_dir / ZIGZAG)
    assert rudder_response(t, u, r, np.full_like(t, np.radians(1.0))).sign is RudderSign.NOT_READ


def _negated(tmp_path, dataset_dir, name: str, column: str, relative: str = ZIGZAG):
    frame = pd.read_csv(dataset_dir / relative)
    frame[column] *= -1.0
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def test_a_reversed_rudder_stops_reading_in_one_line(tmp_path, dataset_dir):
    path = _negated(tmp_path, dataset_dir, "flipped.csv", DELTA)
    with pytest.raises(DataError) as info:
        read_run(path, warn=None)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: delta_rudder: the rudder sign looks reversed: positive rudder turns the "
                              "ship to port here: partial correlation -0.45 of dr/dt with the rudder over 92 s of rudder going ahead")
    assert "negate column 'delta_rudder [rad]' in the log" in message
    assert read_run(dataset_dir / ZIGZAG, warn=None).track.channels[-1].verdict is Verdict.CONSISTENT


def test_the_users_column_is_named(tmp_path, dataset_dir):
    frame = pd.read_csv(dataset_dir / ZIGZAG).dropna()
    frame["rudder"] = -np.degrees(frame.pop(DELTA))
    path = tmp_path / "own.csv"
    frame.to_csv(path, index=False)
    columns = parse_columns({"delta_rudder": {"column": "rudder", "unit": "deg"}}, "own.toml")
    with pytest.raises(DataError, match=r"negate column 'rudder' \[deg\] in the log"):
        read_run(path, columns=columns, warn=None)
    frame["rudder"] *= -1.0
    frame.to_csv(path, index=False)
    assert read_run(path, columns=columns, warn=None).track.channels[-1].factor == 1.0


def test_a_flipped_yaw_rate_is_named_as_r_not_as_the_rudder(tmp_path, dataset_dir):
    path = _negated(tmp_path, dataset_dir, "r_flipped.csv", R)
    found = log_track(path)
    bad = found.worst(Verdict.MISMATCH)
    assert [c.channel for c in bad] == ["r"] and bad[0].factor < -0.95 and "a flipped sign" in bad[0].hint
    assert "delta_rudder" not in [c.channel for c in found.channels]


def test_train_logs_check_and_preprocess_say_it(tmp_path, dataset_dir, capsys):
    from sysid.cli import main
    from sysid.cli.preprocess_commands import _check_tracks
    path = _negated(tmp_path, dataset_dir, "flipped.csv", DELTA)
    config = one_epoch_config(tmp_path / "bad.toml", [path])
    with pytest.raises(SystemExit) as stop:
        main(["train", str(config), "-o", str(tmp_path / "run")])
    assert stop.value.code == 2 and not (tmp_path / "run").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {path}: delta_rudder: the rudder sign looks reversed")

    with pytest.raises(SystemExit) as stop:
        main(["logs", "check", str(path)])
    assert stop.value.code == 2
    out = capsys.readouterr().out.splitlines()
    rows = {tuple(line.split()[:2]): line.split() for line in out[1:-1]}
    assert rows[("flipped.csv", "delta_rudder")][2:5] == ["-1", "-0.447", "mismatch"]
    assert out[-1] == "logs check: 1 log(s), 1 clear mismatch(es), 0 marginal, 0 unreadable, 0 without a track"

    with pytest.raises(DataError) as bad:
        _check_tracks([{"ok": True, "file": "raw/zz.csv", "outputs": [str(path)]}])
    assert str(bad.value).startswith("raw/zz.csv: its processed log flipped.csv: delta_rudder: the rudder sign "
                                     "looks reversed")


def test_a_yaw_rate_that_does_not_answer_the_rudder_gives_no_claim():
    """The analytic run's r and delta are in phase sines (r is not driven by delta): whichever
    sign delta has, no claim."""
    from analytic_runs import analytic_run
    run = analytic_run(600.0)
    t, u, r, delta = (run[c].to_numpy() for c in ("t", "u_velo", "r_angvelo", "delta_rudder"))
    for sign in (1.0, -1.0):
        found = rudder_response(t, u, r, sign * delta)
        assert found.excited_s > 300.0 and found.sign is RudderSign.UNCLEAR, found
        assert check_rudder(t, u, r, sign * delta).verdict is Verdict.UNCHECKED


def test_logs_simulated_by_the_mmg_turn_to_starboard():
    """The convention's own truth: 1-Hz logs simulated by sysid's MMG (a perturbed Esso Osaka,
    measurement noise on u, v, r) read as turning to starboard, and as reversed with delta
    negated."""
    from synthetic_rundir import measured_runs
    for scenario, run in measured_runs().items():
        t, u, r, delta = run.t, run.states[:, 1], run.states[:, 5], run.inputs[:, 1]
        found = rudder_response(t, u, r, delta)
        assert found.sign is RudderSign.STARBOARD and found.correlation > 0.4, (scenario, found)
        assert rudder_response(t, u, r, -delta).sign is RudderSign.PORT_CLEAR, scenario


def _course_keeping(seeds: int, minutes: float = 20.0, dt: float = 0.1) -> tuple[np.ndarray, ...]:
    """`seeds` 10-Hz logs of a first-order Nomoto ship (T dr/dt + r = K delta + w; K = 0.47
    1/s, T = 8.6 s: K' = T' = 2 at 0.7 m/s and L = 3 m, a model ship) held on course by a PD
    autopilot (delta = -2 psi - 8 r, within +-15 deg) against a yaw disturbance w [rad/s],
    coloured noise of 20 s correlation time (wind gusts): the rudder answers the yaw, not the
    other way round, the case where a rudder read by correlation could turn over. (t, u, r,
    delta), each (seeds, N)."""
    K, T_yaw, u0 = 0.47, 8.6, 0.7
    rng = np.random.default_rng(7)
    n = int(minutes * 60 / dt)
    r, psi, w = np.zeros(seeds), np.zeros(seeds), np.zeros(seeds)
    rs, deltas = np.empty((seeds, n)), np.empty((seeds, n))
    for i in range(n):
        w += -w / 20.0 * dt + 0.02 * np.sqrt(2 * dt / 20.0) * rng.standard_normal(seeds)
        delta = np.clip(-2.0 * psi - 8.0 * r, -np.radians(15), np.radians(15))
        r = r + (K * delta - r + w) / T_yaw * dt
        psi = psi + r * dt
        rs[:, i], deltas[:, i] = r, delta
    rs += 0.0005 * rng.standard_normal(rs.shape)   # the gyro's noise [rad/s]
    t = np.tile(np.arange(n) * dt, (seeds, 1))
    return t, np.full((seeds, n), u0), rs, deltas


def test_an_autopilot_against_gusts_reads_the_right_way_round():
    """Closed-loop course keeping in gusts (`_course_keeping`), rudder the right way round:
    every log reads STARBOARD (its rudder excited for minutes, not just 30 s), never reversed;
    +0.24 to +0.31 here, the weakest relations seen: a reversed one of that size is only
    marginal (PORT_WEAK) and an error needs -0.3 or below."""
    t, u, r, delta = _course_keeping(4)
    found = [rudder_response(*(a[k] for a in (t, u, r, delta))) for k in range(4)]
    assert all(f.sign is RudderSign.STARBOARD and f.excited_s > 120.0 for f in found), found
    assert min(f.correlation for f in found) > REVERSED_CORRELATION - 0.1
    negated = [rudder_response(t[k], u[k], r[k], -delta[k]) for k in range(4)]
    assert all(f.sign in (RudderSign.PORT_WEAK, RudderSign.PORT_CLEAR) for f in negated), negated



def _nomoto_log(path, tug: bool, seconds: float = 600.0, dt: float = 0.1):
    """A 1-Hz processed log of a first-order Nomoto ship (T dr/dt + r = K delta + m; K = 0.47
    1/s, T = 8.6 s; u = 0.7 m/s +- 0.1 over 120 s, v_m +- 0.03 m/s over 90 s) whose rudder is logged in sysid's convention (K > 0: the
    truth). `tug`: a tug's yaw moment m [rad/s], coloured noise of 30 s correlation time,
    that the helmsman answers with rudder against it (delta = -0.6 m / K, within +-20 deg),
    so the tug, not the rudder, turns the ship (net 0.4 m); else no tug and a zig-zag rudder
    of +-15 deg every 40 s. The track (x, y, psi) is integrated from u and r at 10 Hz: the
    log agrees with its GNSS track. Returns `path`."""
    from processed_runs import write_processed_csv
    K, T_yaw, u0 = 0.47, 8.6, 0.7
    rng = np.random.default_rng(11)
    n = int(round(seconds / dt))
    m, r, psi, x, y = 0.0, 0.0, 0.0, 0.0, 0.0
    rows = np.empty((n, 7))   # x, y, psi, r, delta, u, v_m
    for i in range(n):
        u, v = u0 + 0.1 * np.sin(2 * np.pi * i * dt / 120.0), 0.03 * np.sin(2 * np.pi * i * dt / 90.0)
        if tug:
            m += -m / 30.0 * dt + 0.15 * np.sqrt(2 * dt / 30.0) * rng.standard_normal()
            delta = float(np.clip(-0.6 * m / K, -np.radians(20), np.radians(20)))
        else:
            delta = np.radians(15) * np.sign(np.sin(2 * np.pi * i * dt / 80.0) + 1e-9)
        rows[i] = (x, y, psi, r, delta, u, v)
        x, y = x + (u * np.cos(psi) - v * np.sin(psi)) * dt, y + (u * np.sin(psi) + v * np.cos(psi)) * dt
        psi, r = psi + r * dt, r + (K * delta - r + m) / T_yaw * dt
    sampled = rows[::int(round(1.0 / dt))]
    t = np.arange(len(sampled), dtype=float)
    ones = np.ones_like(t)
    states = np.column_stack([sampled[:, 0], sampled[:, 5], sampled[:, 1], sampled[:, 6], sampled[:, 2], sampled[:, 3]])
    inputs = np.column_stack([10.0 * ones, sampled[:, 4], 1.0 * ones, 0.5 * ones])
    return write_processed_csv(path, t, states, inputs)


def test_a_reversed_rudder_and_a_rudder_fooled_by_a_tug_are_refused_with_both_fixes(tmp_path):
    """Known truth both ways: a zig-zag log with its rudder column negated (reversed) and a
    berthing-like log whose rudder is right but whose tug turns the ship against it. The check
    reads both as reversed; the one-line refusal names both fixes: negate the column, or name
    the log in [data] rudder_sign_checked."""
    reversed_log = _nomoto_log(tmp_path / "zz.csv", tug=False)
    frame = pd.read_csv(reversed_log)
    frame[DELTA] *= -1.0
    frame.to_csv(reversed_log, index=False)
    fooled = _nomoto_log(tmp_path / "tug_assist.csv", tug=True)
    for path in (reversed_log, fooled):
        t, u, r, delta = _signals(path)
        assert rudder_response(t, u, r, delta).sign is RudderSign.PORT_CLEAR
        with pytest.raises(DataError) as info:
            read_run(path, warn=None)
        message = str(info.value)
        assert "\n" not in message and message.startswith(f"{path}: delta_rudder: the rudder sign looks reversed")
        assert "negate column 'delta_rudder [rad]' in the log" in message
        assert message.endswith(f'[data] rudder_sign_checked = ["{path.stem}"]')
    # the first fix is right for the reversed log: negated back, it reads to starboard
    frame[DELTA] *= -1.0
    frame.to_csv(reversed_log, index=False)
    assert read_run(reversed_log, warn=None).track.channels[-1].verdict is Verdict.CONSISTENT


def test_a_log_whose_rudder_sign_the_user_checked_is_read_and_its_override_said(tmp_path):
    """The tug log (rudder right, the check fooled): named in rudder_sign_checked it is read as
    it is, its check kept as USER_CHECKED with the partial correlation it read, and the
    override said to `warn`; another log in the same call is still refused."""
    fooled = _nomoto_log(tmp_path / "tug_assist.csv", tug=True)
    t, u, r, delta = _signals(fooled)
    read_as = rudder_response(t, u, r, delta).correlation
    assert read_as <= -REVERSED_CORRELATION
    said: list[str] = []
    run = read_runs([fooled], rudder_sign_checked=("tug_assist",), warn=said.append)[0]
    assert run.track.rudder_overridden.correlation == pytest.approx(read_as)
    assert run.track.rudder_overridden.verdict is Verdict.USER_CHECKED
    assert said == [f"{fooled}: delta_rudder: the rudder check reads the sign reversed (partial correlation "
                    f"{read_as:.2f}); read as it is: the log is named in [data] rudder_sign_checked"]
    np.testing.assert_array_equal(run.inputs[:, 1], pd.read_csv(fooled)[DELTA].to_numpy())   # not negated
    other = _nomoto_log(tmp_path / "zz.csv", tug=True)
    with pytest.raises(DataError, match=r'zz.csv: delta_rudder: .*rudder_sign_checked = \["zz"\]$'):
        read_runs([fooled, other], rudder_sign_checked=("tug_assist",), warn=None)
    # a log whose check agrees is unchanged by being named
    straight = read_run(_nomoto_log(tmp_path / "plain.csv", tug=False), rudder_sign_checked=("plain",), warn=None)
    assert straight.track.rudder_overridden is None and straight.track.channels[-1].verdict is Verdict.CONSISTENT


def test_training_on_a_checked_log_records_the_override(tmp_path, capsys):
    """`sysid train` on the tug log: refused without [data] rudder_sign_checked (nothing
    written); with it, trained, the override said in the training output and recorded in
    summary.json beside that log (the partial correlation the check read), not beside the
    other log."""
    from sysid.cli import main
    fooled = _nomoto_log(tmp_path / "tug_assist.csv", tug=True)
    plain = _nomoto_log(tmp_path / "plain.csv", tug=False)
    t, u, r, delta = _signals(fooled)
    read_as = rudder_response(t, u, r, delta).correlation
    body = ("[experiment]\nname = 'tug'\nmodel = 'hybrid'\nseed = 1\n"
            "[data]\ntrain = ['tug_assist.csv', 'plain.csv']\n{checked}"
            "[training]\nepochs = 1\nwarm_start_epochs = 1\n[evaluation]\nhorizons = [30.0]\n")
    config = tmp_path / "tug.toml"
    config.write_text(body.format(checked=""))
    with pytest.raises(SystemExit) as stop:
        main(["train", str(config), "-o", str(tmp_path / "refused")])
    assert stop.value.code == 2 and not (tmp_path / "refused").exists()
    assert 'rudder_sign_checked = ["tug_assist"]' in capsys.readouterr().err
    config.write_text(body.format(checked="rudder_sign_checked = ['tug_assist']\n"))
    main(["train", str(config), "-o", str(tmp_path / "run"), "--threads", "1"])
    said = capsys.readouterr()
    assert f"{fooled}: delta_rudder: the rudder check reads the sign reversed (partial correlation {read_as:.2f})" \
        in said.out + said.err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    recorded = {Path(f["file"]).name: f for f in summary["data"]["train"]}
    assert recorded["tug_assist.csv"]["rudder_sign_checked"] == pytest.approx(read_as, abs=1e-4)
    assert "rudder_sign_checked" not in recorded["plain.csv"]
    assert plain.exists()


def test_logs_check_shows_the_users_checked_sign(tmp_path, capsys):
    """`sysid logs check --config` on the tug log: refused without the config's
    rudder_sign_checked (exit 2), passed with it, its row naming the override."""
    from sysid.cli import main
    fooled = _nomoto_log(tmp_path / "tug_assist.csv", tug=True)
    config = tmp_path / "exp.toml"
    config.write_text("[experiment]\nname = 'tug'\nmodel = 'hybrid'\n[data]\ntrain = ['tug_assist.csv']\n")
    with pytest.raises(SystemExit) as stop:
        main(["logs", "check", str(fooled), "--config", str(config)])
    assert stop.value.code == 2
    capsys.readouterr()
    config.write_text("[experiment]\nname = 'tug'\nmodel = 'hybrid'\n[data]\ntrain = ['tug_assist.csv']\n"
                      "rudder_sign_checked = ['tug_assist']\n")
    main(["logs", "check", str(fooled), "--config", str(config)])
    out = capsys.readouterr().out.splitlines()
    row = next(line for line in out if line.split()[:2] == ["tug_assist.csv", "delta_rudder"])
    assert row.split()[2] == "-1" and row.endswith("sign checked by the user (named in [data] rudder_sign_checked)")
    assert out[-1] == "logs check: 1 log(s), 0 clear mismatch(es), 0 marginal, 0 unreadable, 0 without a track"


def test_preprocess_keeps_a_checked_raw_logs_output(tmp_path):
    """`sysid preprocess`'s check of its outputs (`_check_tracks`) on the tug log as the output
    of raw/tug_run.csv: refused naming --rudder-sign-checked and the processed log's name for
    training; kept with the raw log named."""
    from sysid.cli.preprocess_commands import _check_tracks
    out = _nomoto_log(tmp_path / "tug_run_seg1.csv", tug=True)
    results = [{"ok": True, "file": "raw/tug_run.csv", "outputs": [str(out)]}]
    with pytest.raises(DataError) as bad:
        _check_tracks(results)
    assert str(bad.value).startswith("raw/tug_run.csv: its processed log tug_run_seg1.csv: delta_rudder: the rudder "
                                     "sign looks reversed")
    assert str(bad.value).endswith('give --rudder-sign-checked tug_run and, to train, '
                                   '[data] rudder_sign_checked = ["tug_run_seg1"]')
    _check_tracks(results, ("tug_run",))
    with pytest.raises(DataError):
        _check_tracks(results, ("tug_run_seg1",))   # the raw log's name, not the output's
