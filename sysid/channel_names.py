"""Names and order of the state and input channels.

State ``x`` (..., 6): ``x`` [m], ``u`` [m/s], ``y`` [m], ``v`` [m/s] (v_m at midship),
``psi`` [rad], ``r`` [rad/s]; earth frame x0 (north in lat/lon logs), y0 to starboard of it.
Inputs (..., 4): ``n_prop`` [rps], ``delta_rudder`` [rad, positive turns to starboard],
``wind_velo_true`` [m/s], ``wind_dir_true`` [rad, direction the wind comes from, from x0
towards y0]. Forces (..., 3): X [N], Y [N], N [N m] about midship.
"""
STATE = ("x", "u", "y", "v", "psi", "r")
INPUTS = ("n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true")
VELOCITY = ("u", "v", "r")
VELOCITY_INDEX = (1, 3, 5)
FORCE = ("X", "Y", "N")
# ForceBreakdown component -> the key in column names (XH, YH, NH, ..., XNN)
FORCE_COMPONENTS = {"hull": "H", "propeller": "P", "rudder": "R", "wind": "A", "correction": "NN"}


def force_column(component: str, axis: str) -> str:
    """Column name of one force component: ``force_column("hull", "X") == "XH"``."""
    return f"{axis}{FORCE_COMPONENTS[component]}"
