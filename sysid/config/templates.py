"""The files `sysid init` writes: a ship file of the standard MMG family, an experiment config
with every key, and the next steps.

Both files are generated, not copied: the ship file's keys are those the standard families
need (`sysid.mmg.ship.active_parameters`), the experiment's keys those of the typed config
(`sysid.config.reference`), so a template never lacks a key the parser wants or holds one it
refuses. The ship file's values are the bundled KVLCC2 7 m model's: a start that loads and
checks, to be replaced by the user's ship's values (every line says the unit and where the
value comes from).
"""
from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from pathlib import Path

from sysid.config.experiment import _toml_value
from sysid.config.reference import SECTIONS, config_keys, toml_value
from sysid.errors import ConfigError

STANDARD_MODELS = {"hull": "standard", "propeller": "standard", "rudder": "standard"}
START_SHIP = "kvlcc2_l7"   # whose values fill the template

# ship-file key -> (unit, what it is and where its value comes from)
SHIP_KEYS: dict[str, tuple[str, str]] = {
    "L_pp": ("m", "length between perpendiculars; lines plan"),
    "B": ("m", "moulded breadth; lines plan"),
    "d": ("m", "mean draft in the condition of the logs; loading condition"),
    "rho": ("kg/m^3", "density of the water the logs were recorded in (fresh 1000, sea 1025)"),
    "m": ("kg", "displacement mass in the condition of the logs; hydrostatics"),
    "m_x": ("kg", "added mass in surge, m'_x * 0.5 rho L_pp^2 d; captive tests or an estimate (m'_x 0.01-0.05)"),
    "m_y": ("kg", "added mass in sway, m'_y * 0.5 rho L_pp^2 d; captive tests or an estimate (m'_y 0.1-0.3)"),
    "I_zz_J_zz": ("kg m^2", "yaw moment of inertia about the centre of gravity plus its added moment "
                            "(I_zG + J_z); mass distribution (I_zG ~ m (0.25 L_pp)^2) and captive tests"),
    "x_G": ("m", "centre of gravity forward of midship (negative: aft); hydrostatics"),
    "R_0": ("-", "straight-running resistance R'_0 = R / (0.5 rho L_pp d U^2); resistance test"),
    "X_vv": ("-", "surge derivative X'_vv; captive-model tests (oblique towing, CMT) or empirical formulas"),
    "X_vr": ("-", "surge derivative X'_vr; captive-model tests"),
    "X_rr": ("-", "surge derivative X'_rr; captive-model tests"),
    "X_vvvv": ("-", "surge derivative X'_vvvv; captive-model tests"),
    "Y_v": ("-", "linear sway derivative Y'_v (< 0); captive-model tests or empirical formulas (e.g. Kijima)"),
    "Y_r": ("-", "linear sway derivative Y'_r; captive-model tests or empirical formulas"),
    "Y_vvv": ("-", "non-linear sway derivative Y'_vvv; captive-model tests"),
    "Y_vvr": ("-", "non-linear sway derivative Y'_vvr; captive-model tests"),
    "Y_vrr": ("-", "non-linear sway derivative Y'_vrr; captive-model tests"),
    "Y_rrr": ("-", "non-linear sway derivative Y'_rrr; captive-model tests"),
    "N_v": ("-", "linear yaw-moment derivative N'_v (about midship); captive-model tests or empirical formulas"),
    "N_r": ("-", "linear yaw-moment derivative N'_r (< 0); captive-model tests or empirical formulas"),
    "N_vvv": ("-", "non-linear yaw-moment derivative N'_vvv; captive-model tests"),
    "N_vvr": ("-", "non-linear yaw-moment derivative N'_vvr; captive-model tests"),
    "N_vrr": ("-", "non-linear yaw-moment derivative N'_vrr; captive-model tests"),
    "N_rrr": ("-", "non-linear yaw-moment derivative N'_rrr; captive-model tests"),
    "D": ("m", "propeller diameter; propeller drawing"),
    "t_P": ("-", "thrust deduction factor in straight motion; self-propulsion test"),
    "w_P0": ("-", "effective wake fraction at the propeller in straight motion; self-propulsion test"),
    "x_P": ("-", "x'_P = x_P / L_pp, propeller position as a fraction of L_pp (negative: aft, about -0.5)"),
    "k0": ("-", "K_T(J) = k0 + k1 J + k2 J^2: fit of the propeller open-water test"),
    "k1": ("-", "K_T polynomial, linear term"),
    "k2": ("-", "K_T polynomial, quadratic term"),
    "C_1": ("-", "rate of the wake change with the propeller's drift angle beta_P; captive tests"),
    "C_2_plus": ("-", "(1 - w_P) / (1 - w_P0) at large beta_P > 0; captive tests"),
    "C_2_minus": ("-", "the same for beta_P <= 0; captive tests"),
    "A_R": ("m^2", "rudder profile area; rudder drawing"),
    "H_R": ("m", "rudder span; rudder drawing"),
    "f_alpha": ("-", "rudder lift gradient; Fujii's 6.13 Lambda / (Lambda + 2.25) (Lambda = H_R^2 / A_R) or a "
                     "rudder open-water test"),
    "epsilon": ("-", "wake ratio (1 - w_R) / (1 - w_P); captive tests"),
    "kappa": ("-", "propeller-race factor of the rudder inflow; captive tests"),
    "x_R": ("m", "rudder position from midship (negative: aft, about -0.5 L_pp)"),
    "l_R": ("m", "effective lever of the rudder's inflow angle, l'_R L_pp (about -L_pp); captive tests"),
    "gamma_R_minus": ("-", "flow-straightening coefficient for beta_R < 0; captive tests"),
    "gamma_R_plus": ("-", "flow-straightening coefficient for beta_R >= 0; captive tests"),
    "t_R": ("-", "steering resistance deduction; captive tests"),
    "a_H": ("-", "rudder force increase factor (hull interaction); captive tests"),
    "x_H": ("m", "acting point of the hull's share a_H F_N from midship (about -0.45 L_pp); captive tests"),
}

SENSOR_KEYS: dict[str, tuple[str, str]] = {
    "gnss_fore": ("m", "[x, y] of the fore GNSS antenna from midship (x to the bow, y to starboard)"),
    "gnss_aft": ("m", "[x, y] of the aft GNSS antenna"),
    "gnss_baseline": ("m", "nominal distance between the two antennas"),
    "heading_offset": ("rad", "turn of the antenna pair about midship beyond the positions listed (0 when they are surveyed)"),
    "anemometer_1": ("m", "[x, y] of the first anemometer"),
    "anemometer_2": ("m", "[x, y] of the second anemometer"),
    "fog": ("m", "[x, y] of the fibre-optic gyro"),
}

SHIP_SECTIONS = {
    "principal": "principal particulars",
    "mass": "masses in kg (not non-dimensional); x_G in metres",
    "hull": "standard MMG hull (Yasukawa & Yoshimura 2015); derivatives non-dimensional, without the prime, "
            "forces by 0.5 rho L_pp d U^2, moments by 0.5 rho L_pp^2 d U^2, r' = r L_pp / U",
    "propeller": "standard MMG propeller thrust with the drift correction of the wake",
    "rudder": "standard MMG rudder",
}

NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]*$")


WIDTH = 100  # characters per line of a written file


def _comment(text: str) -> list[str]:
    """`text` as comment lines of at most `WIDTH` characters."""
    return textwrap.wrap(text, WIDTH - 2, initial_indent="# ", subsequent_indent="# ", break_on_hyphens=False)


def _line(key: str, value: str, comment: str, width: int = 24) -> str:
    """``key = value  # comment``, or the comment above the key when the line would be long."""
    line = f"{f'{key} = {value}':<{width}} # {comment}"
    return line if len(line) <= WIDTH else "\n".join(_comment(comment) + [f"{key} = {value}"])


_MANEUVERING_TEXT = {"approach_speed": "speed at the start of every maneuver (--speed)",
                     "scale": "full-scale L_pp over this ship's, for the IMO criteria at full scale",
                     "rudder_rate": "the steering gear's rate at this ship's scale"}


def ship_template(name: str) -> str:
    """A ship file of the standard MMG families for a ship called `name`, every value the
    KVLCC2 7 m model's and commented with its unit and source."""
    from sysid.mmg.ship import MANEUVERING_KEYS, active_parameters, load_ship

    start = load_ship(START_SHIP)
    lines = [
        f"# Ship file of {name}: the standard MMG model (Yasukawa & Yoshimura 2015).",
        f"# Written by `sysid init`. EVERY VALUE BELOW IS THE KVLCC2 7 m MODEL'S (the bundled {START_SHIP}):",
        "# a start that loads, not your ship. Replace each with your ship's value; the comment gives",
        "# the unit and where the value comes from. Units SI (m, kg, s, rad). Then check the file:",
        f"#     sysid ship check {name}.toml",
        "",
        "[ship]",
        f"name = {_toml_value(name)}",
        f'description = "{name} (values still those of the KVLCC2 7 m model: replace them)"',
    ]
    section = None
    for key, (where, _, _) in active_parameters(STANDARD_MODELS).items():
        if where != section:
            section = where
            lines += ["", f"[{where}]", *_comment(SHIP_SECTIONS[where])]
            if where in STANDARD_MODELS:
                lines.append(_line("model", '"standard"', "force-model family (see the docs: ship files)"))
        unit, what = SHIP_KEYS.get(key, ("", ""))
        lines.append(_line(key, repr(start.parameters[key]), f"{unit}, {what}" if what else unit))
    lines += ["", "# No [wind] section: no wind force acts. With wind in your logs, add [wind] model = \"fujiwara\"",
              "# with A_T, A_L, L_wind, X0, X1, X3, X5, Y1, Y3, Y5, N1, N2, N3 and rho_air under [principal].",
              "", "[maneuvering]",
              "# the defaults of `sysid maneuver` (no force depends on them); without rudder_rate, the",
              "# 2.32 deg/s at full scale (SOLAS: 35 deg to 30 deg the other side in 28 s), Froude-scaled by `scale`"]
    for key, setting in start.maneuvering.items():
        lines.append(_line(key, repr(setting), f"{MANEUVERING_KEYS[key][2]}, {_MANEUVERING_TEXT[key]}"))
    lines += ["", "[sensors]",
              "# where the instruments sit (used by `sysid preprocess` on raw logs only)"]
    for key, (unit, what) in SENSOR_KEYS.items():
        value = getattr(start.sensors, key)
        text = f"[{value[0]!r}, {value[1]!r}]" if isinstance(value, tuple) else repr(value)
        lines.append(_line(key, text, f"{unit}, {what}"))
    return "\n".join(lines) + "\n"


def _data_keys() -> set[str]:
    from dataclasses import fields

    from sysid.config.experiment import DataOptions
    return {f.name for f in fields(DataOptions)}


# keys `sysid init` sets for the user's project (others keep the typed config's default)
def _project_values(name: str, ship_file: str) -> dict[tuple[str, str], object]:
    values: dict[tuple[str, str], object] = {("experiment", "name"): name, ("experiment", "model"): "hybrid", ("experiment", "ship"): ship_file}
    if "train" in _data_keys():  # training and test logs named in the config
        values.update({("data", "train"): ["logs/*.csv"], ("data", "test"): ["test/*.csv"]})
    else:
        values[("data", "files")] = ["logs/*.csv"]
    return values


# keys written commented out: they do not apply to a project of one's own ships and logs
_COMMENTED = {("experiment", "dataset"), ("ensemble", "members")}
# tables written as a commented example at the end of their section
_EXAMPLE_TABLES = {("data", "columns"): [
    "[data.columns]          # your logs' names and units; other channels: the processed columns",
    't = "time [s]"',
    'u = { column = "STW", unit = "knots" }',
    'psi = { column = "heading", unit = "deg" }',
    'delta_rudder = { column = "rudder", unit = "deg" }',
    'n_prop = { column = "shaft", unit = "rpm" }',
]}


def experiment_template(name: str, ship_file: str) -> str:
    """An experiment config with every key of the typed config, each commented with its type,
    unit and meaning; `ship_file` and the logs relative to the config's folder."""
    values = _project_values(name, ship_file)
    lines = [f"# Experiment config of {name}, written by `sysid init`: every key, with its default unless",
             "# said otherwise. Relative paths resolve against this file's folder. Reference of every key:",
             "# the docs' \"Config reference\" page.", ""]
    section, deferred = None, []
    for ref in config_keys():
        if ref.section != section:
            lines += deferred
            deferred = []
            section = ref.section
            if lines[-1] != "":
                lines.append("")
            lines += [f"[{section}]", *_comment(SECTIONS.get(section, ""))]
        unit = f" [{ref.unit}]" if ref.unit else ""
        choices = f" One of: {', '.join(ref.choices)}." if ref.choices else ""
        key = (ref.section, ref.key)
        if key in _EXAMPLE_TABLES:  # after the section's keys: a table header ends the section
            deferred = _comment(f"{ref.key} ({ref.type}{unit}): {ref.meaning}{choices} For example:") + [
                f"# {line}" for line in _EXAMPLE_TABLES[key]]
            continue
        lines += _comment(f"{ref.key} ({ref.type}{unit}): {ref.meaning}{choices}")
        text = f"{ref.key} = {toml_value(values.get(key, ref.default))}"
        lines.append(f"# {text}" if key in _COMMENTED else text)
    lines += deferred
    return "\n".join(lines) + "\n"


def next_steps(folder: str, ship_file: str, config_file: str) -> str:
    """What to do after `sysid init`, with the paths as the user gave them."""
    d = folder.rstrip("/") or "."
    test_option = "" if "test" in _data_keys() else f" --test {d}/test"  # else [data] test names them
    return f"""Next steps
1. Put the processed logs to train on (1 Hz, sysid's columns: see the docs, "Input formats")
   into {d}/logs/ and those to test on into {d}/test/; raw 10 Hz logs are preprocessed with
       sysid preprocess RAW.csv ... --ship {d}/{ship_file} -o PROCESSED_FOLDER
2. Replace the values in {d}/{ship_file} with your ship's (each line gives its unit and
   where the value comes from), then check it:
       sysid ship check {d}/{ship_file}
3. Read {d}/{config_file}: every key is there with its default and meaning. [data] lists
   the training and test logs (files, folders or patterns, relative to the config).
4. Train, evaluate on the test logs and write the report:
       sysid train {d}/{config_file} -o {d}/runs/first{test_option}
       sysid report {d}/runs/first -o {d}/reports/first
"""


@dataclass(frozen=True)
class Project:
    """The files of a new project: name -> text, in the folder `folder`."""

    folder: Path
    files: dict[str, str]
    steps: str


def project_files(folder: str | Path, ship: str = "my_ship") -> Project:
    """The ship file, experiment config and next steps of a project in `folder` whose ship is
    called `ship` (a file name without ``.toml``: letters, digits, ``_`` and ``-``)."""
    if not NAME.match(ship):
        raise ConfigError(f"--ship {ship!r}: a ship name becomes the file name {ship}.toml, so it is ASCII "
                          "letters (A-Z, a-z) and digits (0-9) followed by those, '_' and '-' (no spaces, accents "
                          "or other scripts); choose e.g. --ship my_tanker")
    folder = Path(folder)
    ship_file, config_file = f"{ship}.toml", "experiment.toml"
    # the experiment's name is the folder's, made a safe file name (`sysid.config.checks.path_component`)
    name = re.sub(r"[^A-Za-z0-9_.,=+-]", "_", folder.resolve().name).lstrip("._,=+-")[:100] or "experiment"
    steps = next_steps(str(folder), ship_file, config_file)
    return Project(folder, {ship_file: ship_template(ship), config_file: experiment_template(name, ship_file),
                            "NEXT_STEPS.md": steps}, steps)
