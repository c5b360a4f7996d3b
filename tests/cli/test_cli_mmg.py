"""The `sysid forces`, `simulate` and `evaluate` commands, and their errors on bad input."""
import numpy as np
import pandas as pd
import pytest

from sysid.cli import run as main
from sysid.data.recordings import read_run
from sysid.errors import DataError, ShipDefinitionError

# our column -> the oracle's (the lab's names: delta_rad, XH_SI, ...)
OUT = {**{f"{a}{k}": f"{a}{k}_SI" for k in "HPRA" for a in "XYN"}, **{a: f"{a}_SI" for a in "XYN"},
       **{d: d for d in ("x_dot", "u_dot", "y_dot", "v_dot", "psi_dot", "r_dot")}}


def _oracle_input(oracle_dir, tmp_path):
    """The oracle's vectors with our input names (its delta_rad is our delta_rudder)."""
    path = tmp_path / "oracle_in.csv"
    pd.read_csv(oracle_dir / "mmg_vectors_public.csv").rename(columns={"delta_rad": "delta_rudder"}).to_csv(path, index=False)
    return path


def test_forces_command_matches_the_oracle(oracle_dir, tmp_path):
    out = tmp_path / "forces.csv"
    main(["forces", "--ship", "esso_osaka", "--quadrature", "simpson",
          str(_oracle_input(oracle_dir, tmp_path)), "-o", str(out)])
    ours, ref = pd.read_csv(out), pd.read_csv(oracle_dir / "mmg_vectors_public.csv")
    assert len(ours) == len(ref)
    for col, ref_col in OUT.items():
        err = np.abs(ours[col].to_numpy() - ref[ref_col].to_numpy())
        assert (err <= np.maximum(1e-9, 1e-6 * np.abs(ref[ref_col].to_numpy()))).all(), col


def test_simulate_command_reproduces_the_oracle_trajectory(oracle_dir, dataset_dir, tmp_path):
    ref = pd.read_csv(oracle_dir / "traj_zigzag_dt1p0.csv")  # zigzag 13_14_21 from t = 15 s
    out = tmp_path / "sim.csv"
    main(["simulate", "--ship", "esso_osaka", "--log", str(dataset_dir / ref.source[0]),
          "--start", "15", "--horizon", "100", "--integrator", "rk4", "--quadrature", "simpson",
          "-o", str(out)])
    sim = pd.read_csv(out)
    assert len(sim) == 101
    cols = ["x", "u", "y", "v", "psi", "r"]
    assert np.abs(sim[cols].to_numpy() - ref[cols].to_numpy()).max() < 1e-6
    assert np.abs(sim[[f"obs_{c}" for c in cols]].to_numpy() - ref[[f"obs_{c}" for c in cols]].to_numpy()).max() < 1e-12


def test_simulate_reads_a_users_log_through_the_configs_columns(oracle_dir, dataset_dir, tmp_path):
    """``sysid simulate --config EXP`` on the user's copy of the oracle's zig-zag (knots, deg,
    rpm under other names): the config's [data.columns] read it and its ship is the MMG's, so
    the prediction is the oracle's trajectory (in SI); without --config the log is refused
    with one line."""
    from own_logs import columns_table, write_own_log

    ref = pd.read_csv(oracle_dir / "traj_zigzag_dt1p0.csv")  # zigzag 13_14_21 from t = 15 s
    log = write_own_log(dataset_dir / ref.source[0], tmp_path / "my_zigzag.csv")
    config = tmp_path / "exp.toml"
    config.write_text('[experiment]\nmodel = "mmg"\nship = "esso_osaka"\n[data]\ntrain = ["my_zigzag.csv"]\n'
                      + columns_table())
    out = tmp_path / "sim.csv"
    options = ["--start", "15", "--horizon", "100", "--integrator", "rk4", "--quadrature", "simpson", "-o", str(out)]
    with pytest.raises(DataError, match="my_zigzag.csv: no column"):
        main(["simulate", "--log", str(log), *options])
    assert not out.exists()
    main(["simulate", "--log", str(log), "--config", str(config), *options])
    sim = pd.read_csv(out)
    cols = ["x", "u", "y", "v", "psi", "r"]
    assert len(sim) == 101
    assert np.abs(sim[cols].to_numpy() - ref[cols].to_numpy()).max() < 1e-6
    assert np.abs(sim[[f"obs_{c}" for c in cols]].to_numpy() - ref[[f"obs_{c}" for c in cols]].to_numpy()).max() < 1e-9


def _forces_input(tmp_path, frame):
    path = tmp_path / "in.csv"
    frame.to_csv(path, index=False)
    return path


def test_forces_missing_column_and_nan(oracle_vectors, tmp_path):
    cols = ["x", "u", "y", "v", "psi", "r", "n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true"]
    frame = oracle_vectors.rename(columns={"delta_rad": "delta_rudder"})[cols].head(5).copy()
    out = tmp_path / "out.csv"
    with pytest.raises(DataError, match=r"in.csv: missing column\(s\) \['delta_rudder'\]"):
        main(["forces", str(_forces_input(tmp_path, frame.drop(columns="delta_rudder"))), "-o", str(out)])
    frame.loc[3, "r"] = np.nan
    with pytest.raises(DataError, match="in.csv: column 'r' is not a finite number at line 5"):
        main(["forces", str(_forces_input(tmp_path, frame)), "-o", str(out)])
    assert not out.exists()  # nothing half-written
    with pytest.raises(ShipDefinitionError, match="unknown ship 'nope'"):
        main(["forces", "--ship", "nope", str(_forces_input(tmp_path, frame)), "-o", str(out)])
    with pytest.raises(ShipDefinitionError, match="C_D = -1.0 is out of range"):
        main(["forces", "--set", "C_D=-1", str(_forces_input(tmp_path, frame)), "-o", str(out)])


def test_console_script_prints_one_clear_error(tmp_path):
    import subprocess, sys
    proc = subprocess.run([sys.executable, "-c", "from sysid.cli import main; main()", "evaluate",
                           "--data", str(tmp_path / "missing.csv"), "-o", str(tmp_path / "m.csv")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"error: {tmp_path / 'missing.csv'}: no such file or directory"


def _processed(dataset_dir, tmp_path, edit):
    src = dataset_dir / "zigzag" / "zigzag_31-Jul-2020_13_14_21.csv"
    frame = pd.read_csv(src).head(300)
    edit(frame)
    path = tmp_path / "run.csv"
    frame.to_csv(path, index=False)
    return path


def test_a_processed_log_cut_off_mid_row_is_named_as_such(dataset_dir, tmp_path):
    path = _processed(dataset_dir, tmp_path, lambda f: None)
    lines = path.read_text().splitlines()           # the header and 300 rows
    path.write_text("\n".join(lines[:-1] + [lines[-1][:40]]))   # the last row cut after 40 characters
    with pytest.raises(DataError, match=r"run.csv: line 301: the file ends in the middle of it \(no line end, "
                                        r"\d+ of 13 channels missing\): it is cut off"):
        read_run(path)
    path.write_text("\n".join(lines))              # complete, only the last line end missing: read
    assert len(read_run(path, rate=10.0)) == 300


def test_processed_run_errors_name_file_and_field(dataset_dir, tmp_path):
    def nan(f): f.loc[120, "r_angvelo [rad/s]"] = np.nan
    with pytest.raises(DataError, match=r"run.csv: column 'r_angvelo \[rad/s\]' \(channel r\) is empty, NaN or inf at line 122"):
        read_run(_processed(dataset_dir, tmp_path, nan))

    def backwards(f): f.loc[50, "t [s]"] = 1.0
    with pytest.raises(DataError, match=r"run.csv: column 't \[s\]' \(channel t\) is not strictly increasing"):
        read_run(_processed(dataset_dir, tmp_path, backwards))

    def degrees(f): f["delta_rudder [rad]"] = np.degrees(f["delta_rudder [rad]"])
    with pytest.raises(DataError, match=r"run.csv: column 'delta_rudder \[rad\]' \(channel delta_rudder\) reaches .* wrong units"):
        read_run(_processed(dataset_dir, tmp_path, degrees))

    def renamed(f): f.columns = [("u" if c == "u_velo [m/s]" else c) for c in f.columns]
    with pytest.raises(DataError, match=r"run.csv: no column 'u_velo \[m/s\]' for channel u \(the file has"):
        read_run(_processed(dataset_dir, tmp_path, renamed))


def test_trailing_empty_rows_are_dropped(dataset_dir, tmp_path):
    def trailing(f): f.loc[290:, [c for c in f.columns if c != "t [s]"]] = np.nan
    run = read_run(_processed(dataset_dir, tmp_path, trailing))
    assert run.t[-1] == pytest.approx(28.0) and len(run) == 29  # rows 0..289 at 10 Hz, every 10th


def test_dataset_checks_duplicates_and_frozen_gnss(dataset_dir):
    from sysid.data.recordings import duplicate_runs
    cut = read_run(dataset_dir / "turning" / "turn_cut_14-Sep-2020_15_58_08.csv")
    full = read_run(dataset_dir / "turning" / "turn_14-Sep-2020_15_58_08.csv")
    other = read_run(dataset_dir / "turning" / "turn_14-Oct-2020_14_56_07.csv")
    assert duplicate_runs([cut, full, other]) == [(cut.name, full.name)]
    frozen = read_run(dataset_dir / "turning" / "turn_14-Oct-2020_14_08_51.csv")
    assert any("GNSS frozen" in s and "t = 20" in s for s in frozen.issues), frozen.issues


def test_simulate_and_evaluate_take_their_path_from_the_steps_and_the_cache(oracle_dir, dataset_dir, tmp_path,
                                                                            monkeypatch, capsys):
    """`simulate` and `evaluate` say which path they took: with nothing in the cache and
    fewer eager steps than `PREDICTION_REPAY_STEPS`, eager; a prediction whose package is in
    the cache, or with enough steps, compiled; --eager and --compiled as asked. The windows
    `evaluate` counts are the protocol's floor(N / H) per log, H - 1 steps each."""
    from sysid.cli.evaluate_commands import _window_work
    from sysid.cli.mmg_options import mmg_of as _model, prediction_path as _prediction_path
    from sysid.config.choices import Method
    from sysid.fast.payoff import PREDICTION_REPAY_STEPS
    from sysid.fast.compiled import prediction_package
    monkeypatch.setenv("SYSID_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("SYSID_COMPILE", "1")
    log = dataset_dir / pd.read_csv(oracle_dir / "traj_zigzag_dt1p0.csv").source[0]
    args = ["simulate", "--ship", "esso_osaka", "--log", str(log), "--start", "15", "--horizon", "100",
            "--integrator", "rk4", "-o", str(tmp_path / "sim.csv")]
    main(args)
    said = capsys.readouterr().out
    assert (f"simulate: eager prediction: 100 steps, fewer than the {PREDICTION_REPAY_STEPS} per package that "
            "repay compiling 1 package(s) not in the cache") in said
    main([*args[:-1], str(tmp_path / "sim2.csv"), "--eager"])
    assert "simulate: eager prediction (as asked)" in capsys.readouterr().out
    assert pd.read_csv(tmp_path / "sim.csv").equals(pd.read_csv(tmp_path / "sim2.csv"))

    model = _model("esso_osaka", None, "exact")
    _, path = prediction_package(model, Method.RK4, 1.0, 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.touch()  # its package in the cache: a warm start
    warm = _prediction_path("simulate", None, [model], [(1, 100)], Method.RK4, 1.0)
    assert warm.compiled and "1 package(s) in the cache" in warm.reason
    assert not _prediction_path("simulate", None, [model], [(1, 100)], Method.RK4, 0.5).compiled  # another dt: cold
    assert _prediction_path("simulate", None, [model], [(1, PREDICTION_REPAY_STEPS)], Method.RK4, 0.5).compiled
    assert not _prediction_path("simulate", False, [model], [(1, 100)], Method.RK4, 1.0).compiled
    capsys.readouterr()

    runs = [read_run(log, 1.0)]
    assert _window_work(runs, [30.0, 100.0]) == [(len(runs[0]) // 30, 29), (len(runs[0]) // 100, 99)]
