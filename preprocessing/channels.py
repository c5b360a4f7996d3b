"""The processed log schema's columns (bare name -> unit, in the public files' column order)
and the channel each one is in sysid (`sysid.channel_names`). Plain dicts, no numpy or pandas: the
config reads them (`sysid.config.column_map`) without loading either."""
from __future__ import annotations

# processed schema, in the public files' column order
PROCESSED = {
    "t": "s", "x_position_mid": "m", "u_velo": "m/s", "y_position_mid": "m", "vm_velo": "m/s",
    "psi_hat": "rad", "r_angvelo": "rad/s", "n_prop": "rps", "delta_rudder": "rad",
    "wind_velo_relative_mid": "m/s", "wind_dir_relative_mid": "rad",
    "wind_velo_true": "m/s", "wind_dir_true": "rad",
}

# processed column -> the channel name of sysid's state and inputs (`sysid.channel_names`)
PROCESSED_CHANNEL = {
    "t": "t", "x_position_mid": "x", "u_velo": "u", "y_position_mid": "y", "vm_velo": "v",
    "psi_hat": "psi", "r_angvelo": "r", "n_prop": "n_prop", "delta_rudder": "delta_rudder",
    "wind_velo_relative_mid": "wind_velo_relative", "wind_dir_relative_mid": "wind_dir_relative",
    "wind_velo_true": "wind_velo_true", "wind_dir_true": "wind_dir_true",
}
